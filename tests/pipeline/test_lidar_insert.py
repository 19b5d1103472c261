"""Inserted objects in the LiDAR sweep: beams through an object return from its surface."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from streetaug.augment.core.raycast import RayScene
from streetaug.augment.pipeline.lidar import DEFAULT_CAR_INTENSITY, car_intensity, empty_beams, insert_into_sweep
from streetaug.datasets.sample import Box
from streetaug.placement.rules import points_in_box


def box_mesh(center, extents):
    m = trimesh.creation.box(extents=extents)
    return m.vertices + np.asarray(center, float), m.faces


def sweep(xyz, intensity=50.0):
    xyz = np.asarray(xyz, np.float32)
    ring = np.arange(len(xyz), dtype=np.float32)
    return np.column_stack([xyz, np.full(len(xyz), intensity, np.float32), ring])


def test_returns_behind_the_object_move_onto_its_front_face():
    box = box_mesh([10.0, 0.0, 0.0], [2.0, 2.0, 2.0])  # front face at x = 9
    points = sweep([[20.0, 0.0, 0.0], [20.0, 4.0, 0.0], [5.0, 0.0, 0.0], [30.0, 0.6, -0.3], [-20.0, 0.0, 0.0]])
    labels = np.array([24, 24, 24, 10, 24], np.uint8)
    out = insert_into_sweep(points, [box], labels, [17], intensity=12.0)
    np.testing.assert_array_equal(out.moved, [0, -1, -1, 0, -1])
    np.testing.assert_allclose(out.points[0, :3], [9.001, 0.0, 0.0], atol=1e-5)  # 1 mm inside
    # moved along its own beam: same direction from the sensor
    d = out.points[3, :3] / np.linalg.norm(out.points[3, :3])
    np.testing.assert_allclose(d, points[3, :3] / np.linalg.norm(points[3, :3]), atol=1e-6)
    assert out.points[3, 0] == pytest.approx(9.0, abs=2e-3)
    unchanged = out.moved < 0
    np.testing.assert_array_equal(out.points[unchanged], points[unchanged])
    np.testing.assert_array_equal(out.points[:, 4], points[:, 4])  # rings kept
    np.testing.assert_array_equal(out.points[out.moved >= 0, 3], 12.0)
    np.testing.assert_array_equal(out.labels, [17, 24, 24, 17, 24])
    np.testing.assert_array_equal(labels, [24, 24, 24, 10, 24])  # input untouched


def test_the_nearer_of_two_objects_takes_the_return():
    near, far = box_mesh([10.0, 0.0, 0.0], [2.0, 2.0, 2.0]), box_mesh([15.0, 0.0, 0.0], [2.0, 2.0, 2.0])
    for order in ([far, near], [near, far]):
        out = insert_into_sweep(sweep([[30.0, 0.0, 0.0]]), order)
        assert out.points[0, 0] == pytest.approx(9.0, abs=2e-3)
        assert order[out.moved[0]] is near
    assert out.labels is None


def test_the_box_counts_exactly_the_moved_points():
    box = box_mesh([10.0, 2.0, 0.5], [4.0, 2.0, 1.5])
    ys, zs = np.meshgrid(np.linspace(-1, 5, 40), np.linspace(-1, 2, 20))
    far = np.column_stack([np.full(ys.size, 40.0), ys.ravel() * 4, zs.ravel() * 4])
    out = insert_into_sweep(sweep(far), [box])
    # the mesh's tight box (LiDAR frame = global frame here): w along y, l along x, h
    tight = Box(np.array([10.0, 2.0, 0.5]), np.array([2.0, 4.0, 1.5]), np.array([1.0, 0.0, 0.0, 0.0]), "vehicle.car")
    n = np.count_nonzero(points_in_box(out.points[:, :3], tight))
    assert n == np.count_nonzero(out.moved == 0) > 10


def test_car_intensity_is_the_median_of_real_cars_or_the_default():
    points = sweep(np.ones((100, 3)))
    points[:, 3] = np.arange(100)
    assert car_intensity(points, np.arange(100) < 50) == pytest.approx(24.5)
    assert car_intensity(points, np.arange(100) < 5) == DEFAULT_CAR_INTENSITY  # too few to trust


def test_no_objects_no_change():
    points = sweep([[10.0, 1.0, 0.0]])
    out = insert_into_sweep(points, [])
    np.testing.assert_array_equal(out.points, points) and np.testing.assert_array_equal(out.moved, [-1])


# ----------------------------------------------------------------------------- beams that returned nothing

RING_ELEVATIONS_DEG = np.linspace(-20.0, 10.0, 32)
GROUND_Z = -1.8


def firing_order_sweep(n_firings: int = 720, ground_max_range_m: float = 15.0):
    """A nuScenes-like sweep: 32 rings x ``n_firings`` firings (0.5 deg apart), firing after firing. Beams reach
    a ground plane 1.8 m below the sensor up to ``ground_max_range_m``; the others return nothing and are
    stored at the sensor's position, which moves 0.4 m along +y over the sweep. Returns (points, true beam
    directions (N, 3), the sensor position of each point (N, 3))."""
    az = np.radians(np.arange(n_firings) * 0.5)
    el = np.radians(RING_ELEVATIONS_DEG)
    d = np.stack([np.cos(el)[None] * np.cos(az)[:, None], np.cos(el)[None] * np.sin(az)[:, None],
                  np.broadcast_to(np.sin(el)[None], (n_firings, 32))], -1).reshape(-1, 3)
    sensor = np.repeat(np.stack([np.zeros(n_firings), np.linspace(0.0, 0.4, n_firings), np.zeros(n_firings)], 1),
                       32, axis=0)
    ring = np.tile(np.arange(32), n_firings)
    with np.errstate(divide="ignore"):
        t = np.where(d[:, 2] < 0, GROUND_Z / d[:, 2], np.inf)
    returned = t < ground_max_range_m
    xyz = np.where(returned[:, None], sensor + d * np.where(returned, t, 0.0)[:, None], sensor)
    points = np.column_stack([xyz, np.full(len(xyz), 30.0), ring]).astype(np.float32)
    return points, d, sensor


def test_empty_beams_are_rebuilt_from_their_ring_and_firing():
    points, d, _ = firing_order_sweep()
    empty = empty_beams(points)
    assert empty is not None
    expected = np.linalg.norm(points[:, :3], axis=1) < 2.0
    expected &= RING_ELEVATIONS_DEG[points[:, 4].astype(int)] > -10.0  # steeper rings: the road or the roof
    np.testing.assert_array_equal(empty.mask, expected)
    cos = np.clip((empty.directions * d[empty.mask]).sum(1), -1, 1)
    assert np.degrees(np.arccos(cos)).max() < 0.05


def test_an_object_beyond_the_returns_is_hit_by_the_empty_beams():
    points, d, sensor = firing_order_sweep()
    box = box_mesh([20.0, 0.0, GROUND_Z + 0.75], [1.9, 4.5, 1.5])  # beyond the 15 m of ground returns
    out = insert_into_sweep(points, [box])
    hit = out.moved == 0
    # every beam that meets the box (ray cast from the true beams) now returns from it, and only those

    truth = RayScene(*box).intersect(sensor.astype(np.float64), d)
    assert hit.sum() == truth.hit.sum() > 20
    np.testing.assert_array_equal(hit, truth.hit)
    tight = Box(np.array([20.0, 0.0, GROUND_Z + 0.75]), np.array([4.5, 1.9, 1.5]), np.array([1.0, 0.0, 0.0, 0.0]),
                "vehicle.car")
    assert points_in_box(out.points[hit, :3].astype(np.float64), tight).all()
    np.testing.assert_array_equal(out.points[:, 4], points[:, 4])  # rings kept, count kept
    np.testing.assert_array_equal(out.points[~hit], points[~hit])
    # without them (the ablation switch) no beam reaches the box: it stands beyond every return
    assert not (insert_into_sweep(points, [box], use_empty_beams=False).moved >= 0).any()


def test_a_sweep_not_in_firing_order_keeps_its_empty_beams_empty():
    points, _, _ = firing_order_sweep()
    shuffled = points[np.argsort(points[:, 4], kind="stable")]  # ring after ring (the bundled scenes' order)
    assert empty_beams(shuffled) is None
    out = insert_into_sweep(shuffled, [box_mesh([20.0, 0.0, GROUND_Z + 0.75], [1.9, 4.5, 1.5])])
    assert not (out.moved >= 0).any()


REAL_SWEEP = (Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "nuscenes-real" / "samples" / "LIDAR_TOP"
              / "n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin").resolve()


def test_real_sweep_empty_beams_point_where_returns_would():
    if not REAL_SWEEP.exists():
        pytest.skip(f"real nuScenes sweep not found at {REAL_SWEEP}")
    points = np.fromfile(REAL_SWEEP, np.float32).reshape(-1, 5)
    empty = empty_beams(points)
    assert empty is not None and 3000 < empty.mask.sum() < 6000  # of 34,688 beams
    # hide real returns of the upper rings (store them at the sensor, as empty beams are): their rebuilt beams
    # must point at where they returned from
    range_m = np.linalg.norm(points[:, :3], axis=1)
    firing, ring = np.arange(len(points)) // 32, points[:, 4].astype(int)
    stored = empty.mask
    known = np.unique(firing[stored])
    at = np.array([np.median(points[stored & (firing == f), :3], axis=0) for f in known])
    sensor = np.stack([np.interp(firing, known, at[:, c]) for c in range(3)], 1)
    hide = np.flatnonzero((range_m > 5) & (ring >= 16))[::5]
    hidden = points.copy()
    hidden[hide, :3] = sensor[hide]
    rebuilt = empty_beams(hidden)
    pos = np.full(len(points), -1)
    pos[np.flatnonzero(rebuilt.mask)] = np.arange(rebuilt.mask.sum())
    hide = hide[pos[hide] >= 0]
    true_dir = points[hide, :3] - sensor[hide]
    true_dir /= np.linalg.norm(true_dir, axis=1, keepdims=True)
    err_deg = np.degrees(np.arccos(np.clip((rebuilt.directions[pos[hide]] * true_dir).sum(1), -1, 1)))
    assert len(hide) > 1000 and np.median(err_deg) < 0.15 and np.percentile(err_deg, 95) < 0.3
