"""Per-class placement: the rule table, the zones (lane, kerb, road edge, sidewalk, crossing), clusters, the mix."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

from placement_fixtures import (ROAD_HALF_WIDTH_M, T_GLOBAL_FROM_EGO, ego_to_global_xy, lidar_sweep, make_sample,
                                road_polygon_global)
from streetaug.augment.assets.categories import DETECTION_CLASSES, NUSCENES_OBJECT_CATEGORIES
from streetaug.augment.assets.class_sizes import read_class_sizes
from streetaug.augment.assets.classes import CLASS_CATEGORIES, ClassMix
from streetaug.augment.core import InputError, transform_points
from streetaug.placement.audit import audit_placements
from streetaug.placement.class_rules import read_class_rules
from streetaug.placement.explain import class_rule_lines
from streetaug.placement.place import ObjectBox, place_objects
from streetaug.placement.zones import CLUSTER_TAPER_M, ROAD_EDGE_BAND_M, surface_zones

SIDEWALK_HEIGHT_M = 0.15
SIZES = read_class_sizes()


def _box(detection_class: str) -> ObjectBox:
    category = CLASS_CATEGORIES[detection_class][0][0]
    return ObjectBox(SIZES[category].mean_wlh.copy(), category)


def _street(crossing: bool = True):
    """The fixture road (|y_ego| <= 5 m) with raised sidewalks (+15 cm, 5-9 m off the centre line), walls beyond
    (LiDAR obstacles), dense ground points, and a zebra crossing across the road at x_ego 24-28 m."""
    x, y = np.meshgrid(np.arange(-10.0, 60.0, 0.25), np.arange(-9.0, 9.0, 0.25))
    x, y = x.ravel(), y.ravel()
    z = np.where(np.abs(y) > ROAD_HALF_WIDTH_M, SIDEWALK_HEIGHT_M, 0.0)
    wall_x, wall_z = np.meshgrid(np.arange(-10.0, 60.0, 0.25), np.arange(0.2, 3.0, 0.25))
    walls = np.concatenate([np.c_[wall_x.ravel(), np.full(wall_x.size, side * 9.5), wall_z.ravel()]
                            for side in (-1, 1)])
    points = np.concatenate([np.c_[x, y, z], walls])
    crossings = (shapely.Polygon(ego_to_global_xy([[24, -5.5], [28, -5.5], [28, 5.5], [24, 5.5]])),) if crossing else ()
    s = make_sample(lidar=lidar_sweep(points))
    import dataclasses

    return dataclasses.replace(s, ped_crossings_global=crossings).with_lidar(s.lidar)


def _place_many(sample, detection_class: str, n: int, seed0: int = 0):
    from streetaug.placement.scene import scene_depth

    view = sample.cameras["CAM_FRONT"]
    depth_m = scene_depth(sample, view)
    out = []
    for seed in range(seed0, seed0 + n):
        r = place_objects(sample, view, [_box(detection_class)], np.random.default_rng(seed), depth_m=depth_m)
        out.append(r)
    return out


# ---------------------------------------------------------------------------------------------- the table


def test_every_class_and_category_has_a_rule():
    rules = read_class_rules()
    assert set(DETECTION_CLASSES) <= set(rules.classes)
    for category in NUSCENES_OBJECT_CATEGORIES:
        assert rules.for_category(category).name in rules.classes
    assert rules.for_category("human.pedestrian.child").name == "pedestrian"
    assert rules.classes["bus"].config(__import__("streetaug.placement.config", fromlist=["x"]).PlacementConfig()
                                       ).dynamic_clearance_m == 4.0


def test_an_override_file_changes_fields_and_bad_fields_are_named(tmp_path):
    path = tmp_path / "rules.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1",
                                "classes": {"pedestrian": {"zones": {"sidewalk": 1.0}, "distance_m": [5, 20]}}}))
    rules = read_class_rules(path)
    assert rules.classes["pedestrian"].zones == {"sidewalk": 1.0}
    assert rules.classes["pedestrian"].distance_m == (5.0, 20.0)
    assert rules.classes["pedestrian"].static_clearance_m == read_class_rules().classes["pedestrian"].static_clearance_m
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {"bus": {"zones": {"roof": 1}}}}))
    with pytest.raises(InputError, match=r"classes\.bus\.zones: unknown zone 'roof'; expected one of lane"):
        read_class_rules(path)
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1", "categories": {"animal": "dragon"}}))
    with pytest.raises(InputError, match="categories.animal: class 'dragon' has no rule"):
        read_class_rules(path)


# ---------------------------------------------------------------------------------------------- zones


def test_pedestrians_stand_on_sidewalks_or_crossings_never_in_a_lane():
    sample = _street()
    road = road_polygon_global()
    crossing = sample.ped_crossings_global[0]
    zones = set()
    for r in _place_many(sample, "pedestrian", 10):
        for p in r.placements:
            zones.add(p.zone)
            hull = shapely.convex_hull(shapely.multipoints(p.box.corners()[:, :2]))
            if hull.intersects(road):  # on the road only on the crossing
                assert p.zone == "crossing" and crossing.buffer(0.31).contains(hull)
            else:
                assert p.zone == "sidewalk"
            assert p.attribute is None  # an ObjectBox has no pose: no attribute invented
    assert zones == {"sidewalk", "crossing"}


def test_small_objects_stand_on_the_ground_under_them_not_float_or_sink():
    """A pedestrian on the raised sidewalk stands 15 cm up; cones at the road's edge on the road or the kerb top."""
    sample = _street(crossing=False)
    T_ego_from_global = np.linalg.inv(T_GLOBAL_FROM_EGO)
    n = 0
    for cls in ("pedestrian", "traffic_cone"):
        for r in _place_many(sample, cls, 6):
            for p in r.placements:
                bottom_ego = transform_points(T_ego_from_global, p.T_global_from_object[:3, 3][None])[0]
                under = SIDEWALK_HEIGHT_M if abs(bottom_ego[1]) > ROAD_HALF_WIDTH_M else 0.0
                assert abs(bottom_ego[2] - under) < 0.04 or (
                    cls == "traffic_cone" and -0.01 < bottom_ego[2] < SIDEWALK_HEIGHT_M + 0.01), (cls, bottom_ego)
                n += 1
    assert n >= 8


