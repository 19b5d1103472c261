"""Choose where inserted objects stand: candidates in the camera's ground frustum, filtered by the rules.

For each object: ``n_candidates`` candidates are sampled (deterministically from ``rng``) with the box
centre at a horizontal distance r ~ U[min, max] from the camera and an azimuth uniform within the
camera's horizontal field of view. Yaw = the direction of travel of the nearest lane centre line when
the map has lanes and one lies within ``lane_max_distance_m`` of the candidate, else the ego heading
(or its opposite, with probability ``opposite_heading_probability``); plus N(0, yaw_sigma_deg) noise.

The rules are applied in ``RULE_ORDER``; the first surviving candidate (in sampling order) is chosen.
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

from .candidates import Candidates, StoodCandidates, sample_candidates, stand_candidates
from .config import PlacementConfig
from .drivable import DrivableArea, drivable_area_for_sample
from .rules import (
    rule_box_clearance,
    rule_corners_unoccluded,
    rule_distance,
    rule_drivable,
    rule_in_view,
    rule_lidarseg,
    rule_mutual,
    rule_obstacles,
    visible_fraction_estimate,
)
from .scene import PlacementScene

CHUNK = 48  # candidates stood on the ground and checked per round (the first survivor wins)

RULE_ORDER = (
    "drivable",
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
        ground_source: ``"lidarseg"``, ``"lidar-plane"`` or ``"ego-plane"``.
        drivable_source: ``"map"``, ``"lidarseg"`` or ``"lidar-ground"``.
        drivable_confidence: ``"high"``, ``"medium"`` or ``"low"``.
        attribute: ``"vehicle.parked"`` when the footprint is within ``kerb_distance_m`` of the drivable
            area's edge (standing by the kerb), else ``"vehicle.moving"`` (in the lane).
        distance_m: horizontal distance from the camera centre to the box centre.
        edge_distance_m: distance from the footprint to the edge of the drivable area.
        yaw_source: ``"lane"`` (heading of the nearest lane centre line of the map) or ``"ego"``
            (the ego heading or its opposite).
        footprint_xy: (4, 2) float64 the footprint the rules checked (:func:`box_footprint_rect`), global x/y.
        visible_fraction: the estimated fraction of the box's image inside the image and not hidden by
            the scene depth (:func:`visible_fraction_estimate`), as the ``in_view`` rule judged it.
    """

    asset_index: int
    T_global_from_object: np.ndarray
    box: Box
    wlh: np.ndarray
    ground_normal_global: np.ndarray
    ground_source: str
    drivable_source: str
    drivable_confidence: str = ""
    attribute: str = VEHICLE_MOVING
    distance_m: float = float("nan")
    edge_distance_m: float = float("nan")
    yaw_source: str = "ego"
    footprint_xy: np.ndarray = field(default_factory=lambda: np.zeros((4, 2)))
    visible_fraction: float = float("nan")

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
        drivable: the drivable area used (None when there was none).
        config: the configuration used.
    """

    placements: list[Placement]
    report: dict[str, int]
    reason: str | None
    candidates_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    rejected_by: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    drivable: DrivableArea | None = None
    config: PlacementConfig | None = None


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


def prefilter(scene: PlacementScene, cands: Candidates, tally: RuleTally) -> np.ndarray:
    """Indices of the candidates whose flat footprints pass ``drivable`` and ``annotated_boxes`` (cheap, vectorised)."""
    cfg = scene.config
    everyone = np.arange(len(cands.xy))
    alive = tally.keep("drivable", everyone, everyone, rule_drivable(scene.drivable, cands.footprints_xy))
    return tally.keep("annotated_boxes", everyone, alive, rule_box_clearance(
        cands.footprints_xy[alive], scene.box_footprints_xy, scene.box_is_dynamic, cfg.dynamic_clearance_m,
        cfg.static_clearance_m))


@dataclass(frozen=True)
class ChunkSurvivors:
    """Positions (K,) in a chunk of the candidates passing every rule, with their visible fractions (K,)."""

    alive: np.ndarray
    visible_fraction: np.ndarray


def check_stood(scene: PlacementScene, stood: StoodCandidates, wlh: np.ndarray, placed_xy: np.ndarray,
                tally: RuleTally) -> ChunkSurvivors:
    """Apply every rule, in ``RULE_ORDER``, to the standing boxes of one chunk."""
    cfg, camera, idx = scene.config, scene.camera, stood.index
    k = np.arange(len(idx))
    rect = stood.footprints_xy
    k = tally.keep("drivable", idx, k, rule_drivable(scene.drivable, rect[k]))
    k = tally.keep("annotated_boxes", idx, k, rule_box_clearance(
        rect[k], scene.box_footprints_xy, scene.box_is_dynamic, cfg.dynamic_clearance_m, cfg.static_clearance_m))
    k = tally.keep("distance", idx, k, rule_distance(stood.centers[k, :2], scene.camera_xy, cfg.min_distance_m,
                                                     cfg.max_distance_m))
    k = tally.keep("lidar_obstacles", idx, k, rule_obstacles(
        rect[k], stood.ground_points[k], stood.ground_normals[k], scene.obstacle_points, cfg.static_clearance_m,
        cfg.obstacle_min_height_m, cfg.obstacle_max_height_m, cfg.obstacle_max_points))
    k = tally.keep("lidarseg", idx, k, rule_lidarseg(rect[k], scene.non_drivable_xy, cfg.static_clearance_m,
                                                     cfg.lidarseg_max_points))
    visible = np.zeros(len(idx))
    visible[k] = visible_fraction_estimate(stood.T_cam_from_object[k], wlh, camera, scene.depth_m,
                                           cfg.occlusion_tolerance_m)
    k = tally.keep("in_view", idx, k, rule_in_view(stood.corners_cam[k], camera, cfg.min_visible_fraction,
                                                   cfg.near_plane_m, visible[k]))
    if cfg.require_unoccluded_corners:
        k = tally.keep("corners_unoccluded", idx, k, rule_corners_unoccluded(
            stood.corners_cam[k], camera, scene.depth_m, cfg.occlusion_tolerance_m))
    k = tally.keep("mutual_collision", idx, k, rule_mutual(rect[k], placed_xy, cfg.mutual_clearance_m))
    return ChunkSurvivors(k, visible[k])


def make_placement(scene: PlacementScene, asset_index: int, obj: Placeable, wlh: np.ndarray, cands: Candidates,
                   stood: StoodCandidates, j: int, visible_fraction: float) -> Placement:
    """The :class:`Placement` of position ``j`` of ``stood``."""
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
        attribute=VEHICLE_PARKED if edge <= scene.config.kerb_distance_m else VEHICLE_MOVING,
        distance_m=float(np.linalg.norm(center[:2] - scene.camera_xy)),
        edge_distance_m=edge,
        yaw_source="lane" if cands.on_lane[stood.index[j]] else "ego",
        footprint_xy=fp.copy(),
        visible_fraction=float(visible_fraction),
    )


@dataclass(frozen=True)
class ObjectAttempt:
    """One object's candidates, what became of each, and the placement (None when no candidate passed)."""

    candidates_xy: np.ndarray
    rejected_by: np.ndarray
    placement: Placement | None


