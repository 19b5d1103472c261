"""The seen-surface mesh's depth above what the LiDAR measured (augment/lighting/observe.py: mesh_depth)."""

from __future__ import annotations

import numpy as np

from streetaug.augment.lighting import seen_surfaces as ss
from streetaug.augment.lighting.observe import (
    TOP_FARTHEST_MAX_M,
    extend_facades,
    fill_structure_columns,
    mesh_backdrop,
    mesh_depth,
    top_window_px,
)
from streetaug.augment.lighting.seen_surfaces import DepthView, SeenSurfaces

W, H, F = 96, 64, 60.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
CENTRE = np.array([0.0, 0.0, 1.5])
# camera x right, y down, z forward -> volume x forward, y left, z up
T_VOL_FROM_CAM = np.eye(4)
T_VOL_FROM_CAM[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
T_VOL_FROM_CAM[:3, 3] = CENTRE


def test_above_a_low_object_the_mesh_continues_the_farthest_top_nearby():
    """A facade at 30 m measured up to row 8 in columns 0-9, a car at 8 m (rows 14-19) in columns 10-19, sky in
    rows 0-2: above the car the mesh takes the facade's 30 m within the window (the car's own 8 m beyond it);
    what was measured, the sky and the volume's points (extend_facades) are unchanged."""
    depth = np.full((20, 20), np.inf)
    depth[8:, :10] = 30.0
    depth[14:, 10:] = 8.0
    sky = np.zeros((20, 20), bool)
    sky[:3] = True
    out = mesh_depth(depth, sky, 11)
    assert np.all(out[3:14, 10:15] == 30.0)  # within 5 columns of the facade
    assert np.all(out[3:14, 15:] == 8.0)  # farther: the column's own top
    assert np.all(out[14:, 10:] == 8.0) and np.all(out[8:, :10] == 30.0)
    assert np.all(np.isinf(out[:3]))
    points_depth, _ = extend_facades(depth, sky)
    assert np.all(points_depth[3:14, 10:] == 8.0)
    # window 1 is the old rule
    assert np.array_equal(mesh_depth(depth, sky, 1), fill_structure_columns(extend_facades(depth, sky)[0], sky))


def test_a_column_of_ground_up_to_the_horizon_is_not_continued_in_its_neighbours():
    """The ground plane's depth near the horizon (here 2 km) is no structure: the neighbours keep their own."""
    depth = np.full((20, 20), np.inf)
    depth[8:, :] = 20.0
    depth[8, 5] = 2000.0  # column 5: ground right up to its top
    out = mesh_depth(depth, np.zeros((20, 20), bool), 11)
    assert 2000.0 > TOP_FARTHEST_MAX_M
    assert np.all(out[:8, :5] == 20.0) and np.all(out[:8, 6:] == 20.0) and np.all(out[:8, 5] == 2000.0)


def test_backdrop_behind_a_near_top():
    """Only in the columns whose continued depth is farther than their own top (beyond the mesh's depth-ratio
    test): that depth over rows either side of the top, not into the sky."""
    depth = np.full((20, 20), np.inf)
    depth[8:, :10] = 30.0
    depth[14:, 10:] = 8.0
    sky = np.zeros((20, 20), bool)
    sky[:12, 12] = True
    bd = mesh_backdrop(depth, sky, 11, rows=2)
    assert np.all(bd[12:17, 10:12] == 30.0) and np.all(bd[12:17, 13:15] == 30.0)
    assert np.all(np.isinf(bd[:12])) and np.all(np.isinf(bd[17:])) and np.all(np.isinf(bd[:, 15:]))
    assert np.all(np.isinf(bd[:, :10]))  # the facade's columns continue their own top
    assert np.all(bd[12:17, 12] == 30.0) and np.all(np.isinf(bd[:12, 12]))  # no backdrop in the sky


def test_from_its_own_centre_the_camera_sees_no_gap_at_a_near_top():
    """Without the backdrop the mesh breaks between the car's top (8 m) and the wall continued above it
    (30 m): rays from the camera's own centre through the break miss; with it every such ray hits."""
    truth, measured = _scene()
    sky = np.zeros((H, W), bool)
    u, v = np.meshgrid(np.arange(50.0, 90.0, 0.5), np.arange(32.0, 40.0, 0.25))
    rays = np.stack([(u.ravel() - K[0, 2]) / F, (v.ravel() - K[1, 2]) / F, np.ones(u.size)], axis=1)
    dirs = rays @ T_VOL_FROM_CAM[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.repeat(CENTRE[None], len(dirs), axis=0)
    view = _view(mesh_depth(measured, sky, 2 * W + 1), truth)
    hit_without, _, _ = SeenSurfaces.from_views([view]).trace(origins, dirs)
    assert not hit_without.all()
    with_backdrop = DepthView(view.channel, view.depth_m, view.radiance, K, T_VOL_FROM_CAM,
                              mesh_backdrop(measured, sky, 2 * W + 1))
    hit, _, rgb = SeenSurfaces.from_views([with_backdrop]).trace(origins, dirs)
    assert hit.all()


def test_window_in_degrees():
    assert top_window_px(K, 6.0) == 7  # 60 px/rad x 0.105 rad = 6.3 -> odd 7
    assert top_window_px(K, 0.0) == 1


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """True depth (H, W) of a wall at x = 30 m with a car (x = 8 m, rows >= 36) in the right half, and the
    measured depth: the wall in the left half from row 20 down, the car; nothing above the car."""
    truth = np.full((H, W), 30.0)
    truth[36:, 48:] = 8.0
    measured = np.full((H, W), np.inf)
    measured[20:, :48] = 30.0
    measured[36:, 48:] = 8.0
    return truth, measured


def _view(mesh_depth_m: np.ndarray, truth: np.ndarray) -> DepthView:
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    y = -(u - K[0, 2]) / F * truth
    z = CENTRE[2] - (v - K[1, 2]) / F * truth
    return DepthView("CAM_FRONT", mesh_depth_m.astype(np.float32), ss_texture(y, z, truth), K, T_VOL_FROM_CAM)


def ss_texture(y: np.ndarray, z: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The wall painted with smooth stripes, the car flat grey."""
    wall = np.stack([0.5 + 0.4 * np.sin(1.3 * y) * np.cos(0.9 * z), 0.3 + 0.2 * np.cos(0.7 * y + 0.5 * z),
                     np.full_like(y, 0.2)], axis=-1)
    return np.where((truth < 10.0)[..., None], 0.05, wall).astype(np.float32)


def test_from_a_point_ahead_the_wall_above_the_car_is_seen_at_its_place(monkeypatch):
    """6 m ahead, the ray to a point of the wall above the car (30 m, 3 m high) meets the mesh at the wall with
    its colour; with the car's depth continued upwards (the old rule) it met a patch 2 m ahead."""
    monkeypatch.setattr(ss, "DEPTH_UNCERTAINTY", 0.0)
    truth, measured = _scene()
    sky = np.zeros((H, W), bool)
    target = np.array([30.0, -3.0, 3.0])
    origin = CENTRE + np.array([6.0, 0.0, 0.0])
    d = (target - origin) / np.linalg.norm(target - origin)
    new = SeenSurfaces.from_views([_view(mesh_depth(measured, sky, 2 * W + 1), truth)])
    hit, t, rgb = new.trace(origin[None], d[None])
    assert hit[0] and abs(t[0] - np.linalg.norm(target - origin)) < 0.05
    wall = ss_texture(np.array([target[1]]), np.array([target[2]]), np.array([30.0]))[0]
    assert np.abs(rgb[0] - wall).max() < 0.02
    old = SeenSurfaces.from_views([_view(mesh_depth(measured, sky, 1), truth)])
    hit, t, _ = old.trace(origin[None], d[None])
    assert hit[0] and t[0] < 3.0
