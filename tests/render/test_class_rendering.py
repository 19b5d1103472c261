"""Rendering every nuScenes class: retro-reflective bands, thin parts (spokes, frames), contact shadows at feet.

Test-only meshes are closed boxes (:func:`_boxes`) at 320 x 180 (f = 277 px): a 2 cm tube at 15 m is
0.37 px wide, a 5 mm spoke 0.09 px, so coverage and shadows must be resolved below a pixel.
"""

import cv2
import numpy as np
import pytest

from render_fixtures import ground_scene, sunny_light
from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.assets.mesh_parts import box_mesh
from streetaug.augment.assets.validate import face_normals
from streetaug.augment.core import (PinholeCamera, camera_envmap_directions, intrinsics_from_fov, invert_transform,
                                    pose_camera_to_transform)
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render import prepare_asset, render_insertion
from streetaug.augment.render.brdf import RETRO_ALBEDO, BRDFParams, eval_brdf, retro_env_factor, retro_lobe
from streetaug.augment.render.sampling import sample_cone

W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP_CAM = np.array([0.0, -1.0, 0.0])
GREY = Material("grey", np.full(3, 0.5), roughness=0.6)


def _rot_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def _boxes(specs, material: Material = GREY) -> Asset:
    """Closed flat-shaded boxes ((size (3,), centre (3,), rotation (3, 3)) each), resting on z = 0."""
    Vs, Fs, Ns = [], [], []
    for size, centre, R in specs:
        size = np.asarray(size, dtype=np.float64)
        V, F = box_mesh(-size / 2, size / 2)
        V = V @ np.asarray(R).T + np.asarray(centre, dtype=np.float64)
        fn, _ = face_normals(V, F)
        N = np.zeros_like(V)
        for k in range(3):
            N[F[:, k]] = fn
        Fs.append(F + sum(len(v) for v in Vs))
        Vs.append(V)
        Ns.append(N)
    V = np.concatenate(Vs)
    V[:, 2] -= V[:, 2].min()
    F = np.concatenate(Fs)
    return Asset("test_boxes", V, F, np.zeros(len(F), np.int64), (material,), np.concatenate(Ns))


def _tube() -> Asset:
    """A 2 cm x 2 cm x 2 m post (a bicycle frame tube stood up)."""
    return _boxes([((0.02, 0.02, 2.0), (0.0, 0.0, 1.0), np.eye(3))])


def _spokes() -> Asset:
    """Nine 5 mm x 5 mm x 1.2 m spokes 15 cm apart, upright and tilted by +-30 / 45 degrees (facing the camera)."""
    ys = np.linspace(-0.6, 0.6, 9)
    tilts = np.tile([0.0, 30.0, -45.0], 3)
    return _boxes([((0.005, 0.005, 1.2), (0.0, y, 0.7), _rot_x(t)) for y, t in zip(ys, tilts)])


def _projected_area_px(asset: Asset, T: np.ndarray) -> float:
    """Exact projected area (pixels) of non-overlapping convex boxes (24 vertices each): the sum of their hulls."""
    total = 0.0
    for b in range(0, len(asset.vertices), 24):
        uv, _ = CAMERA.project(asset.vertices[b:b + 24] @ T[:3, :3].T + T[:3, 3])
        total += cv2.contourArea(cv2.convexHull(uv.astype(np.float32)))
    return total


# ----------------------------------------------------------------------------- retro-reflection


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_retro_lobe_nonnegative_reciprocal_and_zero_without_retro():
    rng = np.random.default_rng(0)
    N = 2000
    n = np.tile([0.0, 0.0, 1.0], (N, 1))
    v = _unit(rng.normal(size=(N, 3)) * [1, 1, 0.3] + [0, 0, 1])
    l = _unit(v + rng.normal(scale=0.01, size=(N, 3)))  # near-coaxial pairs, where the lobe is large
    p = BRDFParams.uniform(N, base_color=(0.8, 0.6, 0.1), retroreflective=1.0)
    f = retro_lobe(n, v, l, p)
    assert np.all(f >= 0) and f.max() > 100.0
    np.testing.assert_allclose(f, retro_lobe(n, l, v, p), rtol=1e-12)  # reciprocity
    assert np.all(retro_lobe(n, v, l, BRDFParams.uniform(N, retroreflective=0.0)) == 0)
    zeros = BRDFParams.uniform(N)
    assert zeros.retroreflective is None and not zeros.has_retro
    np.testing.assert_array_equal(retro_env_factor(n, v, zeros), 0.0)


