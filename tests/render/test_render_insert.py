"""Renderer end to end: white furnace, shadows, occlusion, anti-aliasing, byte-identity, determinism."""


import numpy as np
import pytest

from render_fixtures import ground_scene, primitive_car, sphere_asset, sunny_light
from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.core import (InputError, hdr_to_ldr_uint8, intrinsics_from_fov, invert_transform,
                                    ldr_uint8_to_hdr, pose_camera_to_transform, unproject_depth)
from streetaug.augment.lighting.light import DistantLight, SunLight
from streetaug.augment.render import QUALITY_PRESETS, RenderSettings, render_insertion, shade, shadow
from streetaug.augment.render.brdf import BRDFParams, eval_brdf
from streetaug.augment.render.composite import composite, depth_visibility

W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)
T_SIDE = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)  # the car 12 m ahead, seen from its side


@pytest.fixture(scope="module")
def car():
    return primitive_car()


@pytest.fixture(scope="module")
def scene():
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))  # sun to the camera's right, ahead
    image, depth, ev = ground_scene(light, K, W, H)
    return light, image, depth, ev


@pytest.fixture(scope="module")
def result(car, scene):
    light, image, depth, ev = scene
    return render_insertion(image, K, depth, light, car, T_SIDE, ev=ev, seed=3)


def test_white_furnace_sphere():
    """A white Lambertian sphere under a constant unit environment reflects radiance 1."""
    light = DistantLight(np.ones((32, 64, 3), np.float32), None)
    sphere = sphere_asset(1.0)
    image = np.full((H, W, 3), 128, np.uint8)
    depth = np.full((H, W), np.inf, np.float32)
    T = pose_camera_to_transform(0.0, 0.0, 6.0, 0.0)
    T[:3, 3] -= T[:3, 2] * 1.0  # centre the sphere on the optical axis
    res = render_insertion(image, K, depth, light, sphere, T, quality="default", seed=0)
    inside = res.coverage > 0.999
    assert inside.sum() > 2000
    rad = res.object_radiance[inside]
    assert abs(rad.mean() - 1.0) < 0.01, rad.mean()
    assert np.percentile(np.abs(rad - 1.0), 95) < 0.35  # per-pixel noise stays moderate


def test_shadow_ratio_one_far_and_below_one_under(result, car, scene):
    S = result.shadow_ratio
    assert S.shape == (H, W) and S.dtype == np.float32
    assert np.all(S <= 1.0) and np.all(S >= 0.0)
    assert np.all(S[:40] == 1.0)  # sky and far ground: exactly unchanged
    assert S[:, -12:].min() > 0.99  # metres away on the sunny side only a sliver of sky is blocked
    x0, y0, x1, y1 = result.stats["shadow"]["box"]
    assert (y1 - y0) < 0.5 * H  # the ratio map is only computed near the object
    # Ground points under the car's body (object frame |x| < 1.5 m, |y| < 0.6 m) that the camera sees
    # between the wheels: the body hides the sun and most of the sky from them.

    ys, xs = np.nonzero((result.coverage == 0) & np.isfinite(scene[2]))
    p_cam = unproject_depth(K, np.stack([xs, ys], 1).astype(float), scene[2][ys, xs])
    p_obj = p_cam @ invert_transform(T_SIDE)[:3, :3].T + invert_transform(T_SIDE)[:3, 3]
    under = (np.abs(p_obj[:, 0]) < 1.5) & (np.abs(p_obj[:, 1]) < 0.6)
    assert under.sum() > 20
    assert np.median(S[ys[under], xs[under]]) < 0.5


def test_sun_shadow_falls_opposite_the_sun(result):
    """Sun on the right (+x) -> the shadow lies left of the car; it is darker than any sky-only occlusion."""
    S = result.shadow_ratio
    shadow = (S < 0.6) & (result.coverage < 0.01)
    assert shadow.sum() > 50
    ys, xs = np.nonzero(shadow)
    car_x = np.nonzero(result.coverage > 0.5)[1].mean()
    assert xs.mean() < car_x - 5


def test_shadow_moves_with_the_sun(car):
    light_l = sunny_light(sun_dir_cam=(-0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light_l, K, W, H)
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)
    res = render_insertion(image, K, depth, light_l, car, T, ev=ev, seed=3)
    ys, xs = np.nonzero((res.shadow_ratio < 0.6) & (res.coverage < 0.01))
    assert xs.mean() > np.nonzero(res.coverage > 0.5)[1].mean() + 5


