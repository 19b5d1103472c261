"""Vehicles park as the sample's own do: the kerb share from their parked share, the pose from the nearest one."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import shapely

from placement_fixtures import EGO_YAW_RAD, ROAD_HALF_WIDTH_M, box_at_ego, ground_grid_ego, lidar_sweep, make_sample
from streetaug.datasets.nuscenes_format import VEHICLE_MOVING, VEHICLE_PARKED
from streetaug.placement.audit import audit_placements
from streetaug.placement.class_rules import read_class_rules
from streetaug.placement.parking import PRIOR_OBJECTS, parked_gap_m, parked_share, with_parked_share
from streetaug.placement.place import ObjectBox, place_objects, scene_rule
from streetaug.placement.scene import scene_depth

CAR = ObjectBox(np.array([1.85, 4.5, 1.6]), "vehicle.car")
N_SEEDS = 12


def _with(box, attribute: str):
    return dataclasses.replace(box, attributes=(attribute,))


def _bays(attribute: str = VEHICLE_PARKED):
    """Cars in perpendicular bays along both road edges (nose 0.25 m in from them), beyond the camera's near range."""
    y = ROAD_HALF_WIDTH_M - 2.5
    return [_with(box_at_ego(x, side * y, yaw_ego=np.pi / 2), attribute) for x, side in
            ((12.0, 1), (45.0, 1), (55.0, 1), (50.0, -1), (55.0, -1), (60.0, -1))]


def _sample(boxes):
    return make_sample(boxes=boxes, lidar=lidar_sweep(ground_grid_ego(0.5, (-10.0, 70.0), 12.0)))


def _place(sample, class_rules=None, n: int = N_SEEDS):
    view = sample.cameras["CAM_FRONT"]
    depth = scene_depth(sample, view)
    out = []
    for seed in range(n):
        r = place_objects(sample, view, [CAR], np.random.default_rng(seed), depth_m=depth, class_rules=class_rules)
        assert all(a.ok for a in audit_placements(sample, view, r.placements, r.drivable, r.config, class_rules))
        out += r.placements
    return out


def _angle_to_road_deg(p) -> float:
    """Angle (0..90 deg) between a placement's heading and the road (along ego x)."""
    T = p.T_global_from_object
    d = np.arctan2(T[1, 0], T[0, 0]) - EGO_YAW_RAD
    return float(np.degrees(np.arccos(abs(np.cos(d)))))


def test_the_kerb_weight_follows_the_share_of_parked_vehicles_with_the_table_as_prior():
    car = read_class_rules().classes["car"]
    lane, kerb = car.zones["lane"], car.zones["kerb"]
    all_parked = with_parked_share(car, 20, 20).zones
    assert all_parked["kerb"] / (lane + kerb) == pytest.approx((20 + PRIOR_OBJECTS * kerb / (lane + kerb)) / 22)
    assert all_parked["kerb"] + all_parked["lane"] == pytest.approx(lane + kerb)
    assert with_parked_share(car, 0, 20).zones["lane"] > 0.9 * (lane + kerb)
    assert with_parked_share(car, 0, 0).zones == pytest.approx(car.zones)  # no evidence: the table's split
    fixed = dataclasses.replace(car, zone_weights="fixed")
    assert with_parked_share(fixed, 20, 20).zones == car.zones
    lane_only = dataclasses.replace(car, zones={"lane": 1.0})
    assert with_parked_share(lane_only, 20, 20).zones == {"lane": 1.0}


def test_parked_share_counts_the_class_categories_and_vehicle_attributes_only():
    boxes = _bays() + [_with(box_at_ego(25.0, -2.0), VEHICLE_MOVING), box_at_ego(30.0, 2.0),  # no attribute
                       _with(box_at_ego(35.0, 2.0, "vehicle.truck"), VEHICLE_PARKED)]
    assert parked_share(boxes, {"vehicle.car"}) == (6, 7)
    rules = read_class_rules()
    assert scene_rule(rules, rules.classes["car"], boxes).zones["kerb"] == pytest.approx(
        with_parked_share(rules.classes["car"], 6, 7).zones["kerb"])


