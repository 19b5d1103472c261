"""Placement: drivable area, local ground, each rule on both sides of its threshold, place_objects."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
import shapely

from placement_fixtures import (
    CAMERA,
    EGO_YAW_RAD,
    HEIGHT,
    K,
    ROAD_HALF_WIDTH_M,
    T_GLOBAL_FROM_EGO,
    WIDTH,
    box_at_ego,
    camera_view,
    ego_to_global_xy,
    ground_grid_ego,
    lidar_rings_ego,
    lidar_sweep,
    make_sample,
)
from scipy.spatial import cKDTree

from streetaug.augment.core import InputError, PinholeCamera, make_transform, quat_to_rotation, quat_to_yaw, transform_points
from streetaug.augment.core.depth import densify_lidar_depth
from streetaug.datasets.lidarseg import read_lidar_points, read_lidarseg_labels
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import LidarSweep
from streetaug.placement.config import PlacementConfig
from streetaug.placement.drivable import DrivableArea, drivable_area_for_sample, drivable_from_map
from streetaug.placement.explain import RULE_COLORS_RGB, draw_placement_bev
from streetaug.placement.ground import LocalGroundFitter, ego_ground_plane
from streetaug.placement.labels import object_label
from streetaug.placement.place import RULE_ORDER, ObjectBox, place_objects
from streetaug.placement.rules import (
    box_corners_object,
    box_footprints,
    footprint_corners,
    points_in_boxes,
    projected_inside_fraction,
    rule_box_clearance,
    rule_corners_unoccluded,
    rule_distance,
    rule_in_view,
    rule_lidarseg,
    rule_mutual,
    rule_obstacles,
)

CFG = PlacementConfig()
L, W = 4.5, 1.8


def fp_ego(x: float, y: float, yaw_ego: float = 0.0, length: float = L, width: float = W) -> np.ndarray:
    """Footprint (1, 4, 2) in global x/y of a box centred at ego (x, y)."""
    return footprint_corners(ego_to_global_xy([[x, y]]), np.array([EGO_YAW_RAD + yaw_ego]), length, width)


# ---------------------------------------------------------------------- drivable area


def _road_area(kind: str) -> DrivableArea:
    if kind == "map":
        return drivable_from_map([shapely.Polygon(ego_to_global_xy([[-20, -5], [90, -5], [90, 5], [-20, 5]]))],
                                 T_GLOBAL_FROM_EGO[:2, 3], CFG.map_roi_m)
    # grid source: lidarseg on sparse rings, road labelled 24, sidewalk 26
    pts = lidar_rings_ego()
    labels = np.where(np.abs(pts[:, 1]) <= ROAD_HALF_WIDTH_M, 24, 26)
    pts_g = transform_points(T_GLOBAL_FROM_EGO, pts)
    s = make_sample(polygons=None, lidar=lidar_sweep(pts, labels))
    area, reason = drivable_area_for_sample(s, s.cameras["CAM_FRONT"], CFG)
    assert reason is None and pts_g.shape[0] > 0
    return area


@pytest.mark.parametrize("kind", ["map", "lidarseg"])
def test_drivable_footprint_corner_over_kerb(kind):
    area = _road_area(kind)
    # inside with 0.3 m to spare vs one side 0.2 m over the kerb (road edge at y = 5)
    # (x = 12 m: the rings are ~1 m apart there, so the kerb is resolved from lidarseg too)
    inside = fp_ego(12.0, ROAD_HALF_WIDTH_M - W / 2 - 0.3)
    over = fp_ego(12.0, ROAD_HALF_WIDTH_M - W / 2 + 0.2)
    # only one corner over: rotate the box a little so its front-left corner pokes out
    corner = fp_ego(12.0, ROAD_HALF_WIDTH_M - W / 2 - 0.05, yaw_ego=np.radians(8))
    got = area.contains_footprints(np.concatenate([inside, over, corner]))
    assert got.tolist() == [True, False, False]
    assert area.source == kind


def test_lidarseg_fill_covers_gaps_between_far_rings():
    area = _road_area("lidarseg")
    # at 30-40 m the rings are > 5 m apart; the whole lane between them must still be drivable
    fps = np.concatenate([fp_ego(x, 0.0) for x in (15.0, 22.0, 31.0, 38.0)])
    assert area.contains_footprints(fps).all()
    assert area.confidence == "medium"
    # and the sidewalk is not
    assert not area.contains_footprints(fp_ego(25.0, 8.0))[0]


def test_drivable_sources_in_order_and_reason_when_none():
    pts = ground_grid_ego()
    view = camera_view()
    s_map = make_sample(lidar=lidar_sweep(pts, np.full(len(pts), 24)))
    assert drivable_area_for_sample(s_map, view, CFG)[0].source == "map"
    s_seg = make_sample(polygons=None, lidar=lidar_sweep(pts, np.full(len(pts), 24)))
    assert drivable_area_for_sample(s_seg, view, CFG)[0].source == "lidarseg"
    s_gnd = make_sample(polygons=None, lidar=lidar_sweep(pts))
    area, _ = drivable_area_for_sample(s_gnd, view, CFG)
    assert (area.source, area.confidence) == ("lidar-ground", "low")
    # the corridor: |y_ego| < 6 m is ground, 10 m to the side is not
    assert area.contains_footprints(fp_ego(20.0, 0.0))[0] and not area.contains_footprints(fp_ego(20.0, 10.0))[0]
    s_none = make_sample(polygons=None, lidar=None)
    area, reason = drivable_area_for_sample(s_none, view, CFG)
    assert area is None and "no map" in reason and "no LiDAR" in reason


def test_no_drivable_area_gives_no_placement_with_reason():
    s = make_sample(polygons=None, lidar=None)
    r = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(np.array([W, L, 1.5]))], np.random.default_rng(0))
    assert r.placements == [] and r.reason.startswith("no drivable area")


def test_map_far_from_camera_falls_back_with_reason():
    far = shapely.box(1e4, 1e4, 1e4 + 10, 1e4 + 10)
    s = make_sample(polygons=[far], lidar=None)
    area, reason = drivable_area_for_sample(s, s.cameras["CAM_FRONT"], CFG)
    assert area is None and "no drivable polygon within" in reason


# ---------------------------------------------------------------------- ground


def test_ground_fit_recovers_slope_and_ignores_obstacles():
    rng = np.random.default_rng(1)
    pts = ground_grid_ego(0.4)
    slope = np.radians(3.0)
    pts[:, 2] = 0.3 + np.tan(slope) * (pts[:, 0] - 20.0) + rng.normal(0, 0.01, len(pts))
    clutter = np.c_[rng.uniform(18, 22, (200, 2)) * [1, 0.2], rng.uniform(0.5, 1.5, 200) + 0.3]
    pts_g = transform_points(T_GLOBAL_FROM_EGO, np.concatenate([pts, clutter]))
    fitter = LocalGroundFitter(pts_g, T_GLOBAL_FROM_EGO, None, CFG)
    plane = fitter.fit(ego_to_global_xy([[20.0, 0.0]])[0])
    assert plane.source == "lidar-plane"
    assert abs(plane.point_global[2] - (5.0 + 0.3)) < 0.02
    normal_ego = T_GLOBAL_FROM_EGO[:3, :3].T @ plane.normal_global
    assert abs(np.degrees(np.arctan2(-normal_ego[0], normal_ego[2])) - 3.0) < 0.3


def test_ground_falls_back_to_ego_plane_without_points():
    xy = ego_to_global_xy([[30.0, 1.0]])[0]
    plane = LocalGroundFitter(None, T_GLOBAL_FROM_EGO, None, CFG).fit(xy)
    assert plane.source == "ego-plane" and plane.n_points == 0
    assert abs(plane.point_global[2] - 5.0) < 1e-9
    np.testing.assert_allclose(plane.normal_global, [0, 0, 1], atol=1e-12)
    assert ego_ground_plane(T_GLOBAL_FROM_EGO, xy).height_at(xy[None])[0] == pytest.approx(5.0)


def test_ground_fit_prefers_the_road_to_a_raised_sidewalk():
    """Road (24) at z = 0 and a 15 cm kerb-high sidewalk (26) 1.5 m to the side within the fit radius."""
    pts = ground_grid_ego(0.25, x_range=(15.0, 25.0), y_half=6.0)
    side = pts[:, 1] > 1.5
    pts[side, 2] = 0.15
    labels = np.where(side, 26, 24)
    pg = transform_points(T_GLOBAL_FROM_EGO, pts)
    plane = LocalGroundFitter(pg, T_GLOBAL_FROM_EGO, labels, CFG).fit(ego_to_global_xy([[20.0, 0.0]])[0])
    assert plane.source == "lidarseg"
    assert abs(plane.point_global[2] - 5.0) < 0.01
    assert plane.normal_global @ T_GLOBAL_FROM_EGO[:3, 2] > np.cos(np.radians(0.3))


@pytest.mark.parametrize("height_m,source", [(0.3, "lidar-plane"), (4.5, "ego-plane")])
def test_ground_fit_rejects_a_canopy_far_above_the_road(height_m, source):
    """Only a flat layer of points 4.5 m above the ego's road (a canopy) near the object: not ground.
    (Allowed offset at 20 m: 0.5 m + 10 % of 20 m = 2.5 m; a 0.3 m rise is accepted.)"""
    pts = ground_grid_ego(0.5, x_range=(15.0, 25.0), y_half=4.0)
    pts[:, 2] = height_m
    plane = LocalGroundFitter(transform_points(T_GLOBAL_FROM_EGO, pts), T_GLOBAL_FROM_EGO, None, CFG).fit(
        ego_to_global_xy([[20.0, 0.0]])[0])
    assert plane.source == source
    assert plane.point_global[2] == pytest.approx(5.0 + (height_m if source == "lidar-plane" else 0.0), abs=0.01)


def test_annotated_objects_correct_a_hedge_mistaken_for_the_ground():
    """Far away only a 1.1 m high layer (a hedge top; the road hidden behind parked cars) is in the LiDAR:
    the fit accepts it (within 0.5 m + 10 % of 30 m), but annotated cars standing 6 m away on the road
    (z = 0.1 above the ego's road) give the height; without them, or far from them, the fit stands; an
    annotated height within the tolerance leaves the LiDAR plane (with its tilt) alone."""
    pts = ground_grid_ego(0.5, x_range=(26.0, 34.0), y_half=4.0)
    pts[:, 2] = 1.1
    pg = transform_points(T_GLOBAL_FROM_EGO, pts)
    xy = ego_to_global_xy([[30.0, 0.0]])[0]
    bottoms = transform_points(T_GLOBAL_FROM_EGO, np.array([[30.0, 6.0, 0.1], [33.0, 6.5, 0.12], [27.0, -6.0, 0.05]]))
    plane = LocalGroundFitter(pg, T_GLOBAL_FROM_EGO, None, CFG).fit(xy)
    assert plane.source == "lidar-plane" and plane.point_global[2] == pytest.approx(5.0 + 1.1, abs=0.01)
    checked = LocalGroundFitter(pg, T_GLOBAL_FROM_EGO, None, CFG, bottoms).fit(xy)
    assert checked.source == "boxes" and checked.n_points == 3
    assert checked.point_global[2] == pytest.approx(5.0 + 0.1, abs=1e-9)  # their median height
    far = transform_points(T_GLOBAL_FROM_EGO, np.array([[30.0, 25.0, 0.1]]))  # 25 m away: no say
    assert LocalGroundFitter(pg, T_GLOBAL_FROM_EGO, None, CFG, far).fit(xy).source == "lidar-plane"
    agree = transform_points(T_GLOBAL_FROM_EGO, np.array([[30.0, 6.0, 0.9]]))  # 0.2 m from the fit: kept
    assert LocalGroundFitter(pg, T_GLOBAL_FROM_EGO, None, CFG, agree).fit(xy).source == "lidar-plane"


def test_box_bottoms_stand_under_the_centres():
    from streetaug.datasets.sample import Box
    from streetaug.placement.rules import box_bottoms

    box = Box(np.array([10.0, 2.0, 1.3]), np.array([1.8, 4.5, 1.6]), np.array([1.0, 0, 0, 0]), "vehicle.car")
    np.testing.assert_allclose(box_bottoms([box]), [[10.0, 2.0, 0.5]])
    assert box_bottoms([]).shape == (0, 3)


# ---------------------------------------------------------------------- rules, both sides of each threshold


def test_rule_distance_edges():
    cam_xy = np.array([3.0, -2.0])
    d = np.array([9.9, 10.1, 39.9, 40.1])
    ang = np.radians([10, 80, 200, 300])
    xy = cam_xy + d[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    assert rule_distance(xy, cam_xy, 10.0, 40.0).tolist() == [False, True, True, False]


@pytest.mark.parametrize("category,threshold", [("vehicle.car", 3.0), ("human.pedestrian.adult", 3.0),
                                                ("movable_object.barrier", 1.0)])
def test_rule_box_clearance_by_class(category, threshold):
    other = box_at_ego(20.0, 0.0, category, wlh=(W, L, 1.5))
    # candidates beside it (same heading): gap between footprints = threshold -/+ 0.1 m
    gaps = [threshold - 0.1, threshold + 0.1]
    fps = np.concatenate([fp_ego(20.0, W + g) for g in gaps])
    ok = rule_box_clearance(fps, box_footprints([other]), np.array([other.is_dynamic]), 3.0, 1.0)
    assert ok.tolist() == [False, True]
    # and measured between footprints, not centres: a candidate rotated 90 deg ahead of it
    ahead = fp_ego(20.0 + L / 2 + W / 2 + threshold + 0.1, 0.0, yaw_ego=np.pi / 2)
    assert rule_box_clearance(ahead, box_footprints([other]), np.array([other.is_dynamic]), 3.0, 1.0)[0]


def test_rule_obstacles_height_band_and_margin():
    fps = np.concatenate([fp_ego(20.0, 0.0), fp_ego(30.0, 0.0), fp_ego(40.0, 0.0)])
    g_point = transform_points(T_GLOBAL_FROM_EGO, np.array([[20.0, 0, 0], [30.0, 0, 0], [40.0, 0, 0]]))
    g_normal = np.tile(T_GLOBAL_FROM_EGO[:3, 2], (3, 1))
    obstacles_ego = np.array(
        [[20.0 + L / 2 + 0.9, 0.0, 1.0]] * 3  # 0.9 m in front of the first footprint, 1 m high: inside the margin
        + [[30.0, 0.5, 0.2]] * 3  # below the band (kerb-height debris) under the second
        + [[40.0 + L / 2 + 1.1, 0.0, 1.0]] * 3  # 1.1 m in front of the third: outside the 1 m margin
    )
    ok = rule_obstacles(fps, g_point, g_normal, transform_points(T_GLOBAL_FROM_EGO, obstacles_ego), 1.0, 0.3, 2.0, 2)
    assert ok.tolist() == [False, True, True]
    # tolerance: two points are accepted, three are not
    ok2 = rule_obstacles(fps[:1], g_point[:1], g_normal[:1],
                         transform_points(T_GLOBAL_FROM_EGO, obstacles_ego[:2]), 1.0, 0.3, 2.0, 2)
    assert ok2[0]


def test_rule_lidarseg_non_drivable_points():
    fps = np.concatenate([fp_ego(20.0, 0.0), fp_ego(30.0, 0.0)])
    side = ego_to_global_xy([[20.0, W / 2 + 0.9]] * 3 + [[30.0, W / 2 + 1.1]] * 3)
    assert rule_lidarseg(fps, side, 1.0, 2).tolist() == [False, True]


def _raster_inside_fraction(corners_cam: np.ndarray) -> float:
    """Independent check: rasterise the projected hull on a large canvas and count pixels in the image."""
    uv = corners_cam @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    off = np.array([2 * WIDTH, 2 * HEIGHT])
    canvas = np.zeros((5 * HEIGHT, 5 * WIDTH), np.uint8)
    hull = cv2.convexHull(np.round((uv + off) * 4).astype(np.int32))
    cv2.fillConvexPoly(canvas, hull, 1, shift=2)
    inside = canvas[2 * HEIGHT:3 * HEIGHT, 2 * WIDTH:3 * WIDTH].sum()
    return inside / canvas.sum()


def test_rule_in_view_and_inside_fraction():
    corners = box_corners_object(np.array([W, L, 1.5]))
    R = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float)  # object x -> cam z, y -> -x, z -> -y

    def at(x, y, z):
        return (corners @ R.T + [x, y, z])[None]

    centred, behind = at(0, 1.5, 20), at(0, 1.5, -20)
    half_out = at((WIDTH - 0.5 - K[0, 2]) * 20 / K[0, 0], 1.5, 20)  # straddles the right image edge
    frac = projected_inside_fraction(np.concatenate([centred, half_out, behind]), CAMERA, 0.5)
    assert frac[0] == pytest.approx(1.0)
    assert 0.05 < frac[1] < 0.95
    assert frac[1] == pytest.approx(_raster_inside_fraction(half_out[0]), abs=0.01)
    assert frac[2] == 0.0
    ok = rule_in_view(np.concatenate([centred, half_out, behind]), CAMERA, frac[1] + 0.01, 0.5)
    assert ok.tolist() == [True, False, False]
    ok = rule_in_view(np.concatenate([centred, half_out, behind]), CAMERA, frac[1] - 0.01, 0.5)
    assert ok.tolist() == [True, True, False]
    # a box straddling the near plane is not "in front of the camera" even if its projection is in the image
    straddle = at(0, 1.5, 2.0)
    assert not rule_in_view(straddle, CAMERA, 0.0, 0.5)[0]


def test_rule_mutual():
    placed = fp_ego(20.0, 0.0)
    fps = np.concatenate([fp_ego(20.0, W + 0.9), fp_ego(20.0, W + 1.1)])
    assert rule_mutual(fps, placed, 1.0).tolist() == [False, True]
    assert rule_mutual(fps, np.zeros((0, 4, 2)), 1.0).tolist() == [True, True]


# ---------------------------------------------------------------------- place_objects


def _scene():
    pts = ground_grid_ego(0.5)
    wall = np.c_[np.full(100, 28.0), np.linspace(-4, -3, 100), np.linspace(0.4, 1.6, 100)]  # unannotated pole
    boxes = [box_at_ego(20.0, 2.5), box_at_ego(35.0, -2.5, yaw_ego=np.pi), box_at_ego(15.0, -3.5, "movable_object.barrier", (0.5, 0.5, 1.0))]
    return make_sample(boxes=boxes, lidar=lidar_sweep(np.concatenate([pts, wall])))


def _check_all_rules(sample, view, placements, cfg=CFG):
    cam_xy = view.T_global_from_cam[:2, 3]
    road = sample.drivable_area_global[0]
    pts = sample.lidar.points_global
    fps = []
    for p in placements:
        fp = p.box.corners()[[0, 1, 5, 4], :2]
        fps.append(fp)
        assert road.contains(shapely.Polygon(fp))
        d = np.linalg.norm(p.box.center[:2] - cam_xy)
        assert cfg.min_distance_m <= d <= cfg.max_distance_m
        for b in sample.boxes:
            gap = shapely.Polygon(fp).distance(shapely.Polygon(b.corners()[[0, 1, 5, 4], :2]))
            assert gap >= (cfg.dynamic_clearance_m if b.is_dynamic else cfg.static_clearance_m)
        # the object sits on the ground: bottom centre at z = 5 (ego ground) within 2 cm
        assert abs(p.T_global_from_object[2, 3] - 5.0) < 0.02
        corners_cam = transform_points(view.T_cam_from_global, p.box.corners())
        assert np.all(corners_cam[:, 2] > 0)
    for i in range(len(fps)):
        for j in range(i):
            assert shapely.Polygon(fps[i]).distance(shapely.Polygon(fps[j])) >= cfg.mutual_clearance_m
    assert len(pts) > 0


def test_place_objects_passes_all_rules_and_is_deterministic():
    s = _scene()
    view = s.cameras["CAM_FRONT"]
    wlhs = [ObjectBox(np.array([1.8, 4.5, 1.5])), ObjectBox(np.array([2.0, 5.0, 1.8])), ObjectBox(np.array([1.7, 4.0, 1.5]))]
    r1 = place_objects(s, view, wlhs, np.random.default_rng(7))
    r2 = place_objects(s, view, wlhs, np.random.default_rng(7))
    r3 = place_objects(s, view, wlhs, np.random.default_rng(8))
    assert len(r1.placements) == 3 and r1.reason is None
    assert list(r1.report) == list(RULE_ORDER) and sum(r1.report.values()) > 0
    for a, b in zip(r1.placements, r2.placements):
        np.testing.assert_array_equal(a.T_global_from_object, b.T_global_from_object)
    assert not np.allclose(r1.placements[0].T_global_from_object, r3.placements[0].T_global_from_object)
    _check_all_rules(s, view, r1.placements)
    assert {p.drivable_source for p in r1.placements} == {"map"}
    assert {p.ground_source for p in r1.placements} <= {"lidar-plane"}
    assert len(r1.candidates_xy) == len(r1.rejected_by) == 3 * CFG.n_candidates


def test_place_objects_rejects_candidates_near_unannotated_obstacles():
    s = _scene()
    view = s.cameras["CAM_FRONT"]
    r = place_objects(s, view, [ObjectBox(np.array([1.8, 4.5, 1.5]))] * 3, np.random.default_rng(3),
                      dataclasses.replace(CFG, n_candidates=2000))
    assert r.report["lidar_obstacles"] > 0
    pole = transform_points(T_GLOBAL_FROM_EGO, np.array([[28.0, -3.5, 1.0]]))[0, :2]
    for p in r.placements:
        fp = shapely.Polygon(p.box.corners()[[0, 1, 5, 4], :2])
        assert fp.distance(shapely.Point(pole)) > CFG.static_clearance_m - 0.5


def test_place_objects_impossible_rules_give_reason():
    s = _scene()
    cfg = dataclasses.replace(CFG, min_distance_m=80.0, max_distance_m=90.0, n_candidates=50)
    r = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(np.array([1.8, 4.5, 1.5]))], np.random.default_rng(0), cfg)
    assert r.placements == [] and "no candidate passed" in r.reason and r.report["surface"] > 0


def test_yaw_along_ego_heading_faces_plus_z_in_front_camera():
    s = _scene()
    view = s.cameras["CAM_FRONT"]
    cfg = dataclasses.replace(CFG, yaw_sigma_deg=0.0, opposite_heading_probability=0.0)
    r = place_objects(s, view, [ObjectBox(np.array([1.8, 4.5, 1.5]))], np.random.default_rng(0), cfg)
    p = r.placements[0]
    front_cam = (view.T_cam_from_global @ p.T_global_from_object)[:3, 0]
    np.testing.assert_allclose(front_cam, [0, 0, 1], atol=1e-6)
    assert quat_to_yaw(p.box.rotation) == pytest.approx(EGO_YAW_RAD, abs=1e-9)
    cfg_opp = dataclasses.replace(cfg, opposite_heading_probability=1.0)
    p2 = place_objects(s, view, [ObjectBox(np.array([1.8, 4.5, 1.5]))], np.random.default_rng(0), cfg_opp).placements[0]
    np.testing.assert_allclose((view.T_cam_from_global @ p2.T_global_from_object)[:3, 0], [0, 0, -1], atol=1e-6)


def test_place_objects_rejects_bad_sizes():
    s = _scene()
    with pytest.raises(InputError, match="objects\\[0\\]"):
        place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(np.array([1.8, -4.5, 1.5]))], np.random.default_rng(0))
    with pytest.raises(InputError, match="ObjectBox"):  # a bare size is not an object
        place_objects(s, s.cameras["CAM_FRONT"], [np.array([1.8, 4.5, 1.5])], np.random.default_rng(0))
    with pytest.raises(ValueError):
        PlacementConfig(min_distance_m=50.0, max_distance_m=40.0)


def test_place_objects_with_lidarseg_only():
    pts = lidar_rings_ego()
    labels = np.where(np.abs(pts[:, 1]) <= ROAD_HALF_WIDTH_M, 24, 26)
    s = make_sample(polygons=None, lidar=lidar_sweep(pts, labels))
    r = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(np.array([1.8, 4.5, 1.5]))] * 2, np.random.default_rng(2))
    assert len(r.placements) == 2
    sidewalk = shapely.points(transform_points(T_GLOBAL_FROM_EGO, pts[labels == 26])[:, :2])
    for p in r.placements:
        assert p.drivable_source == "lidarseg" and p.ground_source == "lidarseg"
        corners_ego = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), p.box.corners())
        assert np.all(np.abs(corners_ego[:, 1]) <= ROAD_HALF_WIDTH_M)  # on the road
        # at most lidarseg_max_points sidewalk returns within the static clearance (1 m) of the footprint (the
        # rings are metres apart at 20-40 m, so the nearest return can be farther than the road's edge)
        near = shapely.distance(shapely.Polygon(p.box.corners()[[0, 1, 5, 4], :2]), sidewalk) <= CFG.static_clearance_m
        assert int(near.sum()) <= CFG.lidarseg_max_points


# ---------------------------------------------------------------------- the real nuScenes sample

REAL = (Path(__file__).parents[2] / ".." / "shared" / "data" / "nuscenes-real").resolve()
REAL_TOKEN = "ca9a282c9e77460f8360f564131a8af5"


@pytest.fixture(scope="module")
def real_sample():
    if not REAL.is_dir():
        pytest.skip(f"real nuScenes sample not found at {REAL}")
    return NuScenesReader(REAL, "v1.0-mini").sample(REAL_TOKEN)


def _raster_fraction(corners_cam, K_, width, height):
    uv = corners_cam @ K_.T
    uv = uv[:, :2] / uv[:, 2:]
    off = np.array([2 * width, 2 * height])
    canvas = np.zeros((5 * height, 5 * width), np.uint8)
    cv2.fillConvexPoly(canvas, cv2.convexHull(np.round((uv + 0.5 + off) * 4).astype(np.int32)), 1, shift=2)
    return canvas[2 * height:3 * height, 2 * width:3 * width].sum() / canvas.sum()


@pytest.mark.parametrize("camera", ["CAM_FRONT", "CAM_BACK"])
def test_real_sample_placements_pass_every_rule(real_sample, camera):
    s = real_sample
    view = s.cameras[camera]
    road = shapely.union_all(s.drivable_area_global)
    pts = s.lidar.points_global
    tree = cKDTree(pts[:, :2])
    cam_xy = view.T_global_from_cam[:2, 3]
    n_placed = 0
    for seed in range(3):
        r = place_objects(s, view, [ObjectBox(np.array([1.9, 4.6, 1.6])), ObjectBox(np.array([1.8, 4.2, 1.5]))], np.random.default_rng(seed))
        assert r.placements, r.reason
        fps = []
        for p in r.placements:
            n_placed += 1
            assert p.drivable_source == "map" and p.ground_source == "lidar-plane"
            fp = shapely.Polygon(p.box.corners()[[0, 1, 5, 4], :2])
            fps.append(fp)
            assert road.contains(fp)
            assert 10.0 <= np.linalg.norm(p.box.center[:2] - cam_xy) <= 40.0
            for b in s.boxes:
                gap = fp.distance(shapely.Polygon(b.corners()[[0, 1, 5, 4], :2]))
                assert gap >= (3.0 if b.is_dynamic else 1.0), (b.category, gap)
            corners_cam = transform_points(view.T_cam_from_global, p.box.corners())
            assert np.all(corners_cam[:, 2] > 0.5)
            assert _raster_fraction(corners_cam, view.K, view.width, view.height) >= 0.5 - 0.01
            # ground contact: LiDAR ground points near the bottom centre lie on the object's bottom plane
            T = p.T_global_from_object
            d = (pts[tree.query_ball_point(T[:2, 3], 2.5)] - T[:3, 3]) @ T[:3, 2]
            d = d[np.abs(d) < 0.5]
            if len(d) >= 5:
                assert abs(np.median(d)) <= 0.10
        for i in range(len(fps)):
            for j in range(i):
                assert fps[i].distance(fps[j]) >= CFG.mutual_clearance_m
    assert n_placed >= 4


def test_real_sample_label_matches_placement(real_sample):
    s = real_sample
    view = s.cameras["CAM_FRONT"]
    p = place_objects(s, view, [ObjectBox(np.array([1.9, 4.6, 1.6]))], np.random.default_rng(0)).placements[0]
    T_co = p.T_cam_from_object(view)
    cov = np.zeros((view.height, view.width))
    corners_cam = transform_points(T_co, box_corners_object(p.wlh))
    uv = corners_cam @ view.K.T
    cv2.fillConvexPoly(cov, cv2.convexHull(np.round(uv[:, :2] / uv[:, 2:]).astype(np.int32)), 1.0)
    lab = object_label(T_co, p.wlh, "vehicle.car", PinholeCamera(view.K, view.width, view.height), cov, cov,
                       view.T_global_from_cam, p.attribute)
    np.testing.assert_allclose(lab["box_global"]["translation"], p.box.center, atol=1e-6)
    np.testing.assert_allclose(np.abs(np.dot(lab["box_global"]["rotation"], p.box.rotation)), 1.0, atol=1e-9)
    assert lab["visible_fraction"] == 1.0 and lab["visibility_token"] == "4" and lab["truncation"] < 0.5
    # the ego heads along the road: the yaw in the forward camera is near 0 or 180 deg
    assert min(abs(lab["box_camera"]["yaw_deg"]), 180 - abs(lab["box_camera"]["yaw_deg"])) < 20


def test_lidarseg_fixture_drivable_and_ground():
    root = (Path(__file__).parents[2] / ".." / "shared" / "data" / "nuscenes-fixtures").resolve()
    if not root.is_dir():
        pytest.skip(f"lidarseg fixture not found at {root}")
    pts = read_lidar_points(next((root / "samples" / "LIDAR_TOP").glob("*.pcd.bin")))[:, :3].astype(np.float64)
    labels = read_lidarseg_labels(next((root / "lidarseg").rglob("*_lidarseg.bin")), len(pts))
    T_ego_from_lidar = make_transform(np.eye(3), [0.0, 0.0, 1.84])
    sweep = LidarSweep(pts, np.zeros(len(pts), np.float32), T_ego_from_lidar, np.eye(4), 0, labels)
    s = make_sample(polygons=None, lidar=sweep)
    area, reason = drivable_area_for_sample(s, s.cameras["CAM_FRONT"], CFG)
    assert reason is None and area.source == "lidarseg"
    pg = sweep.points_global
    assert area.contains_points(pg[labels == 24, :2]).all()
    manmade_low = (labels == 28) & (pg[:, 2] < 1.0)
    assert manmade_low.any() and not area.contains_points(pg[manmade_low, :2]).any()
    plane = LocalGroundFitter(pg, np.eye(4), labels, dataclasses.replace(CFG, ground_min_points=3)).fit(np.array([1.0, -4.0]))
    assert plane.source == "lidarseg"
    near = (labels == 24) & (np.hypot(pg[:, 0] - 1.0, pg[:, 1] + 4.0) < 4.0)
    assert abs(plane.point_global[2] - np.median(pg[near, 2])) < 0.15


def test_points_in_boxes_matches_brute_force():
    rng = np.random.default_rng(0)
    boxes = [box_at_ego(10.0, 2.0, yaw_ego=0.3), box_at_ego(20.0, -3.0, wlh=(2.5, 10.0, 3.0), yaw_ego=-1.0)]
    pts = transform_points(T_GLOBAL_FROM_EGO, np.c_[rng.uniform(0, 30, 20000), rng.uniform(-8, 8, 20000),
                                                     rng.uniform(-1, 4, 20000)])
    got = points_in_boxes(pts, boxes, margin_m=0.2)
    want = np.zeros(len(pts), bool)
    for b in boxes:
        local = (pts - b.center) @ quat_to_rotation(b.rotation)
        want |= np.all(np.abs(local) <= np.asarray(b.wlh)[[1, 0, 2]] / 2 + 0.2, axis=1)
    assert want.sum() > 100 and np.array_equal(got, want)


@pytest.mark.parametrize("polygons", ["road", None])
def test_explain_bev_draws_candidates_and_placements(polygons):
    pts = ground_grid_ego(0.5)
    s = make_sample(boxes=[box_at_ego(20.0, 2.5)], polygons=polygons, lidar=lidar_sweep(pts, np.full(len(pts), 24)))
    view = s.cameras["CAM_FRONT"]
    r = place_objects(s, view, [ObjectBox(np.array([1.8, 4.5, 1.5]))], np.random.default_rng(0))
    img = draw_placement_bev(s, view, r)
    assert img.shape == (800, 800, 3) and img.dtype == np.uint8
    colours = {tuple(c) for c in img.reshape(-1, 3)}
    assert RULE_COLORS_RGB[""] in colours and RULE_COLORS_RGB["annotated_boxes"] in colours


def test_rule_corners_unoccluded():
    corners = box_corners_object(np.array([W, L, 1.5]))
    R = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float)  # object x -> cam z
    box = (corners @ R.T + [0.0, 1.5, 20.0])[None]  # top corners at camera y = 0, z = 17.75 / 22.25
    # an occluder 10 m away covering the box's upper part, vs the same occluder 2.5 m behind the box
    occ_y, occ_x = np.meshgrid(np.linspace(-0.5, 0.5, 40), np.linspace(-2.0, 2.0, 80))
    for z_occ, expect in [(10.0, False), (22.25 + 2.5, True)]:
        pts = np.c_[occ_x.ravel(), occ_y.ravel(), np.full(occ_x.size, z_occ)]
        depth = densify_lidar_depth(pts, K, WIDTH, HEIGHT)
        assert np.isfinite(depth).sum() > 100 and np.nanmin(depth) == pytest.approx(z_occ, abs=1e-4)
        assert rule_corners_unoccluded(box, CAMERA, depth, 1.0)[0] == expect
    # unknown depth (inf) never occludes
    assert rule_corners_unoccluded(box, CAMERA, np.full((HEIGHT, WIDTH), np.inf, np.float32), 1.0)[0]


def test_place_objects_with_occlusion_rule():
    s = _scene()
    cfg = dataclasses.replace(CFG, require_unoccluded_corners=True)
    r = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(np.array([1.8, 4.5, 1.5]))] * 2, np.random.default_rng(1), cfg)
    assert len(r.placements) == 2 and "corners_unoccluded" in r.report
    _check_all_rules(s, s.cameras["CAM_FRONT"], r.placements, cfg)


def test_real_sample_front_left_sees_no_road_in_range(real_sample):
    """CAM_FRONT_LEFT of scene-0061 looks at the kerbside: almost no drivable area 10-40 m inside its view,
    so no placement, with the drivable rule as the reason; the road it sees is nearer than 7 m."""
    s = real_sample
    view = s.cameras["CAM_FRONT_LEFT"]
    r = place_objects(s, view, [ObjectBox(np.array([1.9, 4.6, 1.6]))], np.random.default_rng(0))
    assert r.placements == [] and "surface" in r.reason
    assert r.report["surface"] >= 0.95 * CFG.n_candidates
    near = dataclasses.replace(CFG, min_distance_m=5.0, n_candidates=3000)
    placed = place_objects(s, view, [ObjectBox(np.array([1.9, 4.6, 1.6]))], np.random.default_rng(0), near).placements
    assert placed and placed[0].distance_m < 7.0
