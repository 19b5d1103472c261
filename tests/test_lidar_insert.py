"""Inserted objects in the LiDAR sweep: beams through an object return from its surface."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from streetaug.augment.lidar_insert import DEFAULT_CAR_INTENSITY, car_intensity, insert_into_sweep
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
