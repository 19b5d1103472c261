"""Tracks: inserted objects that live through a scene's keyframes, parked or moving along a lane.

A :class:`Track` is one inserted instance with a pose at every keyframe of its span (global frame). Planning
(:func:`plan_tracks`) draws, per object, an anchor keyframe and camera, samples candidates in that camera's
view at 10-40 m (as single-image placement does, :mod:`.candidates`), turns each into a trajectory, and keeps
the first whose every rule holds at EVERY keyframe of its span:

* ``parked``: static in the global frame, by the kerb (footprint within ``kerb_distance_m`` of the edge of the
  drivable area), heading along the lane: the map lane's direction where the map has lanes, else the direction
  of traffic for that side of the road (the ego's path; Singapore keeps left, Boston right; elsewhere the side
  the annotated moving vehicles show). Stood on the median of the ground planes its keyframes' LiDAR fit.
* ``moving``: along the ego's path shifted sideways by the candidate's offset (a lane beside the ego's, never
  the ego's own: the ego's swept path is kept clear), at a speed drawn per category, in the direction of
  traffic of that lane (map lanes; else the annotated moving vehicles near that offset; else the traffic side),
  heading = the path's smooth tangent; stood at each keyframe on that keyframe's ground (heights median-filtered).

A track's span is the run of keyframes around the anchor in which it lies within ``annotate_range_m`` of the
ego (nuScenes annotates what is near), pushed on at both ends while a camera still has it in view (up to
``max_visible_range_m``): it never pops in or out of view inside the scene. In every frame of the span the rules are: drivable footprint, clearance
to every annotated box of that keyframe, to the ego's swept path (its footprint at every keyframe and between
them) and to the other tracks at that keyframe, no unannotated LiDAR obstacle nor non-drivable lidarseg point
in the footprint; at the anchor, the object is in the camera's view and visible (the single-image rules), and cut
by that camera's frame with the single-image ``truncated_share`` (each track draws which; :func:`anchor_truncated`).
Annotated boxes are checked at keyframes only: at urban speeds two boxes cannot pass through each other
within one 0.5 s interval without violating the clearance at a keyframe (that needs > 15 m of relative motion).

Everything is deterministic for a given ``rng``; each object's draws come in a fixed order.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.ndimage import median_filter
from scipy.spatial.transform import Rotation, Slerp

from streetaug.augment.core import InputError, PinholeCamera, rotation_to_quat
from streetaug.datasets.nuscenes_format import VEHICLE_MOVING, VEHICLE_PARKED, VEHICLE_STOPPED
from streetaug.datasets.sample import Box, Sample

from .candidates import object_transforms, sample_candidates
from .class_rules import ClassRule, ClassRules, read_class_rules
from .config import PlacementConfig
from .drivable import DrivableArea, drivable_area_for_sample
from .ego_path import EgoPath, PathCoords, traffic_side
from .height_drift import height_drift_m, static_bottoms
from .place import FULL_VIEW_FRACTION, OFF_ROAD_ZONES, Placeable, Placement, check_objects, zone_order
from .rules import (box_corners_object, box_footprint_rect, footprint_corners, occlusion_tolerance_for,
                    projected_inside_fraction, rule_box_clearance, rule_drivable, rule_in_view, rule_lidarseg, rule_mutual, rule_obstacles,
                    visible_fraction_estimate)
from .scene import PlacementScene

# The nuScenes data vehicle (Renault Zoe, 4.08 x 1.73 m) around its ego origin (rear axle, on the ground).
EGO_X_RANGE_M = (-0.9, 3.2)
EGO_HALF_WIDTH_M = 0.9

# Plausible urban speeds (m/s) per category prefix; the longest matching prefix wins.
SPEED_RANGE_MPS = {
    "vehicle": (3.0, 10.0),
    "vehicle.car": (3.0, 11.0),
    "vehicle.truck": (3.0, 9.0),
    "vehicle.bus": (3.0, 8.0),
    "vehicle.trailer": (3.0, 8.0),
    "vehicle.construction": (1.0, 4.0),
    "vehicle.motorcycle": (3.0, 11.0),
    "vehicle.bicycle": (2.0, 6.0),
    "human.pedestrian": (0.8, 1.8),
}

TRACK_RULES = ("lane_offset", "span", "surface", "annotated_boxes", "ego_path", "mutual_collision", "kerb", "lidar_obstacles",
               "lidarseg", "in_view")
SWEPT_PATH_STEPS = 4  # ego footprints per keyframe interval in the swept path
MAX_LATERAL_ACCEL_MPS2 = 2.0  # comfortable cornering: a moving track slows down to this in curves
LANE_WIDTH_M = 3.3  # moving candidates: lane centres at multiples of this from the ego's path ...
LANE_JITTER_M = 0.3  # ... give or take this (std)
STOPPED_BELOW_MPS = 0.5  # a moving track slower than this at a keyframe is labelled vehicle.stopped there
TRUNCATION_EXTRA_ATTEMPTS = 2  # attempts after the first passing track of the other kind, seeking the drawn kind
CHUNK = 48  # candidates past the flat rules that are stood on the ground per attempt (the first passing wins)


def speed_range(category: str) -> tuple[float, float]:
    """(min, max) speed in m/s of a moving object of ``category`` (:data:`SPEED_RANGE_MPS`)."""
    best = max((k for k in SPEED_RANGE_MPS if category == k or category.startswith(k + ".")), key=len,
               default="vehicle")
    return SPEED_RANGE_MPS[best]


@dataclass(frozen=True)
class TrackConfig:
    """What shapes tracks (metres, seconds, probabilities).

    Attributes:
        placement: the single-image rules and thresholds (distances, clearances, visibility, ground); for
            tracks the clearance to annotated moving things (and the ego) is 2 m: traffic passes that close.
        moving_probability: probability that an object is a moving track (else parked).
        annotate_range_m: a track is annotated at the keyframes where it is this close to the ego (the nuScenes
            detection range of cars) ...
        max_visible_range_m: ... and beyond, up to this distance, for as long as a camera still has it in view
            (so it never appears or vanishes in view).
        min_lane_offset_m, max_lane_offset_m: a moving track's lateral offset from the ego's path.
        ego_clearance_m: footprint clearance to the ego's swept path.
        direction_band_m: annotated moving vehicles within this lateral distance of a track's offset vote for
            its direction of travel.
        attempts: anchor keyframes (each with ``placement.n_candidates`` candidates) tried per object.
    """

    placement: PlacementConfig = PlacementConfig(dynamic_clearance_m=2.0)
    moving_probability: float = 0.5
    annotate_range_m: float = 50.0
    max_visible_range_m: float = 100.0
    min_lane_offset_m: float = 2.5
    max_lane_offset_m: float = 12.0
    ego_clearance_m: float = 0.5
    direction_band_m: float = 1.75
    attempts: int = 10

    def __post_init__(self) -> None:
        if not 0.0 <= self.moving_probability <= 1.0:
            raise InputError(f"TrackConfig.moving_probability must be in [0, 1], got {self.moving_probability}")
        if not 0 < self.min_lane_offset_m < self.max_lane_offset_m:
            raise InputError("TrackConfig: need 0 < min_lane_offset_m < max_lane_offset_m, got "
                             f"{self.min_lane_offset_m}, {self.max_lane_offset_m}")
        if self.attempts < 1 or self.annotate_range_m <= 0:
            raise InputError("TrackConfig: attempts must be >= 1 and annotate_range_m > 0")


def ego_footprint(T_global_from_ego: np.ndarray) -> np.ndarray:
    """(4, 2) the ego vehicle's footprint (global x/y) at pose ``T_global_from_ego`` (4, 4)."""
    x0, x1 = EGO_X_RANGE_M
    w = EGO_HALF_WIDTH_M
    local = np.array([[x1, w, 0, 1], [x0, w, 0, 1], [x0, -w, 0, 1], [x1, -w, 0, 1]], dtype=np.float64)
    return (local @ np.asarray(T_global_from_ego).T)[:, :2]


