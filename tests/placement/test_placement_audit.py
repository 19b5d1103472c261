"""Independent re-check of final placements; exact footprints on grids and on tilted ground."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely

from placement_fixtures import (
    CAMERA,
    EGO_YAW_RAD,
    HEIGHT,
    K,
    ROAD_HALF_WIDTH_M,
    T_EGO_FROM_CAM,
    T_GLOBAL_FROM_EGO,
    WIDTH,
    box_at_ego,
    camera_view,
    ground_grid_ego,
    lidar_rings_ego,
    lidar_sweep,
    make_sample,
)
from streetaug.augment.core import pose_camera_to_transform, quat_to_rotation, rotation_to_quat, transform_points
from streetaug.augment.core.depth import densify_lidar_depth
from streetaug.datasets.sample import Box
from streetaug.placement.audit import AUDITED_RULES, audit_placements, box_hull_xy
from streetaug.placement.config import PlacementConfig
from streetaug.placement.drivable import DrivableArea
from streetaug.placement.candidates import object_transforms
from streetaug.placement.place import ObjectBox, Placement, place_objects
from streetaug.placement.scene import scene_depth
from streetaug.placement.rules import box_footprint_rect, footprint_corners, visible_fraction_estimate

CFG = PlacementConfig()
WLH = np.array([1.8, 4.5, 1.5])


def _scene(**kw):
    pts = ground_grid_ego(0.5)
    boxes = [box_at_ego(20.0, 2.5), box_at_ego(32.0, -2.5),
             box_at_ego(14.0, -3.8, "movable_object.barrier", (0.5, 0.5, 1.0))]
    return make_sample(boxes=boxes, lidar=lidar_sweep(pts), **kw)


def _moved(p: Placement, dx_ego: float, dy_ego: float) -> Placement:
    """The same placement shifted by (dx, dy) in the ego frame (box and transform together)."""
    shift = T_GLOBAL_FROM_EGO[:3, :3] @ np.array([dx_ego, dy_ego, 0.0])
    T = p.T_global_from_object.copy()
    T[:3, 3] += shift
    box = Box(p.box.center + shift, p.box.wlh, p.box.rotation, p.box.category)
    return dataclasses.replace(p, T_global_from_object=T, box=box)


def test_final_placements_pass_the_audit_and_the_audit_can_fail():
    s = _scene()
    view = s.cameras["CAM_FRONT"]
    r = place_objects(s, view, [ObjectBox(WLH)] * 3, np.random.default_rng(5))
    assert len(r.placements) == 3
    audits = audit_placements(s, view, r.placements, r.drivable, CFG)
    assert all(a.ok for a in audits), [a.passed for a in audits]
    assert set(audits[0].passed) == set(AUDITED_RULES) - {"lidarseg", "corners_unoccluded"}  # no labels, no rule
    # the audit is not a rubber stamp: move one placement onto the kerb, into a car, next to another placement
    p = r.placements[0]
    y_ego = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), p.box.center[None])[0, 1]
    kerb = _moved(p, 0.0, np.sign(y_ego or 1.0) * (ROAD_HALF_WIDTH_M - abs(y_ego) - WLH[0] / 2 + 0.05))
    assert not audit_placements(s, view, [kerb], r.drivable, CFG)[0].passed["surface"]
    car_xy = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), s.boxes[0].center[None])[0]
    p_xy = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), p.box.center[None])[0]
    into_car = _moved(p, car_xy[0] - p_xy[0], car_xy[1] - p_xy[1] - WLH[0] - 2.9)  # 2.9 m gap beside a car
    a = audit_placements(s, view, [into_car], r.drivable, CFG)[0]
    assert not a.passed["annotated_boxes"] and 2.5 < a.measured["min_gap_dynamic_m"] < 3.0
    twins = audit_placements(s, view, [p, _moved(p, 0.0, WLH[0] + 2.9)], r.drivable, CFG)
    assert not twins[0].passed["mutual_collision"]
    far = _moved(p, 60.0, 0.0)
    assert not audit_placements(s, view, [far], r.drivable, CFG)[0].passed["distance"]


def test_audit_counts_obstacles_and_lidarseg_points():
    pts = ground_grid_ego(0.5)
    labels = np.full(len(pts), 24)
    s = _scene()
    view = s.cameras["CAM_FRONT"]
    p = place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(0)).placements[0]
    local = np.array([[WLH[1] / 2 + 0.9, 0.0, 1.0]] * 3)  # 0.9 m in front of the bumper, 1 m high
    extra = transform_points(p.T_global_from_object, local)
    extra_ego = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), extra)
    s2 = make_sample(boxes=s.boxes, lidar=lidar_sweep(np.concatenate([pts, extra_ego]),
                                                      np.r_[labels, np.full(3, 28)]))
    drivable = place_objects(s2, view, [ObjectBox(WLH)], np.random.default_rng(0)).drivable
    a = audit_placements(s2, view, [p], drivable, CFG)[0]
    assert a.measured["obstacle_points"] == 3 and not a.passed["lidar_obstacles"]
    assert a.measured["non_drivable_points"] == 3 and not a.passed["lidarseg"]
    # and the placement itself never chooses such a spot
    r = place_objects(s2, view, [ObjectBox(WLH)], np.random.default_rng(0))
    assert all(x.ok for x in audit_placements(s2, view, r.placements, r.drivable, CFG))


def test_grid_sources_pass_the_audit():
    pts = lidar_rings_ego()
    labels = np.where(np.abs(pts[:, 1]) <= ROAD_HALF_WIDTH_M, 24, 26)
    for lab in (labels, None):
        s = make_sample(polygons=None, lidar=lidar_sweep(pts, lab))
        view = s.cameras["CAM_FRONT"]
        for seed in range(2):
            r = place_objects(s, view, [ObjectBox(WLH)] * 2, np.random.default_rng(seed))
            assert r.placements and r.drivable.source == ("lidarseg" if lab is not None else "lidar-ground")
            assert all(a.ok for a in audit_placements(s, view, r.placements, r.drivable, CFG))


def test_grid_footprint_test_is_exact_at_cell_corners():
    """A footprint whose corner pokes 1 cm into a non-drivable cell is rejected; 1 cm short of it, accepted."""
    res = 0.25
    grid = np.ones((80, 80), bool)
    grid[40, 40] = False  # cell [10, 10.25) x [10, 10.25)
    area = DrivableArea("lidarseg", "medium", grid=grid, grid_origin_xy=np.zeros(2), resolution_m=res)
    half_diag = np.hypot(2.25, 0.9)
    # a box rotated so that its front-left corner points exactly along -x, towards the cell's left edge
    yaw = np.pi - np.arctan2(0.9, 2.25)
    for gap, expect in [(-0.01, False), (0.01, True)]:
        centre = np.array([[10.0 - gap - half_diag, 10.125]])
        fp = footprint_corners(centre, np.array([yaw]), 4.5, 1.8)
        assert np.isclose(fp[0, :, 0].max(), 10.0 - gap)
        assert area.contains_footprints(fp)[0] == expect
        hull = shapely.Polygon(fp[0])
        cell = shapely.box(10.0, 10.0, 10.25, 10.25)
        assert (hull.intersection(cell).area > 0) == (not expect)


def test_footprint_rect_bounds_a_tilted_box():
    yaw = np.array([0.4, -2.0])
    normals = np.array([[0.08, -0.05, 1.0], [0.0, 0.0, 1.0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    T = object_transforms(np.array([[3.0, 4.0], [-1.0, 2.0]]), yaw, np.array([1.0, 0.0]), normals)
    rect = box_footprint_rect(T, WLH)
    for k in range(2):
        box = Box(T[k, :3, 3] + WLH[2] / 2 * T[k, :3, 2], WLH, rotation_to_quat(T[k, :3, :3]), "vehicle.car")
        poly = shapely.Polygon(rect[k]).buffer(1e-9)
        assert poly.contains(box_hull_xy(box))
    np.testing.assert_allclose(rect[1], footprint_corners(T[1:, :2, 3], yaw[1:], WLH[1], WLH[0])[0], atol=1e-12)
    # on tilted ground the top overhangs the bottom: the rectangle is larger than the flat footprint
    assert shapely.Polygon(rect[0]).area > WLH[0] * WLH[1] + 1e-3


def test_placements_on_a_slope_pass_the_audit_and_touch_the_slope():
    rng = np.random.default_rng(1)
    pts = ground_grid_ego(0.4)
    slope_x, slope_y = np.tan(np.radians(4.0)), np.tan(np.radians(2.0))
    pts[:, 2] = slope_x * pts[:, 0] + slope_y * pts[:, 1] + rng.normal(0, 0.005, len(pts))
    s = make_sample(lidar=lidar_sweep(pts))
    view = s.cameras["CAM_FRONT"]
    r = place_objects(s, view, [ObjectBox(WLH)] * 3, np.random.default_rng(2))
    assert len(r.placements) == 3
    assert all(a.ok for a in audit_placements(s, view, r.placements, r.drivable, CFG))
    T_ego_from_global = np.linalg.inv(T_GLOBAL_FROM_EGO)
    for p in r.placements:
        assert p.ground_source == "lidar-plane"
        bottom = transform_points(T_ego_from_global, transform_points(p.T_global_from_object, np.array(
            [[x, y, 0.0] for x in (-2.25, 2.25) for y in (-0.9, 0.9)])))
        ground_z = slope_x * bottom[:, 0] + slope_y * bottom[:, 1]
        np.testing.assert_allclose(bottom[:, 2], ground_z, atol=0.02)  # all four wheels on the slope
        R = quat_to_rotation(p.box.rotation)
        assert np.degrees(np.arccos(R[2, 2])) > 3.0  # the label box is tilted with the ground
    # heading still the ego's (or opposite) in x/y
    for p in r.placements:
        h = p.T_global_from_object[:2, 0]
        d = np.degrees(np.arctan2(h[1], h[0]) - EGO_YAW_RAD) % 180
        assert min(d, 180 - d) < 3 * 3.0 + 1.0


# ---------------------------------------------------------------------- occlusion-aware visible fraction


def _wall_cam(z_m: float, x_range=(-30.0, 30.0), y_range=(-3.0, 1.5), dx: float = 0.014, dy: float = 0.093):
    """LiDAR-like wall points (camera frame) at depth z: dense along x, beam rows every ``dy`` metres."""
    xs, ys = np.meshgrid(np.arange(*x_range, dx), np.arange(*y_range, dy))
    return np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, z_m)]


def test_visible_fraction_estimate_counts_image_and_occluders():
    T = pose_camera_to_transform(0.0, 1.5, 20.0, 90.0)[None]  # a car side-on, 20 m ahead
    nothing = np.full(CAMERA.shape, np.inf, np.float32)
    assert visible_fraction_estimate(T, WLH, CAMERA, nothing, 1.0)[0] == pytest.approx(1.0)
    # a wall 8 m away hiding the left half of the image (x < 0 at any depth: u < cx)
    depth = densify_lidar_depth(_wall_cam(8.0, x_range=(-30.0, 0.0)), K, WIDTH, HEIGHT)
    assert visible_fraction_estimate(T, WLH, CAMERA, depth, 1.0)[0] == pytest.approx(0.5, abs=0.08)
    # the same wall behind the car hides nothing
    depth_behind = densify_lidar_depth(_wall_cam(30.0, x_range=(-30.0, 0.0)), K, WIDTH, HEIGHT)
    assert visible_fraction_estimate(T, WLH, CAMERA, depth_behind, 1.0)[0] == pytest.approx(1.0)
    # half out of the image on the right
    x_edge = (WIDTH - 0.5 - K[0, 2]) * 20.0 / K[0, 0]
    T_edge = pose_camera_to_transform(x_edge, 1.5, 20.0, 90.0)[None]
    assert visible_fraction_estimate(T_edge, WLH, CAMERA, nothing, 1.0)[0] == pytest.approx(0.5, abs=0.08)


def test_placement_judges_occlusion_on_the_renderers_depth():
    """Without a depth given, placement computes the renderer's (LiDAR densified, ego ground plane in the
    holes); a given depth is the one it tests against (a wall in it everywhere: nothing is visible)."""
    s = make_sample(lidar=lidar_sweep(ground_grid_ego(0.5)))
    view = s.cameras["CAM_FRONT"]
    points_cam = s.lidar.points_in(view.T_cam_from_global)
    expected = densify_lidar_depth(points_cam, K, WIDTH, HEIGHT, ground_fill=view.ego_ground_plane_cam)
    np.testing.assert_array_equal(scene_depth(s, view), expected)
    r = place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(0))
    given = place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(0), depth_m=expected)
    np.testing.assert_array_equal(r.placements[0].T_global_from_object, given.placements[0].T_global_from_object)
    assert r.placements[0].visible_fraction >= PlacementConfig().min_visible_fraction
    wall = np.full(CAMERA.shape, 3.0, np.float32)
    hidden = place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(0), depth_m=wall)
    assert hidden.placements == [] and hidden.report["in_view"] > 0


def test_ego_ground_plane_in_the_camera():
    normal, offset = camera_view().ego_ground_plane_cam
    on_ground = transform_points(np.linalg.inv(T_EGO_FROM_CAM), np.array([[12.0, -3.0, 0.0], [30.0, 4.0, 0.0]]))
    np.testing.assert_allclose(on_ground @ normal + offset, 0.0, atol=1e-12)
    assert offset == pytest.approx(1.5)  # the camera 1.5 m above the ground


def test_no_placement_behind_a_wall_that_fills_the_view():
    """A LiDAR wall 6 m ahead across the whole view, the map road beyond it: nothing is placed.

    The sweep holds what a LiDAR sees: the ground up to the wall (x_ego < 7.7 m) and the wall, not the
    ground behind it (whose returns would show through the gaps between the wall's beams in the
    renderer's depth, as they would in the render)."""
    wall_ego = transform_points(T_EGO_FROM_CAM, _wall_cam(6.0, y_range=(-4.0, 1.5)))
    s = make_sample(lidar=lidar_sweep(np.concatenate([ground_grid_ego(0.5, x_range=(-10.0, 7.5)), wall_ego])))
    r = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(WLH)], np.random.default_rng(0))
    assert r.placements == [] and r.report["in_view"] > 0 and "in_view" in r.reason
    # without the wall the same seed places
    s2 = make_sample(lidar=lidar_sweep(ground_grid_ego(0.5)))
    assert place_objects(s2, s2.cameras["CAM_FRONT"], [ObjectBox(WLH)], np.random.default_rng(0)).placements
