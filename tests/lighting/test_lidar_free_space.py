"""What a LiDAR beam passed through is empty (augment/lighting/observe.py: lidar_passed_through): a camera pixel whose
densified depth put it there shows what the beam came back from, farther, and its volume point moves there.

The case behind it (benchmarks/diag_local_map_horizon.py, bundled sunny scene, the kerb car): a parked car's depth,
grown over the sky and facades above its roof, stood 1-2.5 m high in the voxels 4 m ahead of the inserted car, so
its glass mirrored a dark wall there instead of the sky down the street.
"""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.core import PinholeCamera, make_transform
from streetaug.augment.lighting import observe
from streetaug.augment.lighting.observe import (
    LIDAR_LOWEST_RING_DEG,
    LIDAR_N_RINGS,
    LIDAR_RING_DEG,
    lidar_passed_through,
    observe_view,
)
from streetaug.datasets.sample import CameraView

LIDAR_VOL = np.array([1.0, 0.0, 1.84])  # volume frame = ego frame here (ground z = 0)
BOX = (19.0, 21.0, 1.0, 1.2)  # a low object: x from, x to, |y| below, top (m)
WALL_X = 60.0


def _cast(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance (N,) along unit-or-not rays (N, 3) from ``o`` (3,) to the first of: the box's near face, the
    wall at x = WALL_X (30 m high), the ground; inf where none."""
    t = np.full(len(d), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = -o[2] / d[:, 2]
        t = np.where((d[:, 2] < 0) & (tg > 0), tg, t)
        for x, half, top in ((BOX[0], BOX[2], BOX[3]), (WALL_X, 1e9, 30.0)):
            tx = (x - o[0]) / d[:, 0]
            p = o[None] + tx[:, None] * d
            ok = (d[:, 0] > 0) & (np.abs(p[:, 1]) < half) & (p[:, 2] < top) & (p[:, 2] > 0) & (tx < t)
            t = np.where(ok, tx, t)
    return t


def _lidar_vol() -> np.ndarray:
    """The scene's returns (N, 3), volume frame, of every ring, -40..40 deg of azimuth every 0.2 deg."""
    el = np.radians(LIDAR_LOWEST_RING_DEG + LIDAR_RING_DEG * np.arange(LIDAR_N_RINGS))
    az = np.radians(np.arange(-40.0, 40.0, 0.2))
    E, A = np.meshgrid(el, az)
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    t = _cast(LIDAR_VOL, d)
    ok = np.isfinite(t)
    return LIDAR_VOL[None] + t[ok, None] * d[ok]


def test_a_point_a_beam_passed_on_its_way_to_a_farther_return_is_free():
    ring0 = np.radians(np.arange(0.0, 20.0, 0.36))  # ring 0 (0 deg) returns at 60 m, ring -1 at 40 m
    r1 = np.radians(LIDAR_RING_DEG)
    lidar = np.concatenate([
        np.stack([60 * np.cos(ring0), 60 * np.sin(ring0), np.zeros_like(ring0)], 1),
        np.stack([40 * np.cos(r1) * np.cos(ring0), 40 * np.cos(r1) * np.sin(ring0), -40 * np.sin(r1) + 0 * ring0], 1),
    ])
    a = np.radians(10.0)
    pts = np.array([
        [40 * np.cos(a), 40 * np.sin(a), 0.0],  # ring 0, nearer than its returns: free
        [40 * np.cos(r1) * np.cos(a), 40 * np.cos(r1) * np.sin(a), -40 * np.sin(r1)],  # ring -1 at its return: kept
        [40 * np.cos(0.9), 40 * np.sin(0.9), 0.0],  # no return at this azimuth: kept
        [58 * np.cos(a), 58 * np.sin(a), 0.0],  # within the margin before the return: kept
        [40 * np.cos(a), 40 * np.sin(a), 40 * np.tan(np.radians(20.0))],  # above the highest ring: kept
    ])
    passed, behind = lidar_passed_through(pts, lidar, np.zeros(3))
    assert passed.tolist() == [True, False, False, False, False]
    assert behind[0] == pytest.approx(60.0) and np.isinf(behind[1:]).all()


def _view() -> tuple[CameraView, np.ndarray]:
    W, H = 480, 270
    K = np.array([[250.0, 0.0, (W - 1) / 2], [0.0, 250.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    T_ego_from_cam = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [1.5, 0.0, 1.5])
    image = np.random.default_rng(3).integers(40, 200, (H, W, 3)).astype(np.uint8)
    return CameraView("CAM_FRONT", "tok", "synthetic.png", K, W, H, T_ego_from_cam, np.eye(4), 0).with_image(image), K


@pytest.mark.parametrize("free_space", [True, False])
def test_the_depth_grown_over_a_low_objects_top_is_not_a_wall_in_the_volume(monkeypatch, free_space):
    """A low box (1.2 m high, 20 m ahead) before a wall at 60 m; the densified depth puts the box's depth on the
    wall's pixels up to 3 m above its top (a dilation's growth). The LiDAR's beams over the box's top returned from
    the wall: with the free-space rule no volume point stands above the box (without it, the old rule, they do);
    the box's own points and the wall's stay."""
    view, K = _view()
    T = np.asarray(view.T_ego_from_cam)
    rays = PinholeCamera(K, view.width, view.height).rays(unit=False)  # camera z = 1
    d_vol = rays.reshape(-1, 3) @ T[:3, :3].T
    depth = _cast(T[:3, 3], d_vol)  # camera-z depth: rays have z = 1
    p = T[:3, 3][None] + depth[:, None] * d_vol
    t_box = (BOX[0] - T[0, 3]) / d_vol[:, 0]
    q = T[:3, 3][None] + t_box[:, None] * d_vol
    grown = (np.abs(q[:, 1]) < BOX[2]) & (q[:, 2] >= BOX[3]) & (q[:, 2] < BOX[3] + 3.0) & (depth > t_box)
    depth = np.where(grown, t_box, depth).reshape(view.height, view.width).astype(np.float32)
    monkeypatch.setattr(observe, "densify_lidar_depth", lambda *a, **k: depth.copy())
    monkeypatch.setattr(observe, "image_sky_mask", lambda work: np.zeros((view.height, view.width), bool))
    monkeypatch.setattr(observe, "LIDAR_FREE_SPACE", free_space)
    lidar_cam = (_lidar_vol() - T[:3, 3]) @ T[:3, :3]
    n_cam = T[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    ground = (n_cam, float(n_cam @ (T[:3, :3].T @ T[:3, 3])))
    origin_cam = (LIDAR_VOL - T[:3, 3]) @ T[:3, :3]
    obs = observe_view(view, T, 1.0, lidar_cam, ground, lidar_origin_cam=origin_cam)
    assert (obs.free_points is not None) == free_space
    pts = obs.free_points if free_space else obs.points
    at_box = (np.abs(pts[:, 0] - BOX[0]) < 0.3) & (np.abs(pts[:, 1]) < BOX[2] - 0.1)
    above = at_box & (pts[:, 2] > BOX[3] + 0.5)
    assert (at_box & (pts[:, 2] < BOX[3] - 0.1)).sum() > 50  # the box's face
    on_wall = (np.abs(pts[:, 0] - WALL_X) < 3.0) & (np.abs(pts[:, 1]) < BOX[2] - 0.1) & (pts[:, 2] > BOX[3] + 0.5)
    assert (np.abs(pts[:, 0] - WALL_X) < 0.5).sum() > 1000  # the wall
    if free_space:
        assert above.sum() == 0
        assert on_wall.sum() > 100  # the grown pixels show the wall behind the box, moved there
    else:
        assert above.sum() > 100


def test_the_volume_bins_a_freed_point_where_the_move_changes_what_its_centre_sees():
    """binned_points: a point 4 m ahead of the grid's centre moved 20 m back along its camera ray (the direction from
    the centre turns by ~10 deg) is binned at the return; a point 60 m off moved by 1 m stays (the angle is tiny)."""
    from dataclasses import replace as dc_replace

    from streetaug.augment.lighting.build import binned_points
    from streetaug.augment.lighting.volume import LogGrid

    grid = LogGrid(shape=(16, 16, 8), half_extent_xy_m=40.0, z_min_m=-4.0, z_max_m=36.0, n_below=2,
                   centre_xy_m=(34.0, 8.0))
    cam = np.array([0.0, 0.0, 1.5])
    near = np.array([38.0, 7.8, 2.0])
    far = np.array([90.0, 20.0, 3.0])
    moved = np.stack([cam + (near - cam) * 1.5, cam + (far - cam) * 1.01])
    obs = observe.ViewObservation("CAM_FRONT", np.stack([near, far]), np.zeros((2, 3), np.float32), np.zeros((2, 3)),
                                  np.zeros(2, bool), np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros(0, bool),
                                  np.zeros(0, bool), cam)
    np.testing.assert_array_equal(binned_points(grid, obs), obs.points)  # no free points: as they are
    out = binned_points(grid, dc_replace(obs, free_points=moved))
    np.testing.assert_allclose(out, [moved[0], far])
