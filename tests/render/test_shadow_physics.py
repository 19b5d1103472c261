"""The sky a car hides, against closed forms: a black plate at a car's clearance under a uniform overcast sky.

The ground under a plate (parallel to the ground, height ``c``) sees the sky except through the plate, so its
ratio is ``1 - F`` with ``F`` the view factor from a ground point to the plate's rectangle (the corner formula
of a differential area under a parallel rectangle, summed with signs over the four corners).  A black plate
sends no bounce light: the ratio map must follow ``1 - F`` everywhere, including the soft edge (whose width
the clearance sets) and the deep shadow under the middle, without blotches from sampling noise.
"""

import numpy as np
import pytest
import trimesh

from render_fixtures import plane_shadow, primitive_car, sunny_light, two_level_sky
from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render.shadow import _Ground

W, H = 640, 360
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])
T = pose_camera_to_transform(0.0, 1.5, 7.0, 30.0)
DEPTH = ground_plane_depth(K, W, H, UP, 1.5)
CLEARANCE_M = 0.2  # a car's underbody height
HALF_M = np.array([2.2, 0.9])  # half length, half width of the plate (a car's footprint)


def black_plate(clearance_m: float = CLEARANCE_M) -> Asset:
    """A 4.4 x 1.8 m plate, 2 mm thick, albedo 0, its underside ``clearance_m`` above the ground (object frame)."""
    box = trimesh.creation.box(extents=[2 * HALF_M[0], 2 * HALF_M[1], 0.002])
    box.apply_translation([0.0, 0.0, clearance_m + 0.001])
    V = box.vertices[box.faces].reshape(-1, 3)
    F = np.arange(len(V)).reshape(-1, 3)
    N = np.repeat(box.face_normals, 3, axis=0)
    black = Material("black", np.zeros(3), metallic=0.0, roughness=1.0, specular=0.0)
    return Asset("black_plate", V, F, np.zeros(len(F), np.int64), (black,), N)


def corner_view_factor(a: np.ndarray, b: np.ndarray, c: float) -> np.ndarray:
    """View factor from a differential ground area to a parallel a x b rectangle at height c above one of its
    corners (signed: negative a or b flips the sign, for superposition)."""
    x, y = np.abs(a) / c, np.abs(b) / c
    sx, sy = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    f = (x / sx * np.arctan(y / sx) + y / sy * np.arctan(x / sy)) / (2 * np.pi)
    return np.sign(a) * np.sign(b) * f


def plate_view_factor(p_xy: np.ndarray, half: np.ndarray, c: float) -> np.ndarray:
    """(N,) view factor from ground points (N, 2) to the rectangle [-half, half] at height c."""
    dx0, dx1 = -half[0] - p_xy[:, 0], half[0] - p_xy[:, 0]
    dy0, dy1 = -half[1] - p_xy[:, 1], half[1] - p_xy[:, 1]
    F = corner_view_factor
    return F(dx1, dy1, c) - F(dx0, dy1, c) - F(dx1, dy0, c) + F(dx0, dy0, c)


def _map(light: DistantLight, seed: int = 0):
    """(ratio (N,), analytic 1 - F (N,), ground points (N, 3), (h, w)) over the plate's shadow box."""
    box, sh = plane_shadow(CAMERA, black_plate(), T, UP, light, DEPTH, seed=seed)
    ys, xs = np.mgrid[box.y0:box.y1, box.x0:box.x1]
    uv = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    p, ok = _Ground(CAMERA, DEPTH, UP, T).points_obj(uv)
    assert ok.all()
    expected = 1.0 - plate_view_factor(p[:, :2], HALF_M, CLEARANCE_M)
    return sh.ratio_rgb.mean(axis=2).ravel(), expected, p, (box.height, box.width)


def _uniform_sky() -> DistantLight:
    """Overcast: sky radiance 1 above the horizon, the unshadowed ground's 0.2 below; no sun."""
    return DistantLight(two_level_sky(UP, 1.0, 0.2), None)


def test_corner_view_factor_limits():
    """The closed form: a rectangle covering the whole sky above a corner gives 1/4; superposed, 1 under the
    middle of an infinite plate, and 1/2 under the edge of a half-plane."""
    assert corner_view_factor(np.array([1e6]), np.array([1e6]), 1.0)[0] == pytest.approx(0.25, abs=1e-5)
    big = np.array([1e6, 1e6])
    assert plate_view_factor(np.zeros((1, 2)), big, 0.2)[0] == pytest.approx(1.0, abs=1e-5)
    assert plate_view_factor(np.array([[0.0, 1e6]]), big, 0.2)[0] == pytest.approx(0.5, abs=1e-5)


@pytest.fixture(scope="module")
def uniform_map():
    return _map(_uniform_sky())


