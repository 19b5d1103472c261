"""Lanes: map expansion lane centre lines (arcline paths, edge lines) and yaw along the lane direction."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import shapely

from placement_fixtures import (
    EGO_YAW_RAD,
    T_GLOBAL_FROM_EGO,
    ego_to_global_xy,
    ground_grid_ego,
    lane_ego,
    lanes_from,
    lidar_sweep,
    make_sample,
)
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core import project_points, transform_points
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.errors import DatasetError
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.nuscenes_map import discretize_arcline_path, read_lanes
from streetaug.placement.config import PlacementConfig
from streetaug.placement.explain import LANE_COLOR_RGB, RULE_COLORS_RGB, draw_placement_bev
from streetaug.placement.place import ObjectBox, place_objects

CFG = PlacementConfig()
WLH = np.array([1.8, 4.5, 1.5])


def _angle_diff(a: float, b: float) -> float:
    """a - b wrapped to (-pi, pi]."""
    return float(np.angle(np.exp(1j * (a - b))))


def _heading(T_global_from_object: np.ndarray) -> float:
    return float(np.arctan2(T_global_from_object[1, 0], T_global_from_object[0, 0]))


# ---------------------------------------------------------------------- arcline paths


def test_arcline_quarter_circle_left_then_straight():
    r = 10.0
    path = {"start_pose": [5.0, -2.0, 0.0], "end_pose": [0, 0, 0], "shape": "LSR", "radius": r,
            "segment_length": [np.pi / 2 * r, 4.0, 0.0]}
    pts = discretize_arcline_path(path, resolution_m=0.5)
    # a left quarter circle from heading 0 ends at (+r, +r) heading 90 deg, then 4 m straight north
    np.testing.assert_allclose(pts[0], [5.0, -2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pts[-1], [5.0 + r, -2.0 + r + 4.0, np.pi / 2], atol=1e-9)
    # every arc sample lies on the circle centred at (5, 8) and the heading is its tangent
    arc = pts[np.abs(pts[:, 2]) < np.pi / 2 - 1e-9]
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 5.0, arc[:, 1] - 8.0), r, atol=1e-9)
    step = np.diff(pts[:, :2], axis=0)
    assert np.linalg.norm(step, axis=1).max() <= 0.5 + 1e-9
    chord_heading = np.arctan2(step[:, 1], step[:, 0])
    mid_heading = 0.5 * (pts[1:, 2] + pts[:-1, 2])
    np.testing.assert_allclose(chord_heading, mid_heading, atol=1e-6)


def test_arcline_right_turn_and_bad_record():
    path = {"start_pose": [0.0, 0.0, np.pi / 2], "shape": "RSS", "radius": 5.0,
            "segment_length": [np.pi / 2 * 5.0, 0.0, 0.0]}
    end = discretize_arcline_path(path)[-1]
    np.testing.assert_allclose(end, [5.0, 5.0, 0.0], atol=1e-9)  # heading north, turning right ends heading east
    with pytest.raises(ValueError, match="shape"):
        discretize_arcline_path({**path, "shape": "LXS"})


# ---------------------------------------------------------------------- map expansion files


def _map_with_lanes(tmp_path: Path, lanes: list[dict], arclines: dict, lines=(), nodes=()) -> Path:
    doc = {"version": "1.3", "node": list(nodes), "line": list(lines), "polygon": [], "drivable_area": [],
           "lane": lanes, "lane_connector": [], "arcline_path_3": arclines}
    path = tmp_path / "maps" / "expansion" / "test-location.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc))
    return path


def test_read_lanes_from_arclines_and_edge_lines(tmp_path):
    nodes = [{"token": t, "x": x, "y": y} for t, x, y in
             [("a0", 0.0, 20.0), ("a1", 0.0, 23.0), ("b0", -10.0, 20.0), ("b1", -10.0, 23.0)]]
    lines = [{"token": "from", "node_tokens": ["a0", "a1"]}, {"token": "to", "node_tokens": ["b0", "b1"]}]
    lanes = [{"token": "east", "polygon_token": ""},
             {"token": "west", "polygon_token": "", "from_edge_line_token": "from", "to_edge_line_token": "to"},
             {"token": "nothing", "polygon_token": ""}]
    arclines = {"east": [{"start_pose": [0.0, 0.0, 0.0], "end_pose": [20.0, 0.0, 0.0], "shape": "SSS",
                          "radius": 999.0, "segment_length": [10.0, 5.0, 5.0]}]}
    got = read_lanes(_map_with_lanes(tmp_path, lanes, arclines, lines, nodes))
    assert got.tokens == ("east", "west")  # "nothing" has no centre line
    heading, found = got.heading_at(np.array([[10.0, 1.0], [-5.0, 21.0], [-5.0, 30.0]]), 2.0)
    assert found.tolist() == [True, True, False]
    # the "west" lane runs from its "from" edge (x = 0) to its "to" edge (x = -10)
    np.testing.assert_allclose(np.c_[np.cos(heading[:2]), np.sin(heading[:2])], [[1, 0], [-1, 0]], atol=1e-9)


def test_read_lanes_none_and_errors(tmp_path):
    assert read_lanes(_map_with_lanes(tmp_path, [], {})) is None
    bad = _map_with_lanes(tmp_path, [{"token": "x"}], {"x": [{"start_pose": [0, 0]}]})
    with pytest.raises(DatasetError, match="malformed lane record"):
        read_lanes(bad)
    with pytest.raises(DatasetError, match="not found"):
        read_lanes(tmp_path / "missing.json")


REAL = (Path(__file__).parents[2] / ".." / "shared" / "data" / "nuscenes-real").resolve()


def test_bundled_maps_have_lanes_the_real_excerpt_has_none():
    """The bundled maps carry the generated streets' four travel lanes; the nuScenes-mini excerpt has none."""
    for path in (bundled_dataroot() / "maps" / "expansion").glob("*.json"):
        lanes = read_lanes(path)
        assert lanes is not None and len(lanes.tokens) % 4 == 0 and len(lanes.tokens) > 0
    if REAL.is_dir():
        assert read_lanes(REAL / "maps" / "expansion" / "singapore-onenorth.json") is None