def test_untouched_pixels_byte_identical(result, scene):
    _, image, _, _ = scene
    untouched = (result.mask == 0) & np.all(result.shadow_ratio_rgb == 1.0, axis=2)
    assert untouched.sum() > 0.5 * H * W
    np.testing.assert_array_equal(result.image[untouched], image[untouched])
    changed = np.any(result.image != image, axis=2)
    assert changed.sum() > 500  # the car and its shadow are there


def test_silhouette_pixels_get_fractional_alpha(result):
    cov = result.coverage
    frac = (cov > 0.05) & (cov < 0.95)
    full = cov >= 0.999
    assert full.sum() > 500
    assert frac.sum() > 40
    # fractional pixels sit on the boundary of the full region, not inside it
    assert frac.sum() < 0.5 * full.sum()


def test_depth_test_hides_object_behind_nearer_plane(car, scene):
    light, image, _, ev = scene
    wall = np.full((H, W), 5.0, np.float32)  # a plane 5 m ahead, the car 12 m away
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)
    res = render_insertion(image, K, wall, light, car, T, ev=ev, seed=0)
    assert res.coverage.sum() > 500
    assert res.mask.max() < 1e-6
    car_px = res.coverage > 0.5
    np.testing.assert_array_equal(res.image[car_px], image[car_px])


def test_partial_occlusion_soft_edge():
    obj = np.full((5, 8), 10.0)
    scene = np.full((5, 8), np.inf)
    scene[:, :4] = 8.0  # something 2 m nearer covers the left half
    vis = depth_visibility(obj, scene)
    assert np.all(vis[:, :3] == 0) and np.all(vis[:, 5:] == 1)
    assert 0 < vis[2, 3] < 1 and 0 < vis[2, 4] < 1  # one pixel of blur across the boundary


def test_composite_formula():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (4, 5, 3)).astype(np.uint8)

    rad = np.full((4, 5, 3), 0.3, np.float32)
    cov = np.zeros((4, 5), np.float32)
    cov[1, 1] = 0.5
    vis = np.ones((4, 5), np.float32)
    S = np.ones((4, 5, 3), np.float32)
    S[2, 3] = 0.4
    out = composite(img, rad * cov[..., None], cov, vis, S, ev=0.5)
    I = ldr_uint8_to_hdr(img, 0.5).astype(np.float64)
    exp11 = hdr_to_ldr_uint8((0.5 * 0.3 + 0.5 * I[1, 1])[None, None], 0.5)[0, 0]
    exp23 = hdr_to_ldr_uint8((I[2, 3] * 0.4)[None, None], 0.5)[0, 0]
    np.testing.assert_array_equal(out[1, 1], exp11)
    np.testing.assert_array_equal(out[2, 3], exp23)
    keep = np.ones((4, 5), bool)
    keep[1, 1] = keep[2, 3] = False
    np.testing.assert_array_equal(out[keep], img[keep])


def test_deterministic_for_a_seed(car, scene):
    light, image, depth, ev = scene
    T = pose_camera_to_transform(1.0, 1.5, 14.0, 30.0)
    a = render_insertion(image, K, depth, light, car, T, ev=ev, seed=7, quality="draft")
    b = render_insertion(image, K, depth, light, car, T, ev=ev, seed=7, quality="draft")
    c = render_insertion(image, K, depth, light, car, T, ev=ev, seed=8, quality="draft")
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.shadow_ratio, b.shadow_ratio)
    assert np.any(a.image != c.image)


def test_glass_reflects_and_is_darker_than_paint(car, scene):
    light, image, depth, ev = scene
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)
    res = render_insertion(image, K, depth, light, car, T, ev=ev, seed=1, quality="draft")
    # glass (cabin) occupies the top of the object; the paint is below it
    rows = np.flatnonzero(res.coverage.max(axis=1) > 0.99)
    top = res.object_radiance[rows[1]][res.coverage[rows[1]] > 0.99].mean(axis=0)
    assert np.all(top > 0)  # reflection, not black
    assert top.sum() < 2.0 * res.object_radiance[res.coverage > 0.99].mean(axis=0).sum()


def test_presets_and_bad_quality(car, scene):
    assert set(QUALITY_PRESETS) >= {"draft", "default", "high"}
    d, m, h = (QUALITY_PRESETS[k] for k in ("draft", "default", "high"))
    assert d.aa_grid <= m.aa_grid <= h.aa_grid and d.shadow_sky_dirs < m.shadow_sky_dirs < h.shadow_sky_dirs
    light, image, depth, ev = scene
    with pytest.raises(InputError, match="quality"):
        render_insertion(image, K, depth, light, car, np.eye(4), quality="ultra")
    with pytest.raises(ValueError):
        RenderSettings(aa_grid=0)