def interpolate_poses(T: np.ndarray, t_us: np.ndarray, query_us: np.ndarray) -> np.ndarray:
    """(Q, 4, 4) poses at ``query_us`` (Q,) from poses ``T`` (K, 4, 4) at increasing times ``t_us`` (K,).

    Translation linear, rotation slerp; clamped to the first/last pose outside [t_0, t_K-1].
    """
    T = np.asarray(T, dtype=np.float64).reshape(-1, 4, 4)
    t = np.asarray(t_us, dtype=np.float64)
    q = np.clip(np.asarray(query_us, dtype=np.float64).reshape(-1), t[0], t[-1])
    out = np.tile(np.eye(4), (len(q), 1, 1))
    if len(T) == 1:
        out[:] = T[0]
        return out
    out[:, :3, :3] = Slerp(t, Rotation.from_matrix(T[:, :3, :3]))(q).as_matrix()
    for axis in range(3):
        out[:, axis, 3] = np.interp(q, t, T[:, axis, 3])
    return out


@dataclass(frozen=True)
class Track:
    """One inserted instance through time (global frame).

    Attributes:
        track_index: its index among the scene's tracks (part of its instance token).
        category: nuScenes category name.
        wlh: (3,) float64 width, length, height in metres.
        motion: ``"parked"`` or ``"moving"``.
        speed_mps: speed along its lane (0 when parked).
        lane_source: where its heading/lane came from: ``"map lanes"`` or ``"ego path"``.
        direction_source: where its direction of travel came from: ``"map lanes"``, ``"annotated moving
            vehicles (n)"`` or ``"traffic keeps left"``/``"traffic keeps right"``.
        sample_tokens: (K,) the keyframes of its span, in time order (one annotation each).
        timestamps_us: (K,) int64 their timestamps.
        T_global_from_object: (K, 4, 4) object frame (x front, y left, z up, origin bottom centre) -> global.
        velocity_global: (K, 3) float64 the trajectory's velocity (m/s) at each keyframe.
        ground_source: (K,) the ground each pose stands on (``"lidar-plane"``, ``"lidarseg"``, ``"boxes"``, ``"ego-plane"``).
        drivable_source, drivable_confidence: the drivable area's source at the anchor keyframe.
        anchor_sample_token, anchor_camera: where it was sampled (it is in that camera's view there).
        detection_class, zone: the class whose rule placed it and the surface it stands on.
        fixed_attribute: ``""`` for vehicles (``vehicle.parked`` / ``moving`` / ``stopped`` from the motion);
            otherwise the attribute of every annotation (the asset's: ``pedestrian.standing``,
            ``cycle.without_rider``), or None (cones and barriers have none).
    """

    track_index: int
    category: str
    wlh: np.ndarray
    motion: str
    speed_mps: float
    lane_source: str
    direction_source: str
    sample_tokens: tuple[str, ...]
    timestamps_us: np.ndarray
    T_global_from_object: np.ndarray
    velocity_global: np.ndarray
    ground_source: tuple[str, ...]
    drivable_source: str = ""
    drivable_confidence: str = ""
    anchor_sample_token: str = ""
    anchor_camera: str = ""
    detection_class: str = "car"
    zone: str = ""
    fixed_attribute: str | None = ""

    @property
    def attribute(self) -> str | None:
        """The track's attribute while it moves (``vehicle.parked`` / ``vehicle.moving``; see ``fixed_attribute``)."""
        if self.fixed_attribute != "":
            return self.fixed_attribute
        return VEHICLE_PARKED if self.motion == "parked" else VEHICLE_MOVING

    def attribute_at(self, i: int) -> str:
        """The attribute of its annotation at span position ``i``: a moving track that stands still there (in
        the ego's lane, stopping with the ego) is ``vehicle.stopped``, as nuScenes labels waiting traffic."""
        if self.motion == "moving" and np.linalg.norm(self.velocity_global[i, :2]) < STOPPED_BELOW_MPS:
            return VEHICLE_STOPPED
        return self.attribute

    def index_of(self, sample_token: str) -> int | None:
        """Position of ``sample_token`` in the span (None when the track is not annotated there)."""
        try:
            return self.sample_tokens.index(sample_token)
        except ValueError:
            return None

    def box_at(self, i: int) -> Box:
        """The nuScenes box at span position ``i`` (centre = bottom centre + h/2 along the object's up)."""
        return self._box(self.T_global_from_object[i])

    def pose_at(self, timestamp_us: int | float) -> np.ndarray:
        """(4, 4) T_global_from_object at any time within the span (interpolated; clamped at its ends)."""
        return interpolate_poses(self.T_global_from_object, self.timestamps_us, np.array([timestamp_us]))[0]

    def placement_at(self, sample_token: str, asset_index: int, camera_xy: np.ndarray | None = None) -> Placement:
        """The :class:`Placement` (for rendering) of this track at keyframe ``sample_token``."""
        i = self.index_of(sample_token)
        if i is None:
            raise InputError(f"track {self.track_index}: not annotated at sample {sample_token}")
        return self._placement(self.T_global_from_object[i].copy(), i, asset_index, camera_xy)

    def placement_at_time(self, timestamp_us: int, asset_index: int) -> Placement:
        """The :class:`Placement` at any time of the span (a sweep's): the pose interpolated between keyframes,
        the attribute and ground of the keyframe nearest in time."""
        i = int(np.argmin(np.abs(self.timestamps_us - timestamp_us)))
        return self._placement(self.pose_at(timestamp_us), i, asset_index)

    def _placement(self, T: np.ndarray, i: int, asset_index: int, camera_xy: np.ndarray | None = None) -> Placement:
        """The :class:`Placement` of pose ``T`` (4, 4) with the attribute and ground of span position ``i``."""
        box = self._box(T)
        distance = float("nan") if camera_xy is None else float(np.linalg.norm(box.center[:2] - camera_xy))
        return Placement(asset_index=asset_index, T_global_from_object=T, box=box, wlh=self.wlh.copy(),
                         ground_normal_global=T[:3, 2].copy(), ground_source=self.ground_source[i],
                         drivable_source=self.drivable_source, drivable_confidence=self.drivable_confidence,
                         attribute=self.attribute_at(i), distance_m=distance,
                         yaw_source="lane" if self.lane_source == "map lanes" else "ego",
                         footprint_xy=box_footprint_rect(T[None], self.wlh)[0], detection_class=self.detection_class,
                         zone=self.zone or ("lane" if self.motion == "moving" else "kerb"))

    def _box(self, T: np.ndarray) -> Box:
        center = T[:3, 3] + 0.5 * self.wlh[2] * T[:3, 2]
        return Box(center, self.wlh.copy(), rotation_to_quat(T[:3, :3]), self.category)

    def to_json(self) -> dict:
        return {"track_index": self.track_index, "category": self.category, "wlh": self.wlh.tolist(),
                "motion": self.motion, "attribute": self.attribute, "speed_mps": round(self.speed_mps, 6),
                "lane_source": self.lane_source, "direction_source": self.direction_source,
                "sample_tokens": list(self.sample_tokens), "timestamps_us": [int(t) for t in self.timestamps_us],
                "T_global_from_object": self.T_global_from_object.tolist(),
                "velocity_global": self.velocity_global.tolist(), "ground_source": list(self.ground_source),
                "drivable_source": self.drivable_source, "drivable_confidence": self.drivable_confidence,
                "anchor_sample_token": self.anchor_sample_token, "anchor_camera": self.anchor_camera,
                "detection_class": self.detection_class, "zone": self.zone, "fixed_attribute": self.fixed_attribute}

    @classmethod
    def from_json(cls, doc: dict) -> "Track":
        return cls(track_index=int(doc["track_index"]), category=doc["category"],
                   wlh=np.array(doc["wlh"], dtype=np.float64), motion=doc["motion"],
                   speed_mps=float(doc["speed_mps"]), lane_source=doc["lane_source"],
                   direction_source=doc["direction_source"], sample_tokens=tuple(doc["sample_tokens"]),
                   timestamps_us=np.array(doc["timestamps_us"], dtype=np.int64),
                   T_global_from_object=np.array(doc["T_global_from_object"], dtype=np.float64).reshape(-1, 4, 4),
                   velocity_global=np.array(doc["velocity_global"], dtype=np.float64).reshape(-1, 3),
                   ground_source=tuple(doc["ground_source"]), drivable_source=doc.get("drivable_source", ""),
                   drivable_confidence=doc.get("drivable_confidence", ""),
                   anchor_sample_token=doc.get("anchor_sample_token", ""),
                   anchor_camera=doc.get("anchor_camera", ""), detection_class=doc.get("detection_class", "car"),
                   zone=doc.get("zone", ""), fixed_attribute=doc.get("fixed_attribute", ""))