def test_retro_lobe_is_energy_plausible():
    """Coaxial R_A of a few hundred cd/lx/m^2, none at 90 deg, returned energy <= RETRO_ALBEDO x base colour."""
    n = np.array([[0.0, 0.0, 1.0]])
    p = BRDFParams.uniform(1, base_color=(0.8, 0.8, 0.8), retroreflective=1.0)
    l = _unit([[0.0, np.sin(np.radians(4)), np.cos(np.radians(4))]])  # ASTM entrance angle -4 deg
    obs = _unit(l + [[np.radians(0.2), 0.0, 0.0]])  # observation angle 0.2 deg
    R_A = retro_lobe(n, obs, l, p)[0, 1] * (n @ l[0])[0] * (n @ obs[0])[0]  # cd/lx/m^2 == 1/sr
    assert 100.0 < R_A < 1000.0, R_A
    side = _unit([[1.0, 0.0, 1.0]])
    other = _unit([[-1.0, 0.0, 1.0]])
    assert retro_lobe(n, side, other, p)[0, 1] == 0.0
    # Directional albedo of the lobe (integrated over viewing directions around l): the returned fraction.
    u = np.random.default_rng(1).random((200_000, 2))
    cone = 8 * np.radians(0.4)
    views = sample_cone(l[0], cone, u[:, 0], u[:, 1])
    solid = 2 * np.pi * (1 - np.cos(cone))
    ls = np.repeat(l, len(views), axis=0)
    albedo = (retro_lobe(np.repeat(n, len(views), 0), views, ls, p.take(np.zeros(len(views), int)))[:, 1]
              * (views @ n[0])).mean() * solid
    assert albedo <= RETRO_ALBEDO * 0.8 * 1.01 and albedo > 0.5 * RETRO_ALBEDO * 0.8
    base = eval_brdf(n, side, other, p)[0, 1] * np.pi  # the base BRDF is untouched by retro
    assert base == eval_brdf(n, side, other, BRDFParams.uniform(1, base_color=(0.8, 0.8, 0.8)))[0, 1] * np.pi


T_PANEL = pose_camera_to_transform(0.0, 0.5, 8.0, 0.0)  # a 1 m x 1 m plate 8 m ahead, its -x face to the camera


def _panel(retro: float) -> Asset:
    return _boxes([((0.02, 1.0, 1.0), (0.0, 0.0, 0.5), np.eye(3))],
                  Material("band", np.full(3, 0.8), roughness=0.6, retroreflective=retro))


def _panel_centre_radiance(sun_dir_cam: np.ndarray, retro: float, seed: int = 0) -> tuple[np.ndarray, object]:
    light = sunny_light(sun_dir_cam=sun_dir_cam)
    image, depth, ev = ground_scene(light, K, W, H)
    res = render_insertion(image, K, depth, light, _panel(retro), T_PANEL, ev=ev, seed=seed)
    centre = T_PANEL[:3, :3] @ [0.0, 0.0, 0.5] + T_PANEL[:3, 3]
    u, v = np.round(CAMERA.project(centre[None])[0][0]).astype(int)
    return res.object_radiance[v - 1:v + 2, u - 1:u + 2].mean(axis=(0, 1)), res