def test_object_behind_camera_changes_nothing(car, scene):
    light, image, depth, ev = scene
    T = pose_camera_to_transform(0.0, 1.5, -20.0, 0.0)
    res = render_insertion(image, K, depth, light, car, T, ev=ev)
    np.testing.assert_array_equal(res.image, image)
    assert res.coverage.max() == 0


@pytest.mark.parametrize("what", ["no faces", "nan", "zero area"])
def test_degenerate_asset_clear_error(what, scene):
    light, image, depth, ev = scene
    mat = (Material("m", np.ones(3)),)
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2]])
    if what == "no faces":
        F = np.zeros((0, 3), np.int64)
    elif what == "nan":
        V[1, 0] = np.nan
    else:
        V[:] = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    asset = Asset("bad", V, F, np.zeros(len(F), np.int64), mat, np.tile([0, 0, 1.0], (3, 1)))
    with pytest.raises(InputError, match="bad"):
        render_insertion(image, K, depth, light, asset, pose_camera_to_transform(0, 1.5, 10, 0))


def test_bad_inputs(car, scene):
    light, image, depth, ev = scene
    T = pose_camera_to_transform(0, 1.5, 10, 0)
    with pytest.raises(InputError, match="depth"):
        render_insertion(image, K, depth[:-1], light, car, T)
    with pytest.raises(InputError, match="uint8"):
        render_insertion(image.astype(np.float32), K, depth, light, car, T)


def test_chunked_shading_matches_one_batch(car, scene, monkeypatch):
    """Splitting the shading into memory-bounded chunks changes the noise, not the image."""

    light, image, depth, ev = scene
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)
    a = render_insertion(image, K, depth, light, car, T, ev=ev, seed=1, quality="draft")
    monkeypatch.setattr(shade, "SHADE_CHUNK_RAYS", 999)
    monkeypatch.setattr(shadow, "SHADOW_CHUNK_RAYS", 5000)
    b = render_insertion(image, K, depth, light, car, T, ev=ev, seed=1, quality="draft")
    np.testing.assert_array_equal(a.coverage, b.coverage)
    sel = a.coverage > 0.99
    assert abs(a.object_radiance[sel].mean() - b.object_radiance[sel].mean()) < 0.03 * a.object_radiance[sel].mean()
    assert np.abs(a.shadow_ratio - b.shadow_ratio).mean() < 0.01


def test_furnace_white_metal_matches_albedo():
    """A white rough metal under a constant unit environment reflects its directional albedo (MIS path)."""

    light = DistantLight(np.ones((32, 64, 3), np.float32), None)
    sphere = sphere_asset(1.0, Material("metal", np.ones(3), metallic=1.0, roughness=0.5))
    T = pose_camera_to_transform(0.0, 0.0, 6.0, 0.0)
    T[:3, 3] -= T[:3, 2] * 1.0
    res = render_insertion(np.full((H, W, 3), 128, np.uint8), K, np.full((H, W), np.inf, np.float32), light,
                           sphere, T, quality="high", seed=0)
    cx, cy = int(round(K[0, 2])), int(round(K[1, 2]))
    centre = res.object_radiance[cy - 6 : cy + 7, cx - 6 : cx + 7].reshape(-1, 3)  # n.v ~ 1 there
    rng = np.random.default_rng(0)
    z = rng.random(400_000)
    phi = rng.random(400_000) * 2 * np.pi
    l = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1)
    n = np.tile([0, 0, 1.0], (len(z), 1))
    albedo = (eval_brdf(n, n, l, BRDFParams.uniform(len(z), (1, 1, 1), 1.0, 0.5)) * z[:, None]).mean() * 2 * np.pi
    assert 0.5 < albedo < 1.0
    assert abs(centre.mean() - albedo) < 0.03, (centre.mean(), albedo)