def test_cones_come_in_lines_along_the_road_edge():
    sample = _street(crossing=False)
    zones = surface_zones(sample, sample.cameras["CAM_FRONT"], *_drivable(sample))
    lines = 0
    for r in _place_many(sample, "traffic_cone", 8):
        if not r.placements:
            continue
        leader, members = r.placements[0], r.placements[1:]
        assert leader.zone in ("road_edge", "kerb") and all(m.cluster_of == 0 for m in members)
        assert len({p.asset_index for p in r.placements}) == 1  # one cone, repeated
        for m in members:
            s = float(zones.signed_distance(m.box.center[None, :2])[0])
            assert ROAD_EDGE_BAND_M[0] - 1e-6 <= s <= ROAD_EDGE_BAND_M[1] + CLUSTER_TAPER_M + 1e-6 or m.zone == "kerb"
        centres = np.array([p.box.center[:2] for p in r.placements])
        if len(centres) > 1:  # apart, not stacked
            d = np.linalg.norm(centres[:, None] - centres[None], axis=2) + 1e3 * np.eye(len(centres))
            assert d.min() > 0.4
        assert all(a.ok for a in audit_placements(sample, sample.cameras["CAM_FRONT"], r.placements, r.drivable,
                                                  r.config))
        lines += len(members) >= 2
    assert lines >= 3


def _drivable(sample):
    from streetaug.placement.config import PlacementConfig
    from streetaug.placement.drivable import drivable_area_for_sample

    area, _ = drivable_area_for_sample(sample, sample.cameras["CAM_FRONT"], PlacementConfig())
    return area, PlacementConfig()


def test_a_bus_needs_a_wide_lane_a_car_does_not(tmp_path):
    """On a 3.8 m road a car finds a place in the lane; a bus (2.9 m wide, 0.5 m lane margin) does not."""
    path = tmp_path / "lanes_only.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1",
                                "classes": {"car": {"zones": {"lane": 1}}, "bus": {"zones": {"lane": 1}}}}))
    rules = read_class_rules(path)
    w = 1.9
    narrow = shapely.Polygon(ego_to_global_xy([[-20, -w], [90, -w], [90, w], [-20, w]]))
    x, y = np.meshgrid(np.arange(-10.0, 60.0, 0.5), np.arange(-6.0, 6.0, 0.5))
    sample = make_sample(polygons=[narrow], lidar=lidar_sweep(np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]))
    view = sample.cameras["CAM_FRONT"]
    car = place_objects(sample, view, [_box("car")], np.random.default_rng(0), class_rules=rules)
    bus = place_objects(sample, view, [_box("bus")], np.random.default_rng(0), class_rules=rules)
    assert car.placements and not bus.placements
    assert "bus" in bus.class_reasons and "surface" in bus.reason
    lines = class_rule_lines(bus)
    assert any(line.startswith("bus/lane: surface") for line in lines)
    assert any(line.startswith("not placed: bus") for line in lines)