# ---------------------------------------------------------------------------------------------- the scene


@dataclass(eq=False)
class TrackFrame:
    """One keyframe as track planning reads it: its sample, ego pose, drivable area and rule inputs.

    The rule inputs (annotated boxes, LiDAR obstacles, ground fitter) come from a :class:`PlacementScene`
    of one of its cameras (the same for every camera but the depth); a camera's own scene (its depth, for
    the visibility at an anchor) is built on first use.
    """

    sample: Sample
    T_global_from_ego: np.ndarray
    drivable: DrivableArea | None
    drivable_reason: str | None
    config: PlacementConfig
    _scenes: dict[str, PlacementScene] = field(default_factory=dict)

    @property
    def token(self) -> str:
        return self.sample.token

    @property
    def timestamp_us(self) -> int:
        return self.sample.timestamp_us

    @property
    def channels(self) -> list[str]:
        return sorted(self.sample.cameras)

    def scene(self, channel: str | None = None) -> PlacementScene:
        """The placement scene of ``channel`` (default: the first camera)."""
        channel = channel or self.channels[0]
        if channel not in self._scenes:
            base = next(iter(self._scenes.values()), None)
            view = self.sample.cameras[channel]
            if base is None:
                self._scenes[channel] = PlacementScene.of(self.sample, view, self.config, self.drivable, None)
            else:  # the LiDAR-derived inputs are the camera's-independent: share them
                self._scenes[channel] = PlacementScene(self.sample, view, self.config, self.drivable,
                                                       base.box_footprints_xy, base.box_is_dynamic,
                                                       base.obstacle_points, base.non_drivable_xy, base.ground)
        return self._scenes[channel]


def track_frames(samples: Sequence[Sample], config: PlacementConfig = PlacementConfig()) -> list[TrackFrame]:
    """The keyframes of a scene (``samples`` in time order, each with at least one camera) for planning."""
    frames = []
    for sample in samples:
        if not sample.cameras:
            raise InputError(f"sample {sample.token}: has no camera; tracks need the cameras of every keyframe")
        view = sample.cameras[sorted(sample.cameras)[0]]
        drivable, reason = drivable_area_for_sample(sample, view, config)
        frames.append(TrackFrame(sample, np.asarray(view.T_global_from_ego, dtype=np.float64), drivable, reason,
                                 config))
    times = [f.timestamp_us for f in frames]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise InputError("track planning: the scene's samples must be in strictly increasing time order "
                         f"(timestamps {times[:5]}...)")
    return frames


def swept_ego_footprints(frames: Sequence[TrackFrame]) -> np.ndarray:
    """(F, 4, 2) the ego's footprint at every keyframe and ``SWEPT_PATH_STEPS`` times between consecutive ones."""
    T = np.array([f.T_global_from_ego for f in frames])
    t = np.array([f.timestamp_us for f in frames], dtype=np.float64)
    if len(T) > 1:
        q = np.concatenate([np.linspace(a, b, SWEPT_PATH_STEPS, endpoint=False) for a, b in zip(t[:-1], t[1:])]
                           + [t[-1:]])
        T = interpolate_poses(T, t, q)
    return np.array([ego_footprint(x) for x in T])