def test_bundled_scenes_place_along_their_lanes():
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    (p,) = place_objects(sample, sample.cameras["CAM_FRONT"], [procedural_car(1)], np.random.default_rng(0),
                         class_rules=_fixed_weights()).placements
    assert p.yaw_source == "lane" and p.asset_index == 0


def _fixed_weights():
    """The table's car rule with fixed zone weights: the bundled scenes' annotated cars are parked, so with the
    scene's weights a car parks as they do (test_parking.py); these tests are about the lanes' heading."""
    import tempfile

    from streetaug.placement.class_rules import read_class_rules

    path = Path(tempfile.mkdtemp()) / "fixed.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {"car": {"zone_weights": "fixed"}}}))
    return read_class_rules(path)


def test_reader_attaches_lanes_and_placement_follows_them(tmp_path):
    """A copy of a bundled scene whose lanes are replaced by one lane 20 deg off the ego heading, through the view."""
    src = bundled_dataroot()
    root = tmp_path / "ds"
    root.mkdir()
    for name in ("v1.0-samples", "lidarseg", "maps"):
        shutil.copytree(src / name, root / name)
    (root / "samples").symlink_to(src / "samples")
    reader = NuScenesReader(root, "v1.0-samples")
    token = reader.sample_tokens()[0]
    sample = reader.sample(token)
    assert sample.lanes is not None and len(sample.lanes.tokens) >= 4  # the generated street's own lanes
    view = sample.cameras["CAM_FRONT"]
    T = view.T_global_from_ego
    yaw_ego = np.arctan2(T[1, 0], T[0, 0])
    lane_yaw = yaw_ego + np.radians(20.0)
    start = T[:2, 3] + 8.0 * np.array([np.cos(yaw_ego), np.sin(yaw_ego)])
    map_path = root / "maps" / "expansion" / f"{sample.location}.json"
    doc = json.loads(map_path.read_text())
    doc["lane"] = [{"token": "lane-1", "polygon_token": ""}]
    doc["arcline_path_3"] = {"lane-1": [{"start_pose": [*start, lane_yaw], "end_pose": [0, 0, 0], "shape": "SSS",
                                         "radius": 999.0, "segment_length": [40.0, 0.0, 0.0]}]}
    map_path.write_text(json.dumps(doc))

    sample = NuScenesReader(root, "v1.0-samples").sample(token)
    assert sample.lanes is not None and sample.lanes.tokens == ("lane-1",)
    cfg = dataclasses.replace(CFG, yaw_sigma_deg=0.0, lane_max_distance_m=30.0)  # the whole view takes the lane
    r = place_objects(sample, view, [ObjectBox(WLH)], np.random.default_rng(0), cfg, class_rules=_fixed_weights())
    assert r.placements, r.reason
    p = r.placements[0]
    assert p.yaw_source == "lane"
    assert abs(_angle_diff(_heading(p.T_global_from_object), lane_yaw)) < 1e-6


# ---------------------------------------------------------------------- yaw along lanes (synthetic street)


def _wide_road_sample(lanes):
    road = shapely.Polygon(ego_to_global_xy([[-20, -30], [90, -30], [90, 30], [-20, 30]]))
    pts = ground_grid_ego(1.0, y_half=30.0)
    return make_sample(polygons=[road], lidar=lidar_sweep(pts), lanes=lanes)