def test_off_road_zones_need_a_real_road_edge():
    """With only the LiDAR-ground corridor (no map, no lidarseg) there is no kerb to stand beside."""
    sample = _street(crossing=False)
    import dataclasses

    bare = dataclasses.replace(sample, drivable_area_global=None).with_lidar(sample.lidar)
    r = place_objects(bare, bare.cameras["CAM_FRONT"], [_box("pedestrian")], np.random.default_rng(0))
    assert not r.placements and "no real road edge" in r.class_reasons["pedestrian"]


# ---------------------------------------------------------------------------------------------- the mix


def test_class_weights_change_the_mix_as_asked():
    mix = ClassMix.parse("car,construction_vehicle", "construction_vehicle=4")
    names = mix.draw(np.random.default_rng(0), 5000)
    share = names.count("construction_vehicle") / len(names)
    assert abs(share - 0.8) < 0.02
    even = ClassMix.parse("car,construction_vehicle", None).draw(np.random.default_rng(0), 5000)
    assert abs(even.count("construction_vehicle") / 5000 - 0.5) < 0.03
    assert ClassMix.parse(None, None) is None
    assert ClassMix.parse(None, "bus=2").classes == DETECTION_CLASSES


@pytest.mark.parametrize("classes, weights, message", [
    ("car,pedestriann", None, "unknown class 'pedestriann'; valid classes: car, truck, bus"),
    ("car,bus", "1", "expected one weight per class"),
    ("car,bus", "1,-1", "non-negative"),
    ("car", "bus=2", "not among --classes"),
    ("car,car", None, "listed twice"),
])
def test_bad_class_options_give_clear_errors(classes, weights, message):
    with pytest.raises(InputError, match=message):
        ClassMix.parse(classes, weights)


def test_cli_refuses_an_unknown_class_listing_the_valid_ones(tmp_path):
    from streetaug.cli.main import main

    result = CliRunner().invoke(main, ["insert", "--scene", "sample-sunny", "--classes", "car,lorry",
                                       "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "unknown class 'lorry'" in result.output and "traffic_cone, barrier" in result.output


def test_a_small_object_stands_on_the_lowest_surface_it_sees_and_not_on_an_unseen_far_plane():
    from streetaug.placement.candidates import support_plane
    from streetaug.placement.ground import GroundPlane

    fp = np.array([[0.2, 0.2], [0.2, -0.2], [-0.2, -0.2], [-0.2, 0.2]])
    up = np.array([0.0, 0.0, 1.0])
    on_wall = GroundPlane(np.array([0.0, 0.0, 1.2]), up, "lidar-plane", 30)
    xy = np.random.default_rng(0).uniform(-0.5, 0.5, (40, 2))
    ground_and_wall = np.concatenate([np.c_[xy, np.full(40, 0.02)], np.c_[xy[:10], np.full(10, 1.2)]])
    assert abs(support_plane(on_wall, ground_and_wall, fp).point_global[2] - 0.02) < 1e-9  # drops to the road
    kerb = np.c_[xy, np.full(40, 0.15)]
    road = GroundPlane(np.zeros(3), up, "lidar-plane", 30)
    lifted = support_plane(road, kerb, fp)
    assert abs(lifted.point_global[2] - 0.15) < 1e-9 and lifted.n_points >= 30  # onto the kerb top, seen
    ego = GroundPlane(np.zeros(3), up, "ego-plane", 0)
    far = GroundPlane(np.array([0.0, 0.0, 2.5]), up, "lidar-plane", 12)
    assert support_plane(far, np.zeros((0, 3)), fp, ego).source == "ego-plane"  # unseen and far off the road
    near = GroundPlane(np.array([0.0, 0.0, 0.1]), up, "lidar-plane", 12)
    kept = support_plane(near, np.zeros((0, 3)), fp, ego)
    assert kept.source == "lidar-plane" and kept.n_points == 0  # unseen: kept, but marked as such


def test_a_map_walkway_is_where_pedestrians_go_when_the_map_has_one():
    """With a walkway polygon only on the left side, every pedestrian stands inside it (not the band)."""
    import dataclasses

    sample = _street(crossing=False)
    walk = shapely.Polygon(ego_to_global_xy([[-20, 5.6], [90, 5.6], [90, 8.5], [-20, 8.5]]))
    sample = dataclasses.replace(sample, walkways_global=(walk,)).with_lidar(sample.lidar)
    n = 0
    for r in _place_many(sample, "pedestrian", 6):
        for p in r.placements:
            assert p.zone == "sidewalk" and walk.contains(shapely.convex_hull(shapely.multipoints(p.box.corners()[:, :2])))
            n += 1
    assert n >= 3