@dataclass(frozen=True)
class DirectionVotes:
    """Annotated moving vehicles located on the ego path: left offset ``d`` (N,), +1 along the path / -1 against."""

    d: np.ndarray
    sign: np.ndarray

    def direction_at(self, d: np.ndarray, band_m: float) -> tuple[np.ndarray, np.ndarray]:
        """(direction (N,) +1/-1/0 = no vote, n votes (N,)) of the lanes at offsets ``d`` (N,)."""
        d = np.asarray(d, dtype=np.float64)
        if len(self.d) == 0:
            return np.zeros(len(d)), np.zeros(len(d), dtype=np.int64)
        near = np.abs(d[:, None] - self.d[None]) < band_m
        total = (near * self.sign[None]).sum(axis=1)
        return np.sign(total), near.sum(axis=1)


def direction_votes(frames: Sequence[TrackFrame], path: EgoPath) -> DirectionVotes:
    """Where the annotated moving vehicles of the scene drive, relative to the ego's path."""
    boxes = [b for f in frames for b in f.sample.boxes
             if b.category.startswith("vehicle.") and "vehicle.moving" in b.attributes]
    if not boxes:
        return DirectionVotes(np.zeros(0), np.zeros(0))
    xy = np.array([b.center[:2] for b in boxes])
    yaw = np.array([np.arctan2(*(Rotation.from_quat(np.roll(b.rotation, -1)).as_matrix()[[1, 0], 0]))
                    for b in boxes])
    coords = path.locate(xy)
    c = np.cos(yaw - coords.heading_rad)
    keep = np.abs(c) > 0.7  # driving along the path or against it, not across
    return DirectionVotes(coords.d[keep], np.sign(c[keep]))


# ---------------------------------------------------------------------------------------------- planning


@dataclass(frozen=True)
class TrackPlan:
    """Tracks planned for a scene.

    Attributes:
        tracks: the planned tracks (possibly fewer than asked), ``track_index`` = their object's index.
        report: rule name -> candidates it rejected (keys :data:`TRACK_RULES`), summed over objects.
        reason: why fewer tracks than asked were planned (None when all were).
        traffic_side: ``"left"``/``"right"`` and where it came from (``"location"``, ``"annotated vehicles"``).
    """

    tracks: list[Track]
    report: dict[str, int]
    reason: str | None
    traffic_side: str = ""