def test_base_color_texture_is_sampled_by_uv():
    """A quad facing the camera with a half-red / half-blue texture renders red on one side, blue on the other."""
    # Object frame: x front, y left, z up.  The quad lies in the y-z plane facing -x (towards a camera behind it).
    V = np.array([[0, 1.0, 0], [0, -1.0, 0], [0, -1.0, 2.0], [0, 1.0, 2.0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])  # counter-clockwise seen from -x: the front faces the camera
    uv = np.array([[0, 1.0], [1, 1.0], [1, 0.0], [0, 0.0]])  # glTF uv: v = 0 at the top row
    tex = np.zeros((4, 4, 3), np.float32)
    tex[:, :2] = [1, 0, 0]
    tex[:, 2:] = [0, 0, 1]
    mat = Material("tex", np.ones(3), roughness=1.0, specular=0.0, base_color_texture=tex)
    asset = Asset("quad", V, F, np.zeros(2, np.int64), (mat,), np.tile([-1.0, 0, 0], (4, 1)), uv=uv)
    light = DistantLight(np.ones((16, 32, 3), np.float32), None)
    T = pose_camera_to_transform(0.0, 1.0, 6.0, 0.0)  # front along +z: the quad's -x side faces the camera
    res = render_insertion(np.full((H, W, 3), 100, np.uint8), K, np.full((H, W), np.inf, np.float32), light,
                           asset, T, quality="draft")
    ys, xs = np.nonzero(res.coverage > 0.99)
    assert len(xs) > 500
    rad = res.object_radiance
    left = rad[ys[xs < xs.mean() - 5], xs[xs < xs.mean() - 5]].mean(axis=0)
    right = rad[ys[xs > xs.mean() + 5], xs[xs > xs.mean() + 5]].mean(axis=0)
    # object +y (left of the object) is image-left when its front points away from the camera; uv u=0 there = red
    assert left[0] > 5 * left[2] and right[2] > 5 * right[0], (left, right)


def _textured_quad(material):
    """The quad of the base-colour test (facing a camera behind it, uv u = 0 on the image's left)."""
    V = np.array([[0, 1.0, 0], [0, -1.0, 0], [0, -1.0, 2.0], [0, 1.0, 2.0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])  # counter-clockwise seen from -x: the front faces the camera
    uv = np.array([[0, 1.0], [1, 1.0], [1, 0.0], [0, 0.0]])
    return Asset("quad", V, F, np.zeros(2, np.int64), (material,), np.tile([-1.0, 0, 0], (4, 1)), uv=uv)


def _left_right(res):
    ys, xs = np.nonzero(res.coverage > 0.99)
    assert len(xs) > 500
    rad = res.object_radiance
    left = rad[ys[xs < xs.mean() - 5], xs[xs < xs.mean() - 5]].mean(axis=0)
    right = rad[ys[xs > xs.mean() + 5], xs[xs > xs.mean() + 5]].mean(axis=0)
    return left, right


def test_metallic_roughness_texture_is_sampled_by_uv():
    """glTF metallic-roughness texture (B = metallic): the metal half (left) loses its diffuse light."""
    mr = np.ones((4, 4, 3), np.float32)  # G = roughness 1
    mr[:, 2:, 2] = 0.0  # right half dielectric, left half metal
    mat = Material("mr", np.array([0.8, 0.1, 0.1]), metallic=1.0, roughness=1.0, metallic_roughness_texture=mr)
    light = DistantLight(np.ones((16, 32, 3), np.float32), None)
    T = pose_camera_to_transform(0.0, 1.0, 6.0, 0.0)
    res = render_insertion(np.full((H, W, 3), 100, np.uint8), K, np.full((H, W), np.inf, np.float32), light,
                           _textured_quad(mat), T, quality="draft")
    left, right = _left_right(res)
    assert left[0] < 0.6 * right[0], (left, right)  # rough metal: ~0.3 of base; dielectric: base + 4 %


def test_normal_map_tilts_the_shading_normal():
    """A tangent-space normal map tilting the left half towards the sun makes that half brighter."""
    nmap = np.empty((4, 4, 3), np.float32)
    nmap[:, :2] = [0.5 + 0.5 * 0.6, 0.5, 0.5 + 0.5 * 0.8]  # (0.6, 0, 0.8): tilted along +u (tangent)
    nmap[:, 2:] = [0.5, 0.5, 1.0]  # flat
    mat = Material("nm", np.full(3, 0.7), roughness=1.0, specular=0.0, normal_texture=nmap)
    T = pose_camera_to_transform(0.0, 1.0, 6.0, 0.0)
    # Object frame: the quad faces -x, its tangent (+u) is -y; the sun comes from -x, -y, a little above.
    s_obj = np.array([-1.0, -1.0, 0.3]) / np.linalg.norm([-1.0, -1.0, 0.3])

    light = DistantLight(np.full((16, 32, 3), 0.02, np.float32), SunLight(T[:3, :3] @ s_obj, np.full(3, 3.0)))
    res = render_insertion(np.full((H, W, 3), 100, np.uint8), K, np.full((H, W), np.inf, np.float32), light,
                           _textured_quad(mat), T, quality="draft")
    left, right = _left_right(res)
    # n.s: tilted (-0.8, -0.6, 0) . s = 0.97, flat (-1, 0, 0) . s = 0.69
    assert 1.25 < left.mean() / right.mean() < 1.55, (left, right)