def test_ratio_under_a_car_sized_plate_is_the_view_factor(uniform_map):
    """Everywhere around and under the plate, the ratio is 1 - F (the sky it hides), within sampling noise."""
    r, expected, p, _ = uniform_map
    err = r - expected
    assert np.median(np.abs(err)) < 0.01, np.median(np.abs(err))
    assert np.percentile(np.abs(err), 99) < 0.05, np.percentile(np.abs(err), 99)
    under = np.all(np.abs(p[:, :2]) < HALF_M - 0.3, axis=1)  # well inside: 1 - F = 0.03 .. 0.2
    assert under.sum() > 200
    assert np.abs(np.mean(err[under])) < 0.01 and np.percentile(np.abs(err[under]), 95) < 0.03


def test_edge_of_the_shadow_is_as_soft_as_the_clearance_makes_it(uniform_map):
    """Across the plate's long side the ratio rises from the deep shadow to open ground over a width set
    by the clearance (analytic 10-90 % of the rise); the map's rise has that width (no hard step, no blur)."""
    r, expected, p, _ = uniform_map
    band = np.abs(p[:, 0]) < 1.0  # the middle of the long side
    y = np.abs(p[band, 1]) - HALF_M[1]  # signed distance from the edge (m), outside > 0
    edges = np.arange(-0.5, 0.8, 0.05)
    prof = np.array([np.median(r[band][(y >= a) & (y < a + 0.05)]) for a in edges])
    ref = np.array([np.median(expected[band][(y >= a) & (y < a + 0.05)]) for a in edges])
    assert np.all(np.isfinite(prof))
    assert np.abs(prof - ref).max() < 0.04, np.round(prof - ref, 3)

    def width(v):
        lo, hi = v.min() + 0.1 * np.ptp(v), v.min() + 0.9 * np.ptp(v)
        return np.interp(hi, v, edges) - np.interp(lo, v, edges)  # v rises with the distance

    assert width(prof) == pytest.approx(width(ref), rel=0.25)


def test_deep_shadow_under_a_street_sky_is_the_sky_through_the_gap():
    """Under a zenith-heavy sky (a street: radiance 0.15 below 30 deg, 1.5 above, like scene-0916's local light)
    the ground more than ``c / tan 30 deg`` inside the plate's edge sees only the dim low sky through the gap:
    ratio ``0.15 pi (1 - F) / E`` with ``E = pi (0.15 sin^2 30 + 1.5 cos^2 30)``, about 0.3-1 %.  The map has that
    value (not E minus a sampled estimate of E, whose few-per-cent error is the whole signal there: a deep
    shadow several times too light, or clipped to black), with no pixel blacked out by sampling noise."""
    from streetaug.augment.core import camera_envmap_directions

    low, high, split = 0.15, 1.5, np.radians(30.0)
    d = camera_envmap_directions(64, 128)
    elev = np.arcsin(np.clip(d @ UP, -1.0, 1.0))
    sky = np.where(elev > split, high, np.where(elev > 0.0, low, 0.13))
    light = DistantLight((sky[..., None] * np.ones(3)).astype(np.float32), None)
    E = np.pi * (low * np.sin(split) ** 2 + high * np.cos(split) ** 2)
    maps = [_map(light, seed=s) for s in range(3)]
    r = np.stack([m[0] for m in maps])
    p, open_uniform = maps[0][2], maps[0][1]
    deep = np.all(np.abs(p[:, :2]) < HALF_M - CLEARANCE_M / np.tan(split) - 0.05, axis=1)
    assert deep.sum() > 200
    expected = low * np.pi * open_uniform[deep] / E
    mean = r[:, deep].mean(axis=0)
    assert abs(mean.mean() - expected.mean()) < 0.005, (mean.mean(), expected.mean())
    assert r[:, deep].min() > 0.2 * expected.min(), (r[:, deep].min(), expected.min())


def test_a_sun_of_zero_irradiance_traces_no_sun_rays_and_changes_nothing():
    """Overcast estimates keep the sun's direction with zero irradiance: its shadow is empty, so no rays."""
    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    up = np.array([0.0, -1.0, 0.0])
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 90.0)
    depth = ground_plane_depth(K, W, H, up, 1.5)
    car, camera = primitive_car(), PinholeCamera(K, W, H)
    _, dark_sun = plane_shadow(camera, car, T, up, sunny_light(sun_irradiance=0.0), depth, seed=0)
    _, lit_sun = plane_shadow(camera, car, T, up, sunny_light(sun_irradiance=8.0), depth, seed=0)
    assert lit_sun.stats["rays"].get("shadow_sun", 0) > 1000
    assert dark_sun.stats["rays"].get("shadow_sun", 0) == 0
    assert np.all(np.isfinite(dark_sun.ratio_rgb)) and dark_sun.ratio_rgb.min() >= 0.0