def _contiguous_span(ok: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(C, K) bool: the maximal run of True in each row of ``ok`` (C, K) containing column ``k[c]``."""
    C, K = ok.shape
    idx = np.arange(K)[None]
    bad = ~ok
    left = np.where(bad & (idx < k[:, None]), idx, -1).max(axis=1)
    right = np.where(bad & (idx > k[:, None]), idx, K).min(axis=1)
    span = (idx > left[:, None]) & (idx < right[:, None])
    return span & ok[np.arange(C), k][:, None]


class _Tally:
    def __init__(self, report: dict[str, int]) -> None:
        self.report = report

    def keep(self, name: str, alive: np.ndarray, ok: np.ndarray) -> np.ndarray:
        ok = np.asarray(ok, dtype=bool)
        self.report[name] += int((~ok).sum())
        return alive[ok]


def _side_direction(d: np.ndarray, side: str) -> np.ndarray:
    """+1 (along the ego) / -1 (against) for lanes at left offsets ``d``: where traffic keeps ``side``, the
    lanes on the ego's far side carry the oncoming traffic."""
    along = d > 0 if side == "left" else d < 0
    return np.where(along, 1.0, -1.0)


def plan_tracks(
    frames: Sequence[TrackFrame],
    objects: Sequence[Placeable],
    rng: np.random.Generator,
    config: TrackConfig = TrackConfig(),
    location: str = "",
    class_rules: ClassRules | None = None,
) -> TrackPlan:
    """Plan one track per object through ``frames`` (a scene's keyframes, :func:`track_frames`).

    Draws per object, in order: parked or moving; then per attempt the anchor keyframe, the anchor camera,
    the candidates (:func:`sample_candidates`), their speeds and yaw noise.

    Vehicles (class rules whose ``attribute`` is ``vehicle``) park by the kerb or move along lanes; the other
    classes (``class_rules``, default the built-in table) stand still for the whole span in a zone of their
    rule, with its clearances (a cone at the road's edge, a standing pedestrian on the sidewalk); clusters are
    not formed in tracks.
    """
    check_objects(objects)
    report = {name: 0 for name in TRACK_RULES}
    if not frames:
        return TrackPlan([], report, "the scene has no keyframe")
    usable = [i for i, f in enumerate(frames) if f.drivable is not None]
    if not usable:
        return TrackPlan([], report, f"no drivable area at any keyframe ({frames[0].drivable_reason})")
    try:
        path = EgoPath.from_points(np.array([f.T_global_from_ego[:2, 3] for f in frames]))
    except InputError as e:
        return TrackPlan([], report, str(e))
    votes = direction_votes(frames, path)
    side = traffic_side(location)
    side_source = "location"
    if side is None:  # unknown city: the side the annotated traffic shows (oncoming on the ego's far side)
        left_votes = int(((votes.d < 0) & (votes.sign < 0)).sum() + ((votes.d > 0) & (votes.sign > 0)).sum())
        right_votes = int(((votes.d > 0) & (votes.sign < 0)).sum() + ((votes.d < 0) & (votes.sign > 0)).sum())
        side, side_source = ("left" if left_votes > right_votes else "right"), "annotated vehicles"
        if left_votes == right_votes:
            side_source = "default (no location rule, no annotated traffic)"
    swept = swept_ego_footprints(frames)
    static_m = static_bottoms([f.sample for f in frames])
    tracks: list[Track] = []
    rules = class_rules or read_class_rules()
    for index, obj in enumerate(objects):
        rule = rules.for_category(obj.category)
        moving = bool(rng.random() < config.moving_probability) and speed_range(obj.category)[1] > 0 \
            and rule.attribute == "vehicle"
        track = _plan_one(frames, usable, index, obj, moving, rng, config, path, votes, side, swept, static_m, tracks,
                          report, rule, still_in_zone=rule.attribute not in ("vehicle", "parked"))
        if track is not None:
            tracks.append(track)
    reason = None
    if len(tracks) < len(objects):
        worst = ", ".join(f"{k}: {v}" for k, v in report.items() if v)
        reason = (f"planned {len(tracks)} of {len(objects)} tracks: no candidate passed every rule at every "
                  f"keyframe of its span (rejected by {worst})")
    return TrackPlan(tracks, report, reason, f"traffic keeps {side} ({side_source})")


@dataclass(frozen=True)
class LaneMotion:
    """Where moving candidates are along their lane over time: ``s(t)`` on the ego path (offset ``d`` fixed).

    Candidates in the ego's own lane follow the ego's own speed profile ``tau`` seconds ahead (+) or behind
    (-): s(t) = s_ego(t + tau), as traffic in one lane does (time headway); the others drive at a constant
    signed speed: s(t) = s0 + v (t - t_anchor). ``s_ego`` is the ego's path position at each keyframe,
    continued beyond the scene at its end speeds.
    """

    s0: np.ndarray
    signed_speed: np.ndarray
    follows_ego: np.ndarray
    tau_s: np.ndarray
    t_anchor_s: float
    ego_t_s: np.ndarray
    ego_s: np.ndarray

    def _ego_s_at(self, t: np.ndarray) -> np.ndarray:
        t0, t1 = self.ego_t_s[0], self.ego_t_s[-1]
        v0 = (self.ego_s[1] - self.ego_s[0]) / max(self.ego_t_s[1] - t0, 1e-6) if len(self.ego_t_s) > 1 else 0.0
        v1 = (self.ego_s[-1] - self.ego_s[-2]) / max(t1 - self.ego_t_s[-2], 1e-6) if len(self.ego_t_s) > 1 else 0.0
        return np.interp(t, self.ego_t_s, self.ego_s) + np.minimum(t - t0, 0.0) * v0 + np.maximum(t - t1, 0.0) * v1

    def s_at(self, t: np.ndarray | float, idx: np.ndarray | slice = slice(None)) -> np.ndarray:
        """s of candidates ``idx`` at times ``t`` (seconds; broadcast against the candidates)."""
        t = np.asarray(t, dtype=np.float64)
        linear = self.s0[idx] + self.signed_speed[idx] * (t - self.t_anchor_s)
        follow = self._ego_s_at(t + self.tau_s[idx])
        return np.where(self.follows_ego[idx], follow, linear)

    def heading_sign(self, idx: np.ndarray | slice = slice(None)) -> np.ndarray:
        """+1 driving along the path, -1 against it."""
        return np.where(self.follows_ego[idx] | (self.signed_speed[idx] >= 0), 1.0, -1.0)


def _plan_one(frames, usable, index, obj, moving, rng, config: TrackConfig, path: EgoPath, votes: DirectionVotes,
              side: str, swept: np.ndarray, static_m: np.ndarray, placed: list[Track], report: dict[str, int],
              class_rule: ClassRule, still_in_zone: bool) -> Track | None:
    """One track of ``obj`` (of ``class_rule``'s class): a vehicle by the kerb or in a lane, or with
    ``still_in_zone`` a still object in one of the rule's zones, with its thresholds. ``static_m``: the scene's
    static annotated objects (:func:`~.height_drift.static_bottoms`)."""
    rule = class_rule if still_in_zone else None  # the zone-rule path below; vehicles keep the kerb and lanes
    if rule is not None:
        config = dataclasses.replace(config, placement=rule.config(config.placement))
    pc = config.placement
    wlh = np.asarray(obj.wlh, dtype=np.float64)
    w, l, _ = wlh
    K = len(frames)
    t_s = np.array([f.timestamp_us for f in frames], dtype=np.float64) * 1e-6
    ego_xy = np.array([f.T_global_from_ego[:2, 3] for f in frames])
    ego_speed_mps = float(np.linalg.norm(np.diff(ego_xy, axis=0), axis=1).sum() / max(t_s[-1] - t_s[0], 1e-6))
    s_ego_path = path.locate(ego_xy).s  # (K,) the ego's position along its path at each keyframe
    ego_v = np.diff(s_ego_path) / np.maximum(np.diff(t_s), 1e-6)  # its speed between keyframes ...
    t_mid = 0.5 * (t_s[1:] + t_s[:-1])  # ... at these times
    tally = _Tally(report)
    # cut by the frame of the anchor camera with the single-image share (place.place_one); else the first passing
    want_truncated = bool(side_uniform(rng) < pc.truncated_share)
    fallback: Track | None = None  # the first track passing every rule, of the other kind
    fallback_attempt = 0
    for attempt in range(config.attempts):
        if fallback is not None and attempt >= fallback_attempt + TRUNCATION_EXTRA_ATTEMPTS:
            break
        k = int(usable[rng.integers(len(usable))])
        frame = frames[k]
        if moving:  # in lane coordinates: 10-40 m ahead of or behind the ego, in its lane or 1-2 lanes aside
            channel = None
            scene = frame.scene()
            C = pc.n_candidates
            s_ego = path.locate(ego_xy[k][None]).s[0]
            along_m = rng.uniform(pc.min_distance_m, pc.max_distance_m, C) * np.where(rng.random(C) < 0.5, -1.0, 1.0)
            d = rng.integers(-2, 3, C) * LANE_WIDTH_M + rng.normal(0.0, LANE_JITTER_M, C)
            xy0, heading0 = path.point_at(s_ego + along_m, d)
            coords = PathCoords(s_ego + along_m, d, heading0)
            lane_heading, on_lane = (scene.lanes.heading_at(xy0, pc.lane_max_distance_m) if scene.lanes is not None
                                     else (np.full(C, np.nan), np.zeros(C, dtype=bool)))
        else:
            channel = frame.channels[int(rng.integers(len(frame.channels)))]
            scene = frame.scene(channel)
            zone = None
            if rule is not None:
                zones, _ = zone_order(rule, scene, rng)
                if not zones:
                    report["surface"] += 1
                    continue
                zone = zones[0]
            cands = sample_candidates(scene, wlh, rng, rule, zone or "kerb")
            C = len(cands.xy)
            coords = path.locate(cands.xy)
        lo, hi = speed_range(obj.category)
        speed = rng.uniform(lo, hi, C) if moving else np.zeros(C)
        if moving:  # in the ego's own lane traffic moves with the ego: its mean speed, +-15 %
            own_lane = np.abs(coords.d) < 0.5 * LANE_WIDTH_M
            speed[own_lane] = ego_speed_mps * rng.uniform(0.85, 1.15, int(own_lane.sum()))
        noise = np.radians(rng.normal(0.0, pc.yaw_sigma_deg, C))
        if moving:  # no faster than comfortable cornering allows on the curves within reach of the anchor
            reach = coords.s[:, None] + np.linspace(-config.annotate_range_m, config.annotate_range_m, 41)[None]
            kappa = path.curvature_at(reach.ravel()).reshape(reach.shape)
            kappa = np.abs(kappa / np.maximum(1.0 - kappa * coords.d[:, None], 0.2))  # the offset lane's curvature
            speed = np.minimum(speed, np.sqrt(MAX_LATERAL_ACCEL_MPS2 / np.maximum(kappa.max(axis=1), 1e-6)))
            direction = np.zeros(C)
            lane_source = np.full(C, "ego path", dtype=object)
            dir_source = np.full(C, f"traffic keeps {side}", dtype=object)
            if on_lane.any():
                along = np.cos(np.where(on_lane, lane_heading, 0.0) - coords.heading_rad)
                lane = on_lane & (np.abs(along) > 0.7)
                direction[lane] = np.sign(along[lane])
                dir_source[lane] = "map lanes"
            voted, n_votes = votes.direction_at(coords.d, config.direction_band_m)
            use = (direction == 0) & (voted != 0)
            direction[use] = voted[use]
            dir_source[use] = [f"annotated moving vehicles ({n})" for n in n_votes[use]]
            rest = direction == 0
            direction[rest] = _side_direction(coords.d[rest], side)
            follows = own_lane & (ego_speed_mps > 1.0)
            direction[follows] = 1.0
            dir_source[follows] = "the ego's lane and speed profile"
            v_anchor = max(float(np.interp(t_s[k], t_mid, ego_v)) if len(ego_v) else 0.0, 1.0)
            motion = LaneMotion(coords.s, direction * speed, follows, (coords.s - s_ego_path[k]) / v_anchor,
                                float(t_s[k]), t_s, s_ego_path)
            s_j = motion.s_at(t_s[None, :], np.arange(C)[:, None])
            xy_j, heading_j = path.point_at(s_j, coords.d[:, None])
            yaw_j = heading_j + np.where(motion.heading_sign() > 0, 0.0, np.pi)[:, None]
            # oncoming lanes lie beside the ego's; a lane in the ego's direction may be the ego's own (kept
            # clear of the ego in time below)
            lateral_ok = (np.abs(coords.d) <= config.max_lane_offset_m) & (
                (direction > 0) | (np.abs(coords.d) >= config.min_lane_offset_m))
            alive = np.flatnonzero(lateral_ok)
            report["lane_offset"] += C - len(alive)
        elif rule is not None:  # a still object: the heading its class rule gives
            yaw = cands.yaw_rad
            lane_source = np.where(cands.on_lane, "map lanes", "ego path").astype(object)
            dir_source = np.full(C, f"class rule heading '{rule.heading}'", dtype=object)
            xy_j = np.repeat(cands.xy[:, None], K, axis=1)
            yaw_j = np.repeat(yaw[:, None], K, axis=1)
            alive = np.arange(C)
        else:
            along = np.where(cands.on_lane, 0.0, _side_direction(coords.d, side))
            yaw = np.where(cands.on_lane, cands.yaw_rad,
                           coords.heading_rad + np.where(along > 0, 0.0, np.pi) + noise)
            lane_source = np.where(cands.on_lane, "map lanes", "ego path").astype(object)
            dir_source = np.where(cands.on_lane, "map lanes", f"traffic keeps {side}").astype(object)
            xy_j = np.repeat(cands.xy[:, None], K, axis=1)
            yaw_j = np.repeat(yaw[:, None], K, axis=1)
            alive = np.arange(C)
        yaw_j = np.mod(yaw_j + np.pi, 2 * np.pi) - np.pi
        dist = np.linalg.norm(xy_j - ego_xy[None], axis=2)
        span = _contiguous_span(dist <= config.annotate_range_m, np.full(C, k))
        # no pop in or out of view: a span end is pushed on while a camera still sees the box
        span = _contiguous_span(span | (in_some_view(frames, xy_j, yaw_j, wlh) & (dist <= config.max_visible_range_m)),
                                np.full(C, k))
        alive = tally.keep("span", alive, span[alive, k])
        flat = footprint_corners(xy_j.reshape(-1, 2), yaw_j.reshape(-1), l, w).reshape(C, K, 4, 2)
        if moving:  # clear of the ego at the same time, also between keyframes
            alive = _clear_of_ego_in_time(frames, path, motion, coords.d, t_s, span, alive, wlh, config, tally)
        surface = None if moving or rule is None else (rule, zone)
        alive = _check_flat(frames, flat, span, alive, None if moving else swept, placed, config, tally, surface)
        if not moving and rule is None:
            edge = scene.drivable.edge_distance(flat[alive, k])
            alive = tally.keep("kerb", alive, edge <= pc.kerb_distance_m + 0.5)

        def build(c: int, track) -> Track:
            velocity = (_trajectory_velocity(path, motion, c, coords.d[c], t_s[span[c]]) if moving
                        else np.zeros((int(span[c].sum()), 3)))
            if moving and motion.follows_ego[c]:
                speed[c] = float(np.mean(np.linalg.norm(velocity[:, :2], axis=1)))
            keep = np.flatnonzero(span[c])
            return Track(track_index=index, category=obj.category, wlh=wlh.copy(),
                         motion="moving" if moving else "parked", speed_mps=float(speed[c]),
                         lane_source=str(lane_source[c]), direction_source=str(dir_source[c]),
                         sample_tokens=tuple(frames[j].token for j in keep),
                         timestamps_us=np.array([frames[j].timestamp_us for j in keep], dtype=np.int64),
                         T_global_from_object=track[0], velocity_global=velocity, ground_source=track[1],
                         drivable_source=scene.drivable.source, drivable_confidence=scene.drivable.confidence,
                         anchor_sample_token=frame.token, anchor_camera=track[2],
                         detection_class=class_rule.name,
                         zone=zone if rule is not None else ("lane" if moving else "kerb"),
                         fixed_attribute="" if rule is None else
                         (getattr(obj, "attribute", None) if rule.attribute == "asset" else None))

        for c in alive[:CHUNK]:  # the first survivors only: a bounded cost per attempt
            track = _stand_and_check(frames, k, channel, c, xy_j[c], yaw_j[c], span[c], wlh, moving, swept, static_m,
                                     placed, config, tally, surface)
            if track is None:
                continue
            i_k = int(np.searchsorted(np.flatnonzero(span[c]), k))
            if anchor_truncated(frame, track[2], track[0][i_k], wlh, pc) == want_truncated:
                return build(c, track)
            if fallback is None:
                fallback, fallback_attempt = build(c, track), attempt
    return fallback


def in_some_view(frames, xy_j: np.ndarray, yaw_j: np.ndarray, wlh: np.ndarray) -> np.ndarray:
    """(C, K) bool: whether candidate c's box (on the ego's ground plane) at keyframe j has a corner in front of
    and inside the image of some camera of that keyframe (occlusion ignored: a conservative "could be seen")."""
    C, K = xy_j.shape[:2]
    w, l, h = wlh
    out = np.zeros((C, K), dtype=bool)
    for j, frame in enumerate(frames):
        fp = footprint_corners(xy_j[:, j], yaw_j[:, j], l, w)  # (C, 4, 2)
        z0 = frame.T_global_from_ego[2, 3]
        corners = np.concatenate([np.concatenate([fp, np.full((C, 4, 1), z0)], 2),
                                  np.concatenate([fp, np.full((C, 4, 1), z0 + h)], 2)], 1)  # (C, 8, 3)
        for view in frame.sample.cameras.values():
            T = view.T_cam_from_global
            cam = corners @ T[:3, :3].T + T[:3, 3]
            z = cam[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = view.K[0, 0] * cam[..., 0] / z + view.K[0, 2]
                v = view.K[1, 1] * cam[..., 1] / z + view.K[1, 2]
            inside = (z > 0.5) & (u >= 0) & (u < view.width) & (v >= 0) & (v < view.height)
            out[:, j] |= inside.any(axis=1)
    return out


def _tracks_at(placed: Sequence[Track], token: str) -> np.ndarray:
    """(Q, 4, 2) footprints of the already planned tracks annotated at keyframe ``token``."""
    rects = [box_footprint_rect(t.T_global_from_object[i][None], t.wlh)[0]
             for t in placed if (i := t.index_of(token)) is not None]
    return np.array(rects).reshape(-1, 4, 2)


def _surface_ok(frame, fp: np.ndarray, surface: tuple[ClassRule, str] | None) -> np.ndarray:
    """(N,) bool: footprints (N, 4, 2) on the road (``surface`` None) or in the class rule's zone at ``frame``."""
    if frame.drivable is None:
        return np.zeros(len(fp), dtype=bool)
    if surface is None:
        return rule_drivable(frame.drivable, fp)
    rule, zone = surface
    return frame.scene().zones.footprints_in(zone, fp, rule)


def _check_flat(frames, flat: np.ndarray, span: np.ndarray, alive: np.ndarray, swept: np.ndarray,
                placed: Sequence[Track], config: TrackConfig, tally: _Tally,
                surface: tuple[ClassRule, str] | None = None) -> np.ndarray:
    """Candidates ``alive`` whose flat footprints (C, K, 4, 2) pass the footprint rules at every frame of their span
    (``surface``: the (class rule, zone) of a still non-vehicle object, else the road)."""
    pc = config.placement
    for j, frame in enumerate(frames):
        here = alive[span[alive, j]]
        if not len(here):
            continue
        fp = flat[here, j]
        checks = [
            ("surface", lambda fp: _surface_ok(frame, fp, surface)),
            ("annotated_boxes", lambda fp: rule_box_clearance(fp, frame.scene().box_footprints_xy,
                                                              frame.scene().box_is_dynamic, pc.dynamic_clearance_m,
                                                              pc.static_clearance_m)),
            ("ego_path", lambda fp: np.ones(len(fp), dtype=bool) if swept is None
             else rule_mutual(fp, swept, config.ego_clearance_m)),
            ("mutual_collision", lambda fp: rule_mutual(fp, _tracks_at(placed, frame.token), pc.mutual_clearance_m)),
        ]
        failed = np.zeros(len(here), dtype=bool)
        for name, rule in checks:
            todo = ~failed
            ok = rule(fp[todo])
            tally.report[name] += int((~ok).sum())
            failed[np.flatnonzero(todo)[~ok]] = True
        alive = np.setdiff1d(alive, here[failed], assume_unique=True) if failed.any() else alive
    return alive


def _clear_of_ego_in_time(frames, path: EgoPath, motion: LaneMotion, d: np.ndarray, t_s: np.ndarray,
                          span: np.ndarray, alive: np.ndarray, wlh: np.ndarray, config: TrackConfig,
                          tally: _Tally) -> np.ndarray:
    """Moving candidates ``alive`` whose footprint keeps ``dynamic_clearance_m`` from the ego's footprint at
    every keyframe of their span and ``SWEPT_PATH_STEPS - 1`` times between consecutive ones."""
    if len(frames) > 1:
        t_sub = np.concatenate([np.linspace(a, b, SWEPT_PATH_STEPS, endpoint=False) for a, b in zip(t_s[:-1], t_s[1:])]
                               + [t_s[-1:]])
    else:
        t_sub = t_s.copy()
    T_ego = interpolate_poses(np.array([f.T_global_from_ego for f in frames]), t_s, t_sub)
    ego_fp = np.array([ego_footprint(T) for T in T_ego])
    # the span at sub-steps: between two keyframes of the span
    j_of = np.clip(np.searchsorted(t_s, t_sub, side="right") - 1, 0, len(t_s) - 1)
    j_next = np.minimum(j_of + 1, len(t_s) - 1)
    w, l, _ = wlh
    ok = np.ones(len(alive), dtype=bool)
    for q, t in enumerate(t_sub):
        here = span[alive, j_of[q]] & span[alive, j_next[q]] & ok
        if not here.any():
            continue
        idx = np.flatnonzero(here)
        c = alive[idx]
        xy, heading = path.point_at(motion.s_at(t, c), d[c])
        yaw = heading + np.where(motion.heading_sign(c) > 0, 0.0, np.pi)
        fp = footprint_corners(xy, yaw, l, w)
        clear = rule_mutual(fp, ego_fp[q][None], config.placement.dynamic_clearance_m)
        ok[idx[~clear]] = False
    tally.report["ego_path"] += int((~ok).sum())
    return alive[ok]


def stand_heights(frames, keep: np.ndarray, xy_j: np.ndarray, moving: bool, static_m: np.ndarray | None = None
                  ) -> tuple[list, np.ndarray]:
    """The ground planes a track stands on at its span's keyframes ``keep`` and their heights (K',).

    Each keyframe's LiDAR fits the plane below the track's position there (:class:`LocalGroundFitter`). One
    sweep can mistake a canopy, a wall or car roofs for the ground (within its tolerance: 10 % grade), more so
    far from the ego where the rings are sparse, so: a parked track stands on the plane fitted at the keyframe
    where the ego is closest to it (the densest LiDAR there; the same plane throughout: it is static), at that
    keyframe's height plus the global frame's height drift at its place (:func:`~.height_drift.height_drift_m`
    from ``static_m``, the scene's static annotated objects; none: no drift), so that it stands on every
    keyframe's ground; a moving track's heights are median-filtered over 5 keyframes. The annotated vehicles'
    check of single placements is not used: candidates span every keyframe, most of them 40-50 m from that
    keyframe's ego, where it moved many grounds down onto a lower level and the LiDAR obstacle rule then refused
    them (scene-0916, batch seeds 0-5, 3 tracks each, before the drift: 5 of 18 planned with it, 9 without);
    at a parked track's closest keyframe only, it planned 10 instead of 11 and did not steady the height.
    """
    planes = [frames[j].scene().ground.fit(xy_j[j], check_by_boxes=False) for j in keep]
    z = np.array([p.point_global[2] for p in planes])
    if not moving:
        fitted = [q for q, p in enumerate(planes) if p.source != "ego-plane"] or list(range(len(planes)))
        dist = [np.linalg.norm(frames[keep[q]].T_global_from_ego[:2, 3] - xy_j[keep[q]]) for q in fitted]
        best = fitted[int(np.argmin(dist))]
        drift = (np.zeros(len(frames)) if static_m is None or len(static_m) == 0
                 else height_drift_m(static_m, xy_j[keep[best]], int(keep[best])))
        return [planes[best]] * len(keep), z[best] + drift[keep]
    return planes, median_filter(z, size=5, mode="nearest") if len(z) >= 3 else z


def side_uniform(rng: np.random.Generator) -> float:
    """One uniform draw that leaves ``rng``'s own stream as it is: from a child generator spawned from its seed
    sequence (each call spawns the next child, so it is deterministic per seed); from ``rng`` itself when it has no
    seed sequence. Adding a choice this way does not reshuffle every later draw of the plan."""
    try:
        return float(rng.spawn(1)[0].random())
    except (TypeError, ValueError):
        return float(rng.random())


def anchor_truncated(frame: "TrackFrame", channel: str, T_global_from_object: np.ndarray, wlh: np.ndarray,
                     config: PlacementConfig) -> bool:
    """Whether a track is cut by the image frame in the camera ``channel`` of its anchor keyframe ``frame`` (where
    it was sampled and passed the single-image visibility rule), at its pose there ``T_global_from_object`` (4, 4):
    less than ``FULL_VIEW_FRACTION`` of its projected box inside that image, as :func:`~.place.place_one` judges.

    Not the first keyframe of its span: the span is pushed on while any camera still sees the box, so there it is
    mostly far and small, and wholly inside one of the overlapping cameras."""
    view = frame.sample.cameras[channel]
    T_co = view.T_cam_from_global @ T_global_from_object
    corners = box_corners_object(wlh) @ T_co[:3, :3].T + T_co[:3, 3]
    inside = float(projected_inside_fraction(corners[None], PinholeCamera(view.K, view.width, view.height),
                                             config.near_plane_m)[0])
    return inside < FULL_VIEW_FRACTION


def _stand_and_check(frames, k: int, channel: str | None, c: int, xy_j: np.ndarray, yaw_j: np.ndarray, span: np.ndarray,
                     wlh: np.ndarray, moving: bool, swept: np.ndarray, static_m: np.ndarray, placed: Sequence[Track],
                     config: TrackConfig, tally: _Tally, surface: tuple[ClassRule, str] | None = None
                     ) -> tuple[np.ndarray, tuple[str, ...], str] | None:
    """Stand candidate ``c`` on the ground (:func:`stand_heights`) and apply every
    rule to its tilted boxes at every frame of its span; (T (K', 4, 4), ground sources, anchor camera) or None.
    ``channel``: the camera that must see it at the anchor; None: any of the anchor's cameras."""
    pc = config.placement
    off_road = surface is not None and surface[1] in OFF_ROAD_ZONES
    keep = np.flatnonzero(span)
    planes, heights = stand_heights(frames, keep, xy_j, moving, static_m)
    T_all, sources = [], []
    for q, j in enumerate(keep):
        plane = planes[q]
        ground_point = np.array([*plane.point_global[:2], heights[q]])
        T = object_transforms(xy_j[j][None], np.array([yaw_j[j]]), np.array([heights[q]]), plane.normal_global[None])
        frame = frames[j]
        scene = frame.scene()
        rect = box_footprint_rect(T, wlh)
        rules = (
            ("surface", lambda: bool(_surface_ok(frame, rect, surface)[0]) and not (
                off_road and plane.source == "ego-plane")),
            ("annotated_boxes", lambda: rule_box_clearance(rect, scene.box_footprints_xy, scene.box_is_dynamic,
                                                           pc.dynamic_clearance_m, pc.static_clearance_m)[0]),
            ("ego_path", lambda: moving or rule_mutual(rect, swept, config.ego_clearance_m)[0]),
            ("mutual_collision", lambda: rule_mutual(rect, _tracks_at(placed, frame.token), pc.mutual_clearance_m)[0]),
            ("lidar_obstacles", lambda: rule_obstacles(rect, ground_point[None], plane.normal_global[None],
                                                       scene.obstacle_points, pc.static_clearance_m,
                                                       pc.obstacle_min_height_m, pc.obstacle_max_height_m,
                                                       pc.obstacle_max_points)[0]),
            ("lidarseg", lambda: rule_lidarseg(rect, scene.non_ground_xy if off_road else scene.non_drivable_xy,
                                               pc.static_clearance_m, pc.lidarseg_max_points)[0]),
        )
        for name, rule in rules:
            if not rule():
                tally.report[name] += 1
                return None
        if not moving and surface is None and j == keep[0]:
            edge = float(frames[k].drivable.edge_distance(rect)[0])
            if edge > pc.kerb_distance_m:
                tally.report["kerb"] += 1
                return None
        T_all.append(T[0])
        sources.append(str(plane.source))
    # the anchor camera sees it (the single-image visibility rule); without one given: the first that does
    i_k = int(np.searchsorted(keep, k))
    for name in [channel] if channel is not None else frames[k].channels:
        view_scene = frames[k].scene(name)
        T_co = view_scene.view.T_cam_from_global @ T_all[i_k]
        corners = (T_co[:3, :3] @ box_corners_object(wlh).T).T + T_co[:3, 3]
        if not np.all(corners[:, 2] >= pc.near_plane_m):
            continue
        visible = visible_fraction_estimate(T_co[None], wlh, view_scene.camera, view_scene.depth_m,
                                            occlusion_tolerance_for(wlh, pc.occlusion_tolerance_m))
        if rule_in_view(corners[None], view_scene.camera, pc.min_visible_fraction, pc.near_plane_m, visible)[0]:
            return np.array(T_all), tuple(sources), name
    tally.report["in_view"] += 1
    return None


def _trajectory_velocity(path: EgoPath, motion: LaneMotion, c: int, d: float, t: np.ndarray) -> np.ndarray:
    """(T, 3) velocity (m/s, global) of moving candidate ``c`` (offset ``d``) at times ``t`` (T,) seconds."""
    dt = 1e-3
    a, _ = path.point_at(motion.s_at(t - dt, c), np.full(len(t), d))
    b, _ = path.point_at(motion.s_at(t + dt, c), np.full(len(t), d))
    v = np.zeros((len(t), 3))
    v[:, :2] = (b - a) / (2 * dt)
    return v


__all__ = ["DirectionVotes", "EGO_HALF_WIDTH_M", "EGO_X_RANGE_M", "SPEED_RANGE_MPS", "TRACK_RULES", "Track",
           "TrackConfig", "TrackFrame", "TrackPlan", "direction_votes", "ego_footprint", "anchor_truncated",
           "interpolate_poses",
           "plan_tracks", "speed_range", "swept_ego_footprints", "track_frames"]
