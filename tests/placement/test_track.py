"""Tracks through a scene (placement/track.py, ego_path.py): geometry, and plans on the real dev scene.

The real dev scene is ``../shared/data/nuscenes-seq`` (scene-0916, 41 keyframes, Singapore: traffic keeps
left); tests that need it skip without it.
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from streetaug.augment.core import InputError
from streetaug.placement.ego_path import EgoPath, traffic_side
from streetaug.placement.place import ObjectBox
from streetaug.placement.rules import box_footprint_rect
from streetaug.placement.height_drift import height_drift_m, static_bottoms
from streetaug.placement.track import (Track, TrackConfig, ego_footprint, interpolate_poses, plan_tracks, speed_range,
                                       swept_ego_footprints, track_frames)

from conftest import SHARED_DATA

SEQ = SHARED_DATA / "nuscenes-seq"
needs_seq = pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file(),
                               reason=f"{SEQ} (real nuScenes scene-0916) not present")
CAR = ObjectBox(np.array([1.9, 4.6, 1.6]))


def test_path_locate_inverts_point_at_on_a_curve():
    theta = np.linspace(0, np.pi / 2, 12)
    path = EgoPath.from_points(np.stack([30 * np.sin(theta), 30 - 30 * np.cos(theta)], axis=1))  # left turn, r=30
    s = np.array([3.0, 10.0, 25.0, 40.0])
    d = np.array([3.5, -3.5, 0.0, 6.0])
    xy, heading = path.point_at(s, d)
    back = path.locate(xy)
    # 12 vertices: the nearest point of the polyline and the smooth offset agree to ~0.2 m along, 0.05 m across
    assert np.allclose(back.s, s, atol=0.3) and np.allclose(back.d, d, atol=0.05)
    # a left turn: the heading grows smoothly (no step at the vertices) from 0 towards pi/2
    h = path.heading_at(np.linspace(0, path.length_m, 400))
    assert h[0] == pytest.approx(0.0, abs=0.08) and h[-1] == pytest.approx(np.pi / 2, abs=0.08)
    assert np.all(np.diff(h) >= -1e-9) and np.max(np.diff(h)) < 0.02


def test_path_continues_straight_beyond_its_ends_and_needs_motion():
    path = EgoPath.from_points(np.array([[0.0, 0.0], [10.0, 0.0]]))
    xy, heading = path.point_at(np.array([-5.0, 15.0]), np.array([2.0, -1.0]))
    assert np.allclose(xy, [[-5.0, 2.0], [15.0, -1.0]]) and np.allclose(heading, 0.0)
    with pytest.raises(InputError, match="does not move"):
        EgoPath.from_points(np.zeros((5, 2)))


def test_traffic_side_by_location():
    assert traffic_side("singapore-queenstown") == "left"
    assert traffic_side("boston-seaport") == "right"
    assert traffic_side("las-vegas-strip") is None


def test_speed_range_uses_the_most_specific_category():
    assert speed_range("human.pedestrian.adult") == (0.8, 1.8)
    assert speed_range("vehicle.bus.rigid") == speed_range("vehicle.bus")
    assert speed_range("vehicle.emergency.police") == speed_range("vehicle")


def test_interpolated_pose_lies_between_keyframes():
    T = np.tile(np.eye(4), (2, 1, 1))
    T[1, :3, 3] = [10.0, 0.0, 0.0]
    c, s = np.cos(0.4), np.sin(0.4)
    T[1, :2, :2] = [[c, -s], [s, c]]
    mid = interpolate_poses(T, np.array([0, 100]), np.array([50, 200]))
    assert np.allclose(mid[0, :3, 3], [5.0, 0.0, 0.0])
    assert np.arctan2(mid[0, 1, 0], mid[0, 0, 0]) == pytest.approx(0.2)
    assert np.allclose(mid[1], T[1])  # clamped beyond the last keyframe


def test_ego_footprint_is_the_data_vehicle_around_the_rear_axle():
    fp = ego_footprint(np.eye(4))
    assert fp[:, 0].min() == pytest.approx(-0.9) and fp[:, 0].max() == pytest.approx(3.2)
    assert shapely.Polygon(fp).area == pytest.approx(4.1 * 1.8)


def test_track_json_round_trip():
    T = np.tile(np.eye(4), (2, 1, 1))
    T[1, 0, 3] = 2.5
    track = Track(3, "vehicle.car", np.array([1.9, 4.6, 1.6]), "moving", 5.0, "ego path", "traffic keeps left",
                  ("a", "b"), np.array([0, 500000]), T, np.array([[5.0, 0, 0], [5.0, 0, 0]]), ("ego-plane",) * 2)
    back = Track.from_json(track.to_json())
    assert back.sample_tokens == ("a", "b") and np.allclose(back.T_global_from_object, T)
    assert back.attribute == "vehicle.moving" and np.allclose(back.pose_at(250000)[:3, 3], [1.25, 0, 0])
    assert back.box_at(1).center[2] == pytest.approx(0.8)


@pytest.fixture(scope="module")
def seq_frames():
    if not (SEQ / "v1.0-mini" / "sample.json").is_file():
        pytest.skip(f"{SEQ} (real nuScenes scene-0916) not present")
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(SEQ, "v1.0-mini")
    samples = [reader.sample(t) for t in reader.sample_tokens()]
    return samples, track_frames(samples)


@pytest.fixture(scope="module")
def seq_plan(seq_frames):
    samples, frames = seq_frames
    return plan_tracks(frames, [CAR] * 4, np.random.default_rng(7), TrackConfig(), samples[0].location)


@needs_seq
def test_real_scene_plans_parked_and_moving_tracks(seq_plan):
    assert len(seq_plan.tracks) >= 3, seq_plan.reason
    motions = {t.motion for t in seq_plan.tracks}
    assert motions == {"parked", "moving"}, motions
    assert seq_plan.traffic_side == "traffic keeps left (location)"
    for t in seq_plan.tracks:
        assert len(t.sample_tokens) == len(t.T_global_from_object) == len(t.velocity_global) >= 2
        assert np.all(np.diff(t.timestamps_us) > 0)


@needs_seq
def test_parked_track_stays_put_and_follows_the_frames_height_drift(seq_frames, seq_plan):
    """x, y and rotation are the same in every keyframe; the height follows the global frame's drift at its
    place (nuScenes' ego z is 0 in every keyframe), measured by the scene's static annotated objects."""
    samples, _ = seq_frames
    parked = [t for t in seq_plan.tracks if t.motion == "parked"]
    assert parked
    static_m = static_bottoms(samples)
    index = {s.token: k for k, s in enumerate(samples)}
    for t in parked:
        T = t.T_global_from_object
        assert np.array_equal(T[:, :3, :3], np.repeat(T[:1, :3, :3], len(T), 0))
        assert np.array_equal(T[:, :2, 3], np.repeat(T[:1, :2, 3], len(T), 0))
        assert np.all(t.velocity_global == 0) and t.attribute == "vehicle.parked"
        k = np.array([index[tok] for tok in t.sample_tokens])
        drift = height_drift_m(static_m, T[0, :2, 3], int(k[0]))[k]
        np.testing.assert_allclose(T[:, 2, 3] - T[0, 2, 3], drift, atol=1e-9)
    # the scene climbs: somewhere along the scene a parked track's height changes
    assert max(np.ptp(t.T_global_from_object[:, 2, 3]) for t in parked) > 0.1


@needs_seq
def test_moving_track_velocity_matches_its_motion(seq_plan):
    moving = [t for t in seq_plan.tracks if t.motion == "moving"]
    assert moving
    for t in moving:
        dt = np.diff(t.timestamps_us) * 1e-6
        finite = np.diff(t.T_global_from_object[:, :2, 3], axis=0) / dt[:, None]
        mean_v = 0.5 * (t.velocity_global[1:, :2] + t.velocity_global[:-1, :2])
        assert np.max(np.linalg.norm(finite - mean_v, axis=1)) < 0.3
        speed = np.linalg.norm(t.velocity_global[:, :2], axis=1)
        lo, hi = speed_range(t.category)
        assert np.all(speed < 1.5 * hi)
        # heading along the velocity (forward, not sideways), where it moves
        heading = t.T_global_from_object[:, :2, 0]
        assert np.all(np.einsum("kd,kd->k", heading, t.velocity_global[:, :2]) >= 0.9 * speed)
        stopped = [t.attribute_at(i) == "vehicle.stopped" for i in range(len(speed))]
        assert stopped == list(speed < 0.5)


@needs_seq
def test_tracks_never_overlap_annotated_boxes_the_ego_or_each_other(seq_frames, seq_plan):
    samples, frames = seq_frames
    by_token = {s.token: s for s in samples}
    swept = [shapely.Polygon(fp) for fp in swept_ego_footprints(frames)]
    clearance = TrackConfig().placement.dynamic_clearance_m
    for t in seq_plan.tracks:
        for i, token in enumerate(t.sample_tokens):
            mine = shapely.Polygon(box_footprint_rect(t.T_global_from_object[i][None], t.wlh)[0])
            for box in by_token[token].boxes:
                assert mine.distance(shapely.Polygon(box.corners()[[0, 1, 5, 4], :2])) >= min(clearance, 1.0) - 1e-6
            if t.motion == "parked":
                assert min(mine.distance(e) for e in swept) >= TrackConfig().ego_clearance_m - 1e-6
            for other in seq_plan.tracks:
                j = other.index_of(token)
                if other is t or j is None:
                    continue
                theirs = shapely.Polygon(box_footprint_rect(other.T_global_from_object[j][None], other.wlh)[0])
                assert mine.distance(theirs) >= TrackConfig().placement.mutual_clearance_m - 1e-6


@needs_seq
def test_plan_is_deterministic_per_seed(seq_frames, seq_plan):
    samples, frames = seq_frames
    again = plan_tracks(frames, [CAR] * 4, np.random.default_rng(7), TrackConfig(), samples[0].location)
    assert [t.to_json() for t in again.tracks] == [t.to_json() for t in seq_plan.tracks]


@needs_seq
def test_tracks_stand_on_the_lidar_ground_not_on_roofs_or_canopies(seq_frames, seq_plan):
    """At the keyframe where the ego is closest, the track's bottom is within 0.3 m of the lowest LiDAR returns
    (10th percentile) within 2 m of its centre: the road, not a canopy, a wall or car roofs."""
    samples, _ = seq_frames
    by_token = {s.token: s for s in samples}
    checked = 0
    for t in seq_plan.tracks:
        dist = [np.linalg.norm(by_token[s].cameras["CAM_FRONT"].T_global_from_ego[:2, 3] - t.T_global_from_object[i, :2, 3])
                for i, s in enumerate(t.sample_tokens)]
        i = int(np.argmin(dist))
        points = by_token[t.sample_tokens[i]].lidar.points_global
        xy = t.T_global_from_object[i, :2, 3]
        near = points[np.linalg.norm(points[:, :2] - xy, axis=1) < 2.0]
        if len(near) < 10:
            continue
        assert abs(t.T_global_from_object[i, 2, 3] - np.percentile(near[:, 2], 10)) < 0.3, (t.track_index, t.motion)
        checked += 1
    assert checked >= 2


@needs_seq
def test_other_classes_stand_still_in_their_zone_through_the_span(seq_frames):
    """A cone and a pedestrian become still tracks: the zone of their class rule at every keyframe (the road's
    edge or the kerb; the sidewalk), no vehicle attribute, never moving."""
    from streetaug.placement.class_rules import read_class_rules

    samples, frames = seq_frames
    cone = ObjectBox(np.array([0.41, 0.38, 0.74]), "movable_object.trafficcone")
    person = ObjectBox(np.array([0.7, 0.7, 1.75]), "human.pedestrian.adult")
    plan = plan_tracks(frames, [cone, person, cone], np.random.default_rng(3), TrackConfig(), samples[0].location)
    assert plan.tracks, plan.reason
    rules = read_class_rules()
    by_token = {f.token: f for f in frames}
    static_m, index = static_bottoms(samples), {s.token: k for k, s in enumerate(samples)}
    for t in plan.tracks:
        rule = rules.for_category(t.category)
        assert t.motion == "parked" and t.zone in rule.zones and t.attribute is None
        assert t.detection_class == rule.name
        T = t.T_global_from_object
        assert np.allclose(T[:, :3, :3], T[0, :3, :3]) and np.allclose(T[:, :2, 3], T[0, :2, 3])  # still
        k = np.array([index[tok] for tok in t.sample_tokens])  # its height follows the keyframes' drift
        np.testing.assert_allclose(T[:, 2, 3] - T[0, 2, 3], height_drift_m(static_m, T[0, :2, 3], int(k[0]))[k],
                                   atol=1e-9)
        for i, token in enumerate(t.sample_tokens):
            fp = box_footprint_rect(t.T_global_from_object[i][None], t.wlh)
            assert by_token[token].scene().zones.footprints_in(t.zone, fp, rule)[0]
        assert Track.from_json(t.to_json()).to_json() == t.to_json()