def place_one(scene: PlacementScene, asset_index: int, obj: Placeable, rng: np.random.Generator,
              placed_xy: np.ndarray, report: dict[str, int]) -> ObjectAttempt:
    """Sample candidates for one object and keep the first (in sampling order) passing every rule.

    Candidates past the cheap pre-filters are stood on the ground and checked in chunks of ``CHUNK``, so
    later chunks are only evaluated when needed; the survivors not chosen are marked ``unused``.
    """
    wlh = np.asarray(obj.wlh, dtype=np.float64)
    cands = sample_candidates(scene, wlh, rng)
    tally = RuleTally(len(cands.xy), report)
    alive = prefilter(scene, cands, tally)
    for start in range(0, len(alive), CHUNK):
        stood = stand_candidates(scene, cands, alive[start:start + CHUNK], wlh)
        survivors = check_stood(scene, stood, wlh, placed_xy, tally)
        if len(survivors.alive):
            j = survivors.alive[0]
            tally.rejected_by[stood.index[survivors.alive[1:]]] = "unused"
            tally.rejected_by[alive[start + CHUNK:]] = "unused"  # passed the pre-filters, not evaluated further
            placement = make_placement(scene, asset_index, obj, wlh, cands, stood, j, survivors.visible_fraction[0])
            return ObjectAttempt(cands.xy, tally.rejected_by, placement)
    return ObjectAttempt(cands.xy, tally.rejected_by, None)


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


def place_objects(
    sample: Sample,
    view: CameraView,
    objects: Sequence[Placeable],
    rng: np.random.Generator,
    config: PlacementConfig = PlacementConfig(),
    depth_m: np.ndarray | None = None,
) -> PlacementResult:
    """Place ``objects`` (assets, or :class:`ObjectBox` sizes and categories) in ``view`` of ``sample``.

    Deterministic for a given ``rng`` state. ``config.n_objects`` is not used here: the caller passes
    the objects. Each placement names its object by ``asset_index`` (objects that found no place are
    left out).

    Args:
        depth_m: (H, W) float32 the scene depth of ``view`` (camera z, metres, inf = unknown) the
            renderer will test against; None computes the same (:func:`scene_depth`).
    """
    check_objects(objects)
    report = {name: 0 for name in RULE_ORDER}
    drivable, reason = drivable_area_for_sample(sample, view, config)
    if drivable is None:
        return PlacementResult([], report, reason, config=config)
    scene = PlacementScene.of(sample, view, config, drivable, depth_m)
    placements: list[Placement] = []
    attempts = []
    for i, obj in enumerate(objects):
        placed_xy = np.array([p.footprint_xy for p in placements]).reshape(-1, 4, 2)
        attempt = place_one(scene, i, obj, rng, placed_xy, report)
        attempts.append(attempt)
        if attempt.placement is not None:
            placements.append(attempt.placement)
    reason = None
    if len(placements) < len(objects):
        worst = ", ".join(f"{k}: {v}" for k, v in report.items() if v)
        reason = (f"placed {len(placements)} of {len(objects)} objects: no candidate passed every rule "
                  f"({len(objects) * config.n_candidates} candidates; rejected by {worst})")
    return PlacementResult(placements, report, reason, np.concatenate([a.candidates_xy for a in attempts]),
                           np.concatenate([a.rejected_by for a in attempts]), drivable, config)


__all__ = [
    "CHUNK", "RULE_ORDER", "ChunkSurvivors", "ObjectAttempt", "ObjectBox", "Placeable", "Placement", "PlacementResult",
    "RuleTally", "check_objects", "check_stood", "make_placement", "place_objects", "place_one", "prefilter",
]