def test_retroreflective_plate_shines_back_at_a_light_behind_the_camera():
    centre = T_PANEL[:3, :3] @ [0.0, 0.0, 0.5] + T_PANEL[:3, 3]
    to_camera = _unit(-centre)
    sideways = _unit(0.9 * _unit(np.cross(to_camera, UP_CAM)) + 0.1 * UP_CAM)  # ~90 deg from the view, sun up
    plain, _ = _panel_centre_radiance(to_camera, 0.0)
    retro, res = _panel_centre_radiance(to_camera, 1.0)
    gain = retro / plain
    assert np.all(gain > 50.0), gain  # the sun behind the camera: hundreds of times a white paint
    assert np.all(res.object_radiance >= 0)
    plain_side, _ = _panel_centre_radiance(sideways, 0.0)
    retro_side, _ = _panel_centre_radiance(sideways, 1.0)
    side_gain = retro_side / plain_side
    # Sun at the side: the base BRDF, plus the sky behind the camera returned (a few per cent of white).
    assert np.all(side_gain >= 1.0) and np.all(side_gain < 1.15), side_gain


def test_retro_zero_changes_nothing():
    """retroreflective = 0: no retro tables at all, so the shading runs exactly the code of before."""
    prep = prepare_asset(_panel(0.0))
    assert prep.retroreflective is None
    a, _ = _panel_centre_radiance(_unit([0.6, -0.55, 0.58]), 0.0, seed=4)
    b, _ = _panel_centre_radiance(_unit([0.6, -0.55, 0.58]), 0.0, seed=4)
    np.testing.assert_array_equal(a, b)
    assert prepare_asset(_panel(0.5)).retroreflective.tolist() == [0.5]


# ----------------------------------------------------------------------------- thin structures


@pytest.fixture(scope="module")
def sunny():
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light, K, W, H)
    return light, image, depth, ev


@pytest.mark.parametrize("make, z", [(_tube, 15.0), (_tube, 20.0), (_spokes, 15.0), (_spokes, 20.0)])
def test_thin_geometry_alpha_matches_its_projected_area(sunny, make, z):
    light, image, depth, ev = sunny
    asset = make()
    T = pose_camera_to_transform(0.0, 1.5, z, 0.0)
    area = _projected_area_px(asset, T)
    sums = [render_insertion(image, K, depth, light, asset, T, ev=ev, seed=s).coverage for s in (0, 1)]
    ratio = np.mean([c.sum() for c in sums]) / area
    assert 0.85 < ratio < 1.15, (ratio, area)
    cov = sums[0]
    touched = cov > 0
    fractional = (cov > 0.01) & (cov < 0.99)
    assert fractional.sum() > 0.8 * touched.sum()  # sub-pixel parts: fractional alpha, not all-or-nothing
    if make is _spokes:
        assert cov.max() < 0.6  # 0.09 px wide: never a full pixel


def _sun_blocked_reference(asset: Asset, T: np.ndarray, light: DistantLight, box, n: int = 12, seed: int = 0) -> np.ndarray:
    """Fraction of the sun disc hidden from each pixel's ground (plane 1.5 m below the camera), n x n points per pixel."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = box
    ys, xs = np.mgrid[y0:y1, x0:x1]
    g = (np.arange(n) + 0.5) / n - 0.5
    ox, oy = np.meshgrid(g, g)
    uv = (np.stack([xs.ravel(), ys.ravel()], 1)[:, None] + np.stack([ox.ravel(), oy.ravel()], 1)[None]).reshape(-1, 2)
    rays = CAMERA.rays(uv, unit=False)
    down = rays @ -UP_CAM
    p_cam = rays * np.where(down > 1e-6, 1.5 / np.maximum(down, 1e-6), 0.0)[:, None]
    Ti = invert_transform(T)
    p_obj = p_cam @ Ti[:3, :3].T + Ti[:3, 3]
    s_obj = T[:3, :3].T @ light.sun.direction
    dirs = sample_cone(s_obj, light.sun.half_angle_rad, rng.random(len(uv)), rng.random(len(uv)))
    hit = prepare_asset(asset).scene.occluded(p_obj + [0.0, 0.0, 0.01], dirs) & (down > 1e-6)
    return hit.reshape(-1, n * n).mean(axis=1).reshape(y1 - y0, x1 - x0)


@pytest.mark.parametrize("sun", [(0.6, -0.55, 0.58), (0.0, -0.6, 0.8)])
@pytest.mark.parametrize("make", [_tube, _spokes])
def test_thin_geometry_casts_a_faint_fractional_shadow(make, sun):
    """The shadow of sub-pixel parts: summed darkening = a dense reference's (same geometry), each pixel only partly dark."""
    light = sunny_light(sun_dir_cam=sun, sky=(0.002, 0.002, 0.002), ground=0.001)  # the sun is ~all the light
    image, depth, ev = ground_scene(light, K, W, H)
    asset = make()
    T = pose_camera_to_transform(0.0, 1.5, 15.0, 0.0)
    deficits = []
    for seed in (0, 1):
        res = render_insertion(image, K, depth, light, asset, T, ev=ev, seed=seed)
        x0, y0, x1, y1 = box = res.stats["shadow"]["box"]
        ground = res.coverage[y0:y1, x0:x1] == 0
        d = (1.0 - res.shadow_ratio)[y0:y1, x0:x1]
        deficits.append(float(d[ground].sum()))
    ref = _sun_blocked_reference(asset, T, light, box)[ground].sum()
    assert ref > 1.5  # the reference shadow is there (pixels' worth)
    assert 0.7 < np.mean(deficits) / ref < 1.3, (deficits, ref)
    assert 0.0 < d.max() < 0.8  # darkened, fractionally


