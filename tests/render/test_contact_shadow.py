"""Contact shadow under a uniform sky: dark under the car, rising monotonically and smoothly to 1, no black band."""

import numpy as np
import pytest

from render_fixtures import plane_shadow, primitive_car, two_level_sky
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render import footprint, prepare_asset
from streetaug.augment.render.bounce import BounceLight
from streetaug.augment.render.shadow import _Ground, _sky_deficit

W, H = 480, 270
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])
CAR = primitive_car()
T = pose_camera_to_transform(0.0, 1.5, 8.0, 35.0)
PLANE_DEPTH = ground_plane_depth(K, W, H, UP, 1.5)


def _uniform_sky() -> DistantLight:
    """Sky radiance 1 above the horizon, the unshadowed ground's 0.2 (albedo 0.2) below; no sun."""
    return DistantLight(two_level_sky(UP, 1.0, 0.2), None)


def _ratio(depth=PLANE_DEPTH, seed=0):
    box, sh = plane_shadow(CAMERA, CAR, T, UP, _uniform_sky(), depth, seed=seed)
    return box, sh.ratio_rgb.mean(axis=2)


@pytest.fixture(scope="module")
def ground():
    """The map, and per box pixel: its ground point (object frame), whether the camera sees the ground there
    (not the car), whether it is under the car's box, and its distance (m) from the box's footprint."""
    box, r = _ratio()
    ys, xs = np.mgrid[box.y0:box.y1, box.x0:box.x1]
    uv = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    p, ok = _Ground(CAMERA, PLANE_DEPTH, UP, T).points_obj(uv)
    R, t = T[:3, :3], T[:3, 3]
    d_obj = CAMERA.rays(uv) @ R
    d_obj /= np.linalg.norm(d_obj, axis=1, keepdims=True)
    seen = ok & ~prepare_asset(CAR).scene.occluded(np.broadcast_to(-t @ R, d_obj.shape), d_obj)
    lo, hi = CAR.vertices.min(axis=0), CAR.vertices.max(axis=0)
    gap = np.maximum(np.maximum(lo[:2] - p[:, :2], p[:, :2] - hi[:2]), 0.0)
    inside = np.all((p[:, :2] >= lo[:2]) & (p[:, :2] <= hi[:2]), axis=1)
    return box, r.ravel(), p, seen, inside, np.sqrt((gap * gap).sum(axis=1))


def test_dark_under_the_car_rising_monotonically_to_one(ground):
    _, r, _, seen, inside, dist = ground
    under = np.median(r[seen & inside])
    edges = np.array([0.0, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0, 1.3, 1.6, 2.0, 2.5, 3.0, 3.5])
    prof = np.array([np.median(r[seen & ~inside & (dist >= a) & (dist < b)]) for a, b in zip(edges[:-1], edges[1:])])
    assert under < 0.4 and under < prof[0] < 0.8  # under the car darker than beside it, beside it < 1
    assert np.all(np.diff(prof) > -0.005), prof  # monotone with the distance from the footprint
    assert np.abs(np.diff(prof)).max() < 0.12, prof  # smooth: no step between neighbouring rings
    assert prof[-1] > 0.985 and np.all(r[seen & (dist > 3.6)] >= 0.995)  # ~1 away from it


def test_not_below_the_physical_floor_at_the_tyre_contacts(ground):
    """Visible ground near the tyres' contacts is as dark as the converged sky occlusion there, not darker
    (no black band from coarse cells inside the tyres or the body bleeding out), and never black."""
    box, r, p, seen, inside, _ = ground
    V = CAR.vertices
    contacts = V[V[:, 2] < 0.02]
    near = np.full(len(p), np.inf)
    for c in contacts[:: max(1, len(contacts) // 64)]:
        near = np.minimum(near, np.linalg.norm(p[:, :2] - c[:2], axis=1))
    sel = np.flatnonzero(seen & (near < 0.25))
    assert len(sel) > 30
    light, prep = _uniform_sky(), prepare_asset(CAR)
    b = BounceLight.build(light, prep, T, UP)
    D0, C = _sky_deficit(p[sel], np.array([0.0, 0.0, 1.0]), light, prep, b, 1024, T[:3, :3],
                         np.random.default_rng(1), {"rays": {}})
    E = b.env.sky_irradiance(UP)
    foot = 0.15
    dense = 1.0 - (D0 - C * foot).mean(axis=1) / E.mean()
    assert r[sel].min() >= dense.min() - 0.02  # the floor: the darkest the converged occlusion gets there
    assert np.percentile(dense - r[sel], 99) < 0.08  # no pixel much darker than the physics there
    assert np.percentile(dense - r[sel], 90) < 0.035
    assert np.median(np.abs(dense - r[sel])) < 0.02


def test_noisy_depth_near_the_car_gives_the_plane_contact_shadow():
    """Densified LiDAR depth is off by +-0.2 m in bands between rings; such ground is the plane for the
    shadow (no black band where points fall inside the tyres, no gap where they fall below them)."""
    _, clean = _ratio()
    rows = np.arange(H)[:, None]
    rays = CAMERA.rays(np.stack(np.meshgrid(np.arange(W), np.arange(H)), axis=-1).reshape(-1, 2).astype(np.float64),
                       unit=False)
    down = np.maximum(-(rays @ UP).reshape(H, W), 1e-6)  # metres of height per metre of z along each pixel ray
    height = 0.18 * (((rows % 9) / 4.0) - 1.0)  # a saw-tooth of +-0.18 m between "rings", every 9 rows
    noisy = PLANE_DEPTH + np.where(np.isfinite(PLANE_DEPTH), -height / down, 0.0)
    _, r = _ratio(noisy)
    assert np.abs(r - clean).mean() < 0.003 and np.percentile(np.abs(r - clean), 99.5) < 0.05
