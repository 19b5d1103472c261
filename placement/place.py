"""Choose where inserted objects stand: candidates in the camera's ground frustum, filtered by the rules.

For each object: ``n_candidates`` candidates are sampled (deterministically from ``rng``) with the box
centre at a horizontal distance r ~ U[min, max] from the camera and an azimuth uniform within the
camera's horizontal field of view. Yaw = the direction of travel of the nearest lane centre line when
the map has lanes and one lies within ``lane_max_distance_m`` of the candidate, else the ego heading
(or its opposite, with probability ``opposite_heading_probability``); plus N(0, yaw_sigma_deg) noise.

The rules are applied in ``RULE_ORDER``; the first surviving candidate (in sampling order) of the kind the
object drew is chosen: wholly in the image, or cut by its frame with probability ``truncated_share`` (:func:`place_one`).
``drivable`` and ``annotated_boxes`` first filter the flat footprints cheaply; each survivor then
stands on the local ground plane fitted from LiDAR (roll/pitch from its normal, heading projected onto
the plane) and every footprint rule is (re)applied to the footprint of that tilted box
(:func:`~streetaug.placement.rules.box_footprint_rect`), so a final placement satisfies each rule as labelled.
Candidates are sampled and stood on the ground in :mod:`~streetaug.placement.candidates`.

What hides a candidate (``in_view``, ``corners_unoccluded``) is the scene depth the renderer's depth
test uses (:func:`~streetaug.placement.scene.scene_depth`): pass the pipeline's to :func:`place_objects`,
or it is computed here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np

from streetaug.augment.core import InputError, rotation_to_quat
from streetaug.datasets.nuscenes_format import VEHICLE_MOVING, VEHICLE_PARKED
from streetaug.datasets.sample import Box, CameraView, Sample

from .candidates import (LANE_REACH_OFF_CENTRE_M, Candidates, StoodCandidates, is_small, sample_candidates,
                         stand_candidates)
from .class_rules import ClassRule, ClassRules, read_class_rules
from .config import PlacementConfig
from .drivable import DrivableArea, drivable_area_for_sample
from .rules import (
    footprint_corners,
    occlusion_tolerance_for,
    projected_inside_fraction,
    rule_box_clearance,
    rule_corners_unoccluded,
    rule_distance,
    rule_in_view,
    rule_lidarseg,
    rule_obstacles,
    visible_fraction_estimate,
)
from .parking import parked_share, with_parked_share
from .scene import PlacementScene

CHUNK = 48  # candidates stood on the ground and checked per round (the first survivor of the drawn kind wins)
FULL_VIEW_FRACTION = 0.999  # of the projected box inside the image: a candidate wholly in view (else truncated)

RULE_ORDER = (
    "surface",
    "annotated_boxes",
    "distance",
    "lidar_obstacles",
    "lidarseg",
    "in_view",
    "corners_unoccluded",
    "mutual_collision",
)


class Placeable(Protocol):
    """What placement reads of an object: its box size and category (an ``Asset`` is one)."""

    @property
    def wlh(self) -> np.ndarray: ...

    @property
    def category(self) -> str: ...


@dataclass(frozen=True)
class ObjectBox:
    """An object known only by its box (for callers without a mesh).

    Attributes:
        wlh: (3,) float64 width, length, height in metres.
        category: nuScenes category of the box.
    """

    wlh: np.ndarray
    category: str = "vehicle.car"


@dataclass(frozen=True)
class Placement:
    """One placed object.

    Attributes:
        asset_index: index of the object in the sequence given to :func:`place_objects`.
        T_global_from_object: (4, 4) object frame (x front, y left, z up, origin at the bottom centre) -> global.
        box: nuScenes :class:`Box` in the global frame (centre = bottom centre + h/2 along the object's up).
        wlh: (3,) float64 width, length, height in metres.
        ground_normal_global: (3,) unit normal of the local ground (global frame).
        ground_source: ``"lidarseg"``, ``"lidar-plane"``, ``"boxes"`` or ``"ego-plane"`` (:class:`~.ground.GroundPlane`).
        drivable_source: ``"map"``, ``"lidarseg"`` or ``"lidar-ground"``.
        drivable_confidence: ``"high"``, ``"medium"`` or ``"low"``.
        attribute: ``"vehicle.parked"`` when the footprint is within ``kerb_distance_m`` of the drivable
            area's edge (standing by the kerb), else ``"vehicle.moving"`` (in the lane).
        distance_m: horizontal distance from the camera centre to the box centre.
        edge_distance_m: distance from the footprint to the edge of the drivable area.
        yaw_source: ``"lane"`` (heading of the nearest lane centre line of the map), ``"kerb"`` (from the road
            edge: as the nearest parked box stands, or along the edge; :func:`~streetaug.placement.parking.kerb_poses`),
            ``"ego"`` (the ego heading or its opposite) or ``"random"``.
        footprint_xy: (4, 2) float64 the footprint the rules checked (:func:`box_footprint_rect`), global x/y.
        visible_fraction: the estimated fraction of the box's image inside the image and not hidden by
            the scene depth (:func:`visible_fraction_estimate`), as the ``in_view`` rule judged it.
        detection_class: the class whose rule placed it (:mod:`~streetaug.placement.class_rules`).
        zone: the surface it stands on (``lane``, ``kerb``, ``road_edge``, ``sidewalk``, ``crossing``).
        cluster_of: for a member of a cluster (a line of cones), the index among the result's placements of
            its first member; -1 for the first member and single objects.
    """

    asset_index: int
    T_global_from_object: np.ndarray
    box: Box
    wlh: np.ndarray
    ground_normal_global: np.ndarray
    ground_source: str
    drivable_source: str
    drivable_confidence: str = ""
    attribute: str | None = VEHICLE_MOVING
    distance_m: float = float("nan")
    edge_distance_m: float = float("nan")
    yaw_source: str = "ego"
    footprint_xy: np.ndarray = field(default_factory=lambda: np.zeros((4, 2)))
    visible_fraction: float = float("nan")
    detection_class: str = "car"
    zone: str = "lane"
    cluster_of: int = -1

    def T_cam_from_object(self, view: CameraView) -> np.ndarray:
        """(4, 4) object -> camera frame of ``view``."""
        return view.T_cam_from_global @ self.T_global_from_object


@dataclass(frozen=True)
class PlacementResult:
    """Outcome of :func:`place_objects`.

    Attributes:
        placements: the placed objects (possibly fewer than requested, possibly none), each with the
            index of its object (``asset_index``).
        report: rule name -> number of candidates it rejected (summed over objects), keys in ``RULE_ORDER``.
        reason: why fewer objects than requested were placed (None when all were placed).
        candidates_xy: (C, 2) float64 every sampled candidate's bottom-centre x/y (global), for explanations.
        rejected_by: (C,) the rule that rejected each candidate ('' = passed, 'unused' = not needed).
        candidate_class: (C,) the detection class (and zone, ``class/zone``) each candidate was drawn for.
        drivable: the drivable area used (None when there was none).
        config: the configuration used.
        class_reasons: detection class -> why an object of it was not placed (empty when all were).
    """

    placements: list[Placement]
    report: dict[str, int]
    reason: str | None
    candidates_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    rejected_by: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    drivable: DrivableArea | None = None
    config: PlacementConfig | None = None
    candidate_class: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    class_reasons: dict[str, str] = field(default_factory=dict)


class RuleTally:
    """The rejections of one object's candidates: which rule rejected each, and counts per rule."""

    def __init__(self, n_candidates: int, report: dict[str, int]) -> None:
        self.rejected_by = np.full(n_candidates, "", dtype=object)
        self.report = report

    def keep(self, name: str, index: np.ndarray, alive: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """Record rule ``name`` rejecting candidates ``index[alive[~ok]]``; return the surviving ``alive[ok]``."""
        ok = np.asarray(ok, dtype=bool)
        self.rejected_by[index[alive[~ok]]] = name
        self.report[name] += int((~ok).sum())
        return alive[ok]


def prefilter(scene: PlacementScene, cands: Candidates, tally: RuleTally, rule: ClassRule, zone: str,
              config: PlacementConfig) -> np.ndarray:
    """Indices of the candidates whose flat footprints pass ``surface`` and ``annotated_boxes`` (cheap, vectorised)."""
    everyone = np.arange(len(cands.xy))
    alive = tally.keep("surface", everyone, everyone, scene.zones.footprints_in(zone, cands.footprints_xy, rule))
    return tally.keep("annotated_boxes", everyone, alive,
                      annotated_clearance(scene, cands.footprints_xy[alive], rule, zone, config))


def annotated_clearance(scene: PlacementScene, footprints_xy: np.ndarray, rule: ClassRule, zone: str,
                        config: PlacementConfig) -> np.ndarray:
    """(N,) bool footprints (N, 4, 2) clear of the annotated boxes: the dynamic clearance from dynamic ones, the
    static from the others, only the parking gap from parked vehicles beside a kerb placement
    (:meth:`PlacementScene.beside_parked`)."""
    parked = scene.beside_parked(rule, zone)
    ok = rule_box_clearance(footprints_xy, scene.box_footprints_xy[~parked], scene.box_is_dynamic[~parked],
                            config.dynamic_clearance_m, config.static_clearance_m)
    if parked.any():
        gap = min(scene.parked_gap_m, config.static_clearance_m)
        ok &= rule_box_clearance(footprints_xy, scene.box_footprints_xy[parked], np.zeros(int(parked.sum()), bool),
                                 gap, gap)
    return ok


@dataclass(frozen=True)
class ChunkSurvivors:
    """Positions (K,) in a chunk of the candidates passing every rule, with their visible fractions (K,)."""

    alive: np.ndarray
    visible_fraction: np.ndarray


OFF_ROAD_ZONES = ("road_edge", "sidewalk")  # zones where the ground must be seen (no ego-plane fallback)


@dataclass(frozen=True)
class PlacedSoFar:
    """The footprints (Q, 4, 2) of the objects already placed in this image and their mutual clearances (Q,)."""

    footprints_xy: np.ndarray
    clearance_m: np.ndarray

    @classmethod
    def empty(cls) -> "PlacedSoFar":
        return cls(np.zeros((0, 4, 2)), np.zeros(0))

    def plus(self, footprint_xy: np.ndarray, clearance_m: float) -> "PlacedSoFar":
        return PlacedSoFar(np.concatenate([self.footprints_xy, footprint_xy[None]]), np.r_[self.clearance_m, clearance_m])


def check_stood(scene: PlacementScene, stood: StoodCandidates, wlh: np.ndarray, placed: PlacedSoFar,
                tally: RuleTally, rule: ClassRule, zone: str, config: PlacementConfig,
                skip_mutual: np.ndarray | None = None) -> ChunkSurvivors:
    """Apply every rule, in ``RULE_ORDER``, with ``rule``'s thresholds (``config``), to one chunk's standing boxes.

    ``skip_mutual`` (Q,) bool: placed objects this one may come closer to than the mutual clearance (the
    other members of its own cluster: they only must not touch).
    """
    cfg, camera, idx = config, scene.camera, stood.index
    k = np.arange(len(idx))
    rect = stood.footprints_xy
    in_zone = scene.zones.footprints_in(zone, rect[k], rule, member=skip_mutual is not None)
    if zone in OFF_ROAD_ZONES or is_small(wlh):  # off the road, and under small objects (whose contact shows),
        # the ground must be measured under the object, not assumed
        in_zone &= np.array([p.source != "ego-plane" and p.n_points > 0 for p in stood.planes], dtype=bool)
    k = tally.keep("surface", idx, k, in_zone)
    k = tally.keep("annotated_boxes", idx, k, annotated_clearance(scene, rect[k], rule, zone, cfg))
    k = tally.keep("distance", idx, k, rule_distance(stood.centers[k, :2], scene.camera_xy, cfg.min_distance_m,
                                                     cfg.max_distance_m))
    k = tally.keep("lidar_obstacles", idx, k, rule_obstacles(
        rect[k], stood.ground_points[k], stood.ground_normals[k], scene.obstacle_points, cfg.static_clearance_m,
        cfg.obstacle_min_height_m, cfg.obstacle_max_height_m, cfg.obstacle_max_points))
    blocking = scene.non_drivable_xy if zone not in OFF_ROAD_ZONES else scene.non_ground_xy
    k = tally.keep("lidarseg", idx, k, rule_lidarseg(rect[k], blocking, cfg.static_clearance_m,
                                                     cfg.lidarseg_max_points))
    visible = np.zeros(len(idx))
    visible[k] = visible_fraction_estimate(stood.T_cam_from_object[k], wlh, camera, scene.depth_m,
                                           occlusion_tolerance_for(wlh, cfg.occlusion_tolerance_m))
    k = tally.keep("in_view", idx, k, rule_in_view(stood.corners_cam[k], camera, cfg.min_visible_fraction,
                                                   cfg.near_plane_m, visible[k]))
    if cfg.require_unoccluded_corners:
        k = tally.keep("corners_unoccluded", idx, k, rule_corners_unoccluded(
            stood.corners_cam[k], camera, scene.depth_m, cfg.occlusion_tolerance_m))
    need = np.maximum(placed.clearance_m, cfg.mutual_clearance_m)
    if skip_mutual is not None:
        need = np.where(skip_mutual, 1e-3, need)  # cluster mates: apart, however small the gap
    k = tally.keep("mutual_collision", idx, k, rule_box_clearance(
        rect[k], placed.footprints_xy, np.ones(len(need), bool), need, need) if len(need) and len(k)
        else np.ones(len(k), bool))
    return ChunkSurvivors(k, visible[k])


def placement_attribute(rule: ClassRule, obj: "Placeable", edge_distance_m: float, zone: str,
                        config: PlacementConfig) -> str | None:
    """The nuScenes attribute of a placed object of ``rule``'s class (see ``ClassRule.attribute``)."""
    if rule.attribute == "vehicle":
        return VEHICLE_PARKED if zone == "kerb" or edge_distance_m <= config.kerb_distance_m else VEHICLE_MOVING
    if rule.attribute == "parked":
        return VEHICLE_PARKED
    if rule.attribute == "asset":
        return getattr(obj, "attribute", None)
    return None


def make_placement(scene: PlacementScene, asset_index: int, obj: Placeable, wlh: np.ndarray, cands: Candidates,
                   stood: StoodCandidates, j: int, visible_fraction: float, rule: ClassRule | None = None,
                   zone: str = "lane", cluster_of: int = -1) -> Placement:
    """The :class:`Placement` of position ``j`` of ``stood``."""
    rule = rule or read_class_rules().classes["car"]
    T, center, fp = stood.T_global_from_object[j], stood.centers[j], stood.footprints_xy[j]
    edge = float(scene.drivable.edge_distance(fp[None])[0])
    return Placement(
        asset_index=asset_index,
        T_global_from_object=T,
        box=Box(center.copy(), wlh.copy(), rotation_to_quat(T[:3, :3]), obj.category),
        wlh=wlh.copy(),
        ground_normal_global=stood.planes[j].normal_global.copy(),
        ground_source=str(stood.planes[j].source),
        drivable_source=scene.drivable.source,
        drivable_confidence=scene.drivable.confidence,
        attribute=placement_attribute(rule, obj, edge, zone, scene.config),
        distance_m=float(np.linalg.norm(center[:2] - scene.camera_xy)),
        edge_distance_m=edge,
        yaw_source=("lane" if cands.on_lane[stood.index[j]] else "random" if rule.heading == "random" else
                    "kerb" if rule.parks_like_the_scene(zone) else "ego"),
        footprint_xy=fp.copy(),
        visible_fraction=float(visible_fraction),
        detection_class=rule.name,
        zone=zone,
        cluster_of=cluster_of,
    )


@dataclass(frozen=True)
class ObjectAttempt:
    """One object's candidates, what became of each, and the placement (None when no candidate passed).

    ``candidate_class`` (C,) names each candidate's ``class/zone``; ``reason`` says why nothing was placed.
    """

    candidates_xy: np.ndarray
    rejected_by: np.ndarray
    placement: Placement | None
    candidate_class: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    reason: str | None = None


def zone_order(rule: ClassRule, scene: PlacementScene, rng: np.random.Generator) -> tuple[list[str], list[str]]:
    """(the usable zones of ``rule`` in the order to try them, why the others cannot be used).

    The first zone is drawn by weight, the others follow by decreasing weight; draws one uniform from ``rng``.
    """
    u = rng.random()
    usable = [(z, w) for z, w in rule.zones.items() if scene.zones.unavailable(z) is None]
    notes = [f"{z}: {scene.zones.unavailable(z)}" for z in rule.zones if scene.zones.unavailable(z) is not None]
    if not usable:
        return [], notes
    w = np.array([x[1] for x in usable])
    first = int(np.searchsorted(np.cumsum(w) / w.sum(), u, side="right").clip(0, len(usable) - 1))
    rest = sorted((x for i, x in enumerate(usable) if i != first), key=lambda x: -x[1])
    return [usable[first][0]] + [z for z, _ in rest], notes


def place_one(scene: PlacementScene, asset_index: int, obj: Placeable, rng: np.random.Generator,
              placed: PlacedSoFar, report: dict[str, int], rule: ClassRule | None = None) -> ObjectAttempt:
    """Sample candidates for one object and keep the first (in sampling order) passing every rule, of the kind drawn.

    The kind: wholly in the image (at least ``FULL_VIEW_FRACTION`` of the projected box inside) or cut by its
    frame, truncated with probability ``truncated_share`` (one uniform from ``rng``, drawn after the first zone's
    candidates). The first candidate passing every rule is kept when it is of that kind; else the first of that
    kind after it; when the zone has none of that kind, the first passing every rule. (Taking the first passing
    one, a candidate at the frame's edge passes as easily as one in the middle (centres are sampled over the
    whole field of view, and up to ``1 - min_visible_fraction`` may be outside), and where a kerb is lined with
    parked cars the free places left in range are mostly near ones at the image's side: on the real scene-0916
    the car stood cut by the frame in 18 % of 272 placements, more than half of them by over 30 %, against
    12.7 % of the 1289 annotated cars in range; ``benchmarks/bench_placement_truncation.py``.)

    The zones of the object's class rule are tried in :func:`zone_order` (``n_candidates`` each) until one
    gives a placement. Candidates past the cheap pre-filters are stood on the ground and checked in chunks of
    ``CHUNK``, so later chunks are only evaluated when needed; the survivors not chosen are marked ``unused``.
    """
    rule = rule or read_class_rules().for_category(obj.category)
    config = rule.config(scene.config)
    wlh = np.asarray(obj.wlh, dtype=np.float64)
    zones, notes = zone_order(rule, scene, rng)
    all_xy, all_rej, all_cls = [], [], []
    want_truncated: bool | None = None
    for zone in zones:
        cands = sample_candidates(scene, wlh, rng, rule, zone)
        if want_truncated is None:
            want_truncated = bool(rng.random() < config.truncated_share)
        tally = RuleTally(len(cands.xy), report)
        all_xy.append(cands.xy)
        all_rej.append(tally.rejected_by)
        all_cls.append(np.full(len(cands.xy), f"{rule.name}/{zone}", dtype=object))
        alive = prefilter(scene, cands, tally, rule, zone, config)
        fallback: tuple[StoodCandidates, int, float] | None = None  # the first survivor of either kind
        chosen = None
        for start in range(0, len(alive), CHUNK):
            stood = stand_candidates(scene, cands, alive[start:start + CHUNK], wlh, config)
            survivors = check_stood(scene, stood, wlh, placed, tally, rule, zone, config)
            if not len(survivors.alive):
                continue
            tally.rejected_by[stood.index[survivors.alive]] = "unused"  # until chosen
            if fallback is None:
                fallback = (stood, survivors.alive[0], survivors.visible_fraction[0])
            inside = projected_inside_fraction(stood.corners_cam[survivors.alive], scene.camera, config.near_plane_m)
            kind = np.flatnonzero((inside < FULL_VIEW_FRACTION) == want_truncated)
            if len(kind):
                chosen = (stood, survivors.alive[kind[0]], survivors.visible_fraction[kind[0]])
                tally.rejected_by[alive[start + CHUNK:]] = "unused"  # passed the pre-filters, not evaluated further
                break
        chosen = chosen or fallback
        if chosen is not None:
            stood, j, visible = chosen
            tally.rejected_by[stood.index[j]] = ""
            placement = make_placement(scene, asset_index, obj, wlh, cands, stood, j, visible, rule, zone)
            return ObjectAttempt(np.concatenate(all_xy), np.concatenate(all_rej), placement, np.concatenate(all_cls))
    if not zones:
        reason = f"{rule.name}: no usable zone ({'; '.join(notes)})"
    else:
        reason = f"{rule.name}: no candidate passed every rule in zone(s) {', '.join(zones)}"
        if notes:
            reason += f" ({'; '.join(notes)})"
    empty = np.zeros((0, 2))
    return ObjectAttempt(np.concatenate(all_xy) if all_xy else empty,
                         np.concatenate(all_rej) if all_rej else np.zeros(0, dtype=object), None,
                         np.concatenate(all_cls) if all_cls else np.zeros(0, dtype=object), reason)


def cluster_members(scene: PlacementScene, leader: Placement, leader_index: int, obj: Placeable,
                    rule: ClassRule, rng: np.random.Generator, placed: PlacedSoFar,
                    report: dict[str, int]) -> list[Placement]:
    """The other members of ``leader``'s cluster: a line along the road, each checked by every rule.

    Draws the size, gap, taper and direction (forward or back along the road) from ``rng``; the line grows
    that way until a member fails a rule, then the other way from the first member. Members use the leader's
    object (``asset_index``) and heading noise.
    """
    c = rule.cluster
    n = int(rng.integers(c.size[0], c.size[1] + 1))
    gap = float(rng.uniform(*c.gap_m))
    taper = np.radians(float(rng.uniform(*c.taper_deg)))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    jitter = rng.normal(0.0, 1.0, (max(n - 1, 0), 3))  # per member: along, across (m), yaw
    if n <= 1:
        return []
    config = rule.config(scene.config)
    wlh = np.asarray(obj.wlh, dtype=np.float64)
    road_dir = scene.zones.edge_tangent(leader.box.center[None, :2])[0]  # along the road's edge
    if scene.lanes is not None:
        lane_heading, on_lane = scene.lanes.heading_at(leader.box.center[None, :2],
                                                       scene.config.lane_max_distance_m + LANE_REACH_OFF_CENTRE_M)
        if on_lane[0]:
            road_dir = np.array([np.cos(lane_heading[0]), np.sin(lane_heading[0])])
    lx = leader.T_global_from_object[:2, 0]
    ux = lx / max(np.linalg.norm(lx), 1e-9)  # the leader's x (front) in x/y
    uy = np.array([-ux[1], ux[0]])
    extent = float(leader.wlh[1] * abs(ux @ road_dir) + leader.wlh[0] * abs(uy @ road_dir))  # footprint along the road
    step = extent + gap
    inward = scene.zones.road_normal(leader.box.center[None, :2])[0]
    yaw0 = float(np.arctan2(ux[1], ux[0]))
    members: list[Placement] = []
    mates = [leader_index]
    steps = [(sign, k) for k in range(1, n)] + [(-sign, k) for k in range(1, n)]  # forward, then back
    failed_side = set()
    for i, (side, k) in enumerate(steps):
        if len(members) >= n - 1:
            break
        if side in failed_side:
            continue
        along = side * k * step + 0.05 * jitter[len(members), 0]
        xy = leader.box.center[:2] + along * road_dir + (abs(along) * np.tan(taper) + 0.03 * jitter[len(members), 1]) \
            * inward
        yaw = yaw0 + np.radians(config.yaw_sigma_deg) * jitter[len(members), 2] if rule.heading != "random" else \
            float(np.mod(yaw0 + 2.4 * (i + 1), 2 * np.pi))
        w, l, _ = wlh
        cands = Candidates(xy[None], np.array([yaw]), np.zeros(1, bool), footprint_corners(xy[None], np.array([yaw]), l, w))
        tally = RuleTally(1, report)
        stood = stand_candidates(scene, cands, np.arange(1), wlh, config)
        skip = np.zeros(len(placed.clearance_m), bool)
        skip[mates] = True
        survivors = check_stood(scene, stood, wlh, placed, tally, rule, leader.zone, config, skip_mutual=skip)
        if not len(survivors.alive):
            failed_side.add(side)  # the line ends on this side
            continue
        p = make_placement(scene, leader.asset_index, obj, wlh, cands, stood, 0, survivors.visible_fraction[0],
                           rule, leader.zone, cluster_of=leader_index)
        members.append(p)
        mates.append(len(placed.clearance_m))
        placed = placed.plus(p.footprint_xy, config.mutual_clearance_m)
    return members


def check_objects(objects: Sequence[Placeable]) -> None:
    """Raise :class:`InputError` unless every object has 3 positive finite sizes [w, l, h]."""
    for i, obj in enumerate(objects):
        if not (hasattr(obj, "wlh") and hasattr(obj, "category")):
            raise InputError(f"place_objects: objects[{i}] must have a size .wlh and a .category (an Asset or an "
                             f"ObjectBox), got {type(obj).__name__}")
        a = np.asarray(obj.wlh, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
            raise InputError(f"place_objects: objects[{i}].wlh must be 3 positive finite sizes [w, l, h] in metres, "
                             f"got {a.tolist()}")


def scene_rule(rules: ClassRules, rule: ClassRule, boxes: Sequence[Box]) -> ClassRule:
    """``rule`` with its lane / kerb weights from the parked share of ``boxes`` of its class
    (:func:`~streetaug.placement.parking.with_parked_share`; unchanged for fixed zone weights)."""
    return with_parked_share(rule, *parked_share(boxes, rules.categories_of(rule.name)))


def place_objects(
    sample: Sample,
    view: CameraView,
    objects: Sequence[Placeable],
    rng: np.random.Generator,
    config: PlacementConfig = PlacementConfig(),
    depth_m: np.ndarray | None = None,
    class_rules: ClassRules | None = None,
) -> PlacementResult:
    """Place ``objects`` (assets, or :class:`ObjectBox` sizes and categories) in ``view`` of ``sample``.

    Each object follows the rule of its category's class (``class_rules``, default the built-in table,
    :func:`~streetaug.placement.class_rules.read_class_rules`): its zones (a vehicle's lane / kerb split from the
    sample's own parked share, :func:`scene_rule`), distances and clearances. An object
    of a class with a ``cluster`` rule brings the other members of its line (placements with the same
    ``asset_index`` and ``cluster_of`` set). Deterministic for a given ``rng`` state. ``config.n_objects`` is
    not used here: the caller passes the objects. Objects that found no place are left out.

    Args:
        depth_m: (H, W) float32 the scene depth of ``view`` (camera z, metres, inf = unknown) the
            renderer will test against; None computes the same (:func:`scene_depth`).
    """
    check_objects(objects)
    rules = class_rules or read_class_rules()
    object_rules = [scene_rule(rules, rules.for_category(o.category), sample.boxes) for o in objects]
    report = {name: 0 for name in RULE_ORDER}
    drivable, reason = drivable_area_for_sample(sample, view, config)
    if drivable is None:
        return PlacementResult([], report, reason, config=config,
                               class_reasons={r.name: reason for r in object_rules})
    scene = PlacementScene.of(sample, view, config, drivable, depth_m, rules)
    placements: list[Placement] = []
    placed = PlacedSoFar.empty()
    attempts = []
    class_reasons: dict[str, str] = {}
    for i, (obj, rule) in enumerate(zip(objects, object_rules)):
        attempt = place_one(scene, i, obj, rng, placed, report, rule)
        attempts.append(attempt)
        if attempt.placement is None:
            class_reasons.setdefault(rule.name, attempt.reason or "no valid placement")
            continue
        leader_index = len(placements)
        placements.append(attempt.placement)
        mutual = rule.config(config).mutual_clearance_m
        placed = placed.plus(attempt.placement.footprint_xy, mutual)
        if rule.cluster is not None:
            members = cluster_members(scene, attempt.placement, leader_index, obj, rule, rng, placed, report)
            for p in members:
                placements.append(p)
                placed = placed.plus(p.footprint_xy, mutual)
    reason = None
    n_placed = len({p.asset_index for p in placements})
    if n_placed < len(objects):
        worst = ", ".join(f"{k}: {v}" for k, v in report.items() if v)
        reason = (f"placed {n_placed} of {len(objects)} objects: "
                  + "; ".join(class_reasons.values()) + (f" (rejected by {worst})" if worst else ""))
    return PlacementResult(placements, report, reason, np.concatenate([a.candidates_xy for a in attempts]),
                           np.concatenate([a.rejected_by for a in attempts]), drivable, config,
                           np.concatenate([a.candidate_class for a in attempts]), class_reasons)


__all__ = [
    "CHUNK", "FULL_VIEW_FRACTION", "OFF_ROAD_ZONES", "RULE_ORDER", "ChunkSurvivors", "annotated_clearance", "ObjectAttempt", "ObjectBox", "PlacedSoFar", "Placeable",
    "Placement", "PlacementResult", "RuleTally", "check_objects", "check_stood", "cluster_members", "make_placement",
    "place_objects", "place_one", "placement_attribute", "prefilter", "scene_rule", "zone_order",
]