# ----------------------------------------------------------------------------- contact shadows


PED_BOX = ((0.3, 0.3, 1.7), (0.0, 0.0, 0.85), np.eye(3))


def _ground_ratio(res, T: np.ndarray, points_obj: np.ndarray) -> np.ndarray:
    """Ratio map bilinear at object-frame ground points (P, 3), NaN where the object covers the pixel or off-image."""
    uv, _ = CAMERA.project(points_obj @ T[:3, :3].T + T[:3, 3])
    out = np.full(len(uv), np.nan)
    for i, (u, v) in enumerate(uv):
        if 0 <= u < W - 1 and 0 <= v < H - 1 and res.coverage[int(round(v)), int(round(u))] < 0.01:
            out[i] = cv2.getRectSubPix(res.shadow_ratio, (1, 1), (float(u), float(v)))[0, 0]
    return out


def test_contact_shadow_under_a_sky_only():
    """A 0.3 x 0.3 x 1.7 m box under a uniform sky (no sun): dark at its base, fading to ~1 at 1.5 m."""
    d = camera_envmap_directions(32, 64)
    env = (np.where((d @ UP_CAM > 0)[..., None], 1.0, 0.2) * np.ones(3)).astype(np.float32)
    light = DistantLight(env, None)
    image, depth, ev = ground_scene(light, K, W, H)
    T = pose_camera_to_transform(0.0, 1.5, 7.0, 30.0)
    res = render_insertion(image, K, depth, light, _boxes([PED_BOX]), T, ev=ev, seed=0)
    faces = np.array([[-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])  # the faces towards the camera and at the sides
    def at(dist):
        return _ground_ratio(res, T, np.c_[faces * (0.15 + dist), np.zeros(3)])
    near, far = at(0.05), at(1.5)
    assert np.isfinite(near).sum() >= 1 and np.isfinite(far).sum() >= 2
    assert np.nanmax(near) < 0.85, near
    assert np.nanmin(far) > 0.97, far
    assert np.nanmean(at(0.3)) > np.nanmean(near)  # fades with distance


def test_contact_shadow_with_the_sun_falls_away_from_it():
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))  # to the camera's right, ahead
    image, depth, ev = ground_scene(light, K, W, H)
    T = pose_camera_to_transform(0.0, 1.5, 7.0, 30.0)
    res = render_insertion(image, K, depth, light, _boxes([PED_BOX]), T, ev=ev, seed=0)
    hard = (res.shadow_ratio < 0.5) & (res.coverage < 0.01)
    assert hard.sum() > 20
    # The hard shadow lies on the ground on the side away from the sun: towards object-frame -s (horizontal).
    ys, xs = np.nonzero(hard)
    obj_x = np.nonzero(res.coverage > 0.5)[1].mean()
    assert xs.mean() < obj_x - 3  # sun on the right -> shadow to the left