def test_cars_among_parked_cars_park_and_stand_in_bays_as_they_do():
    """All annotated cars parked in perpendicular bays: inserted cars go to the kerb, at 90 deg to the road,
    labelled parked, every rule re-checked by the audit."""
    placed = _place(_sample(_bays()))
    kerb = [p for p in placed if p.zone == "kerb"]
    assert len(placed) >= N_SEEDS - 2 and len(kerb) >= 0.7 * len(placed)
    assert all(p.attribute == VEHICLE_PARKED and p.yaw_source == "kerb" for p in kerb)
    assert np.median([_angle_to_road_deg(p) for p in kerb]) > 80.0
    # in a bay: the centre about half a length in from the edge, as the annotated cars
    inward = [ROAD_HALF_WIDTH_M - abs(float(np.asarray(_ego_xy(p))[1])) for p in kerb]
    assert np.median(inward) == pytest.approx(2.5, abs=0.4)


def _ego_xy(p):
    from placement_fixtures import T_GLOBAL_FROM_EGO
    from streetaug.augment.core import invert_transform, transform_points

    return transform_points(invert_transform(T_GLOBAL_FROM_EGO), p.box.center[None])[0, :2]


def test_without_parked_cars_the_table_split_holds_and_kerb_cars_stand_along_the_edge():
    moving = [_with(box_at_ego(x, -2.5), VEHICLE_MOVING) for x in (12.0, 45.0)]
    placed = _place(_sample(moving))
    kerb = [p for p in placed if p.zone == "kerb"]
    assert len(kerb) <= 0.5 * len(placed)  # moving cars: mostly in the lane
    assert all(_angle_to_road_deg(p) < 12.0 for p in kerb)


def test_a_fixed_override_keeps_the_table_weights_and_the_lane_heading(tmp_path):
    path = tmp_path / "fixed.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {"car": {"zone_weights": "fixed"}}}))
    rules = read_class_rules(path)
    sample = _sample(_bays())
    assert scene_rule(rules, rules.classes["car"], sample.boxes).zones == {"lane": 0.6, "kerb": 0.4}
    placed = _place(sample, rules)
    assert all(_angle_to_road_deg(p) < 12.0 and p.yaw_source != "kerb" for p in placed)
    lane_only = tmp_path / "lane.json"
    lane_only.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {"car": {"zones": {"lane": 1}}}}))
    assert {p.zone for p in _place(sample, read_class_rules(lane_only), n=4)} == {"lane"}


def test_zone_weights_must_be_fixed_or_scene(tmp_path):
    from streetaug.augment.core import InputError

    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {"car": {"zone_weights": "city"}}}))
    with pytest.raises(InputError, match="zone_weights"):
        read_class_rules(path)


def test_the_parking_gap_is_how_close_parked_vehicles_stand_to_their_neighbours():
    row = [_with(box_at_ego(x, 2.5, yaw_ego=np.pi / 2), VEHICLE_PARKED) for x in np.arange(6.0, 40.0, 2.6)]
    assert parked_gap_m(row, 1.0) == pytest.approx(2.6 - 1.8, abs=1e-6)  # box_at_ego's cars are 1.8 m wide
    assert parked_gap_m(row[:2], 1.0) == 1.0  # too few to say: the static clearance
    assert parked_gap_m([dataclasses.replace(b, attributes=(VEHICLE_MOVING,)) for b in row], 1.0) == 1.0
    far = [_with(box_at_ego(x, 2.5, yaw_ego=np.pi / 2), VEHICLE_PARKED) for x in np.arange(6.0, 40.0, 9.0)]
    assert parked_gap_m(far, 1.0) == 1.0  # at most the static clearance


def test_a_car_parks_in_a_free_bay_between_parked_cars_at_the_parking_gap():
    """Rows of parked cars 6 m apart on both edges (0.5 m apart across the road): the kerb has room only between two
    of them, where a car keeps the scene's parking gap from parked vehicles, not the dynamic clearance (3 m) of moving
    things."""
    y = ROAD_HALF_WIDTH_M - 2.5
    rows = [_with(box_at_ego(x, side * y, yaw_ego=np.pi / 2), VEHICLE_PARKED)
            for x in np.arange(6.0, 60.0, 6.0) for side in (1, -1)]
    gap_m = parked_gap_m(rows, 1.0)
    assert gap_m == pytest.approx(0.5, abs=1e-6)
    sample = _sample(rows)
    kerb = [p for p in _place(sample) if p.zone == "kerb"]
    assert len(kerb) >= N_SEEDS // 2
    footprints = [shapely.Polygon(b.corners()[[0, 1, 5, 4], :2]) for b in rows]
    gaps = [min(shapely.Polygon(p.footprint_xy).distance(f) for f in footprints) for p in kerb]
    assert all(gap_m - 1e-6 <= g < 3.0 for g in gaps)