def test_yaw_follows_lane_direction_including_oncoming_lane():
    # our lane (ego direction) at y = -2, the oncoming lane at y = +2 (heading + 180 deg)
    oncoming = lane_ego(2.0)[::-1] + [0.0, 0.0, np.pi]
    lanes = lanes_from(lane_ego(-2.0), oncoming)
    s = _wide_road_sample(lanes)
    view = s.cameras["CAM_FRONT"]
    cfg = dataclasses.replace(CFG, yaw_sigma_deg=0.0, opposite_heading_probability=0.5)
    sides = []
    for seed in range(12):
        for p in place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(seed), cfg).placements:
            y_ego = transform_points(np.linalg.inv(T_GLOBAL_FROM_EGO), p.box.center[None])[0, 1]
            front_cam = (view.T_cam_from_global @ p.T_global_from_object)[:3, 0]
            if p.yaw_source == "lane":
                sides.append(np.sign(y_ego))
                want = [0, 0, 1] if y_ego < 0 else [0, 0, -1]  # our lane: away from the camera; oncoming: towards it
                np.testing.assert_allclose(front_cam, want, atol=1e-6)
            else:  # off the lanes (> 2 m from both): the ego heading or its opposite
                assert abs(abs(y_ego) - 2.0) > 2.0 - 1e-6 or abs(y_ego) > 4.0
                np.testing.assert_allclose(np.abs(front_cam), [0, 0, 1], atol=1e-6)
    assert {-1.0, 1.0} <= set(sides)


def test_car_along_a_slanted_lane_faces_along_the_lane_in_the_image():
    """A lane 25 deg left of the ego heading: in the image, the car's back-to-front axis runs along the lane."""
    lane = lane_ego(-4.0, np.radians(25.0), x_range=(0.0, 60.0), resolution_m=0.25)
    strip = shapely.LineString(lane[:, :2]).buffer(2.0)  # the road is the lane +- 2 m
    s = make_sample(polygons=[strip], lidar=lidar_sweep(ground_grid_ego(1.0, y_half=30.0)), lanes=lanes_from(lane))
    view = s.cameras["CAM_FRONT"]
    cfg = dataclasses.replace(CFG, yaw_sigma_deg=0.0)
    lane_dir = (lane[-1, :2] - lane[0, :2]) / np.linalg.norm(lane[-1, :2] - lane[0, :2])  # from the polyline
    n_checked = 0
    for seed in range(4):
        for p in place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(seed), cfg).placements:
            assert p.yaw_source == "lane"
            n_checked += 1
            T_co = view.T_cam_from_global @ p.T_global_from_object
            car = transform_points(T_co, np.array([[-WLH[1] / 2, 0, 0], [WLH[1] / 2, 0, 0]]))  # back, front
            c = p.T_global_from_object[:3, 3]
            along = np.stack([c - np.r_[lane_dir, 0] * WLH[1] / 2, c + np.r_[lane_dir, 0] * WLH[1] / 2])
            uv_car, _ = project_points(view.K, car)
            uv_lane, _ = project_points(view.K, transform_points(view.T_cam_from_global, along))
            d_car, d_lane = uv_car[1] - uv_car[0], uv_lane[1] - uv_lane[0]
            assert np.linalg.norm(d_lane) > 5.0
            assert d_car @ d_lane / np.linalg.norm(d_car) / np.linalg.norm(d_lane) > 0.9999
            np.testing.assert_allclose(uv_car, uv_lane, atol=0.05)
    assert n_checked == 4


def test_lanes_can_be_switched_off():
    lanes = lanes_from(lane_ego(0.0, np.radians(30.0)))
    s = _wide_road_sample(lanes)
    cfg = dataclasses.replace(CFG, use_lanes=False, yaw_sigma_deg=0.0, opposite_heading_probability=0.0)
    p = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(WLH)], np.random.default_rng(0), cfg).placements[0]
    assert p.yaw_source == "ego"
    assert abs(_angle_diff(_heading(p.T_global_from_object), EGO_YAW_RAD)) < 1e-9


def test_explain_draws_lanes_and_the_sampled_region():
    s = _wide_road_sample(lanes_from(lane_ego(-2.0)))
    view = s.cameras["CAM_FRONT"]
    r = place_objects(s, view, [ObjectBox(WLH)], np.random.default_rng(0))
    img = draw_placement_bev(s, view, r)
    colours = {tuple(c) for c in img.reshape(-1, 3)}
    assert LANE_COLOR_RGB in colours and RULE_COLORS_RGB[""] in colours and (120, 110, 0) in colours
