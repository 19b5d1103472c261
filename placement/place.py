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
(:func:`box_footprint_rect`), so a final placement satisfies each rule as labelled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from streetaug.augment.core import rotation_to_quat, transform_points
from streetaug.augment.core import InputError
from streetaug.datasets.sample import Box, CameraView, Sample

from .config import LIDARSEG_NON_DRIVABLE, PlacementConfig
from .drivable import DrivableArea, drivable_area_for_sample
from .ground import LocalGroundFitter
from .rules import (
    box_corners_object,
    box_footprint_rect,
    box_footprints,
    footprint_corners,
    points_in_boxes,
    lidar_depth_image,
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

_CHUNK = 48  # candidates stood on the ground and checked per round (the first survivor wins)

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


@dataclass(frozen=True)
class Placement:
    """One placed object.

    Attributes:
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
    """

    T_global_from_object: np.ndarray
    box: Box
    wlh: np.ndarray
    ground_normal_global: np.ndarray
    ground_source: str
    drivable_source: str
    drivable_confidence: str = ""
    attribute: str = "vehicle.moving"
    distance_m: float = float("nan")
    edge_distance_m: float = float("nan")
    yaw_source: str = "ego"
    footprint_xy: np.ndarray | None = None

    def T_cam_from_object(self, view: CameraView) -> np.ndarray:
        """(4, 4) object -> camera frame of ``view``."""
        return view.T_cam_from_global @ self.T_global_from_object


@dataclass(frozen=True)
class PlacementResult:
    """Outcome of :func:`place_objects`.

    Attributes:
        placements: the placed objects (possibly fewer than requested, possibly none).
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


def object_transforms(
    bottom_xy: np.ndarray, yaw_rad: np.ndarray, ground_z: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """T_global_from_object (N, 4, 4) for objects standing on planes.

    Args:
        bottom_xy: (N, 2) global x/y of the bottom centre.
        yaw_rad: (N,) heading in the global x/y plane (rad, from +x towards +y).
        ground_z: (N,) ground height at bottom_xy.
        normals: (N, 3) unit ground normals (z > 0); become the object's +z.
    """
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    h = np.stack([np.cos(yaw_rad), np.sin(yaw_rad), np.zeros_like(yaw_rad)], axis=1)
    x = h - np.einsum("nd,nd->n", h, n)[:, None] * n
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(n, x)
    T = np.tile(np.eye(4), (len(n), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x, y, n
    T[:, :3, 3] = np.concatenate([bottom_xy, np.asarray(ground_z).reshape(-1, 1)], axis=1)
    return T


def _check_wlhs(wlhs: Sequence[np.ndarray]) -> list[np.ndarray]:
    out = []
    for i, wlh in enumerate(wlhs):
        a = np.asarray(wlh, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
            raise InputError(f"place_objects: wlhs[{i}] must be 3 positive finite sizes [w, l, h] in metres, got {a.tolist()}")
        out.append(a)
    return out


def _camera_azimuth_range(view: CameraView) -> tuple[float, float, float]:
    """(heading of the camera's optical axis in global x/y, max angle to the left, max angle to the right)."""
    fwd = view.T_global_from_cam[:3, 2]
    if np.hypot(fwd[0], fwd[1]) < 1e-3:
        raise InputError(f"camera {view.channel}: optical axis is vertical; cannot place objects on the ground")
    base = float(np.arctan2(fwd[1], fwd[0]))
    fx, cx = view.K[0, 0], view.K[0, 2]
    left = float(np.arctan((cx + 0.5) / fx))
    right = float(np.arctan((view.width - 0.5 - cx) / fx))
    return base, left, right


def place_objects(
    sample: Sample,
    view: CameraView,
    wlhs: list[np.ndarray],
    rng: np.random.Generator,
    config: PlacementConfig = PlacementConfig(),
    categories: Sequence[str] | None = None,
) -> PlacementResult:
    """Place ``len(wlhs)`` objects (sizes [w, l, h] in metres) in ``view`` of ``sample``.

    Deterministic for a given ``rng`` state. ``config.n_objects`` is not used here: the caller passes
    one size per object. ``categories`` (one per object, default ``vehicle.car``) name the boxes.
    """
    wlhs = _check_wlhs(wlhs)
    categories = list(categories) if categories is not None else ["vehicle.car"] * len(wlhs)
    if len(categories) != len(wlhs):
        raise InputError(f"place_objects: {len(categories)} categories for {len(wlhs)} objects")
    report = {name: 0 for name in RULE_ORDER}
    drivable, reason = drivable_area_for_sample(sample, view, config)
    if drivable is None:
        return PlacementResult([], report, reason, config=config)

    T_cam_from_global = view.T_cam_from_global
    cam_xy = view.T_global_from_cam[:2, 3]
    base, left, right = _camera_azimuth_range(view)
    R_ego = view.T_global_from_ego[:3, :3]
    yaw_ego = float(np.arctan2(R_ego[1, 0], R_ego[0, 0]))

    boxes = list(sample.boxes)
    box_fp = box_footprints(boxes)
    box_dyn = np.array([b.is_dynamic for b in boxes], dtype=bool)
    lidar = sample.lidar
    if lidar is not None:
        points = lidar.points_global
        labels = lidar.labels
        free = ~points_in_boxes(points, boxes, margin_m=0.1)
        obstacle_pts = points[free]
        if labels is not None:
            non_drivable_xy = points[np.isin(labels, LIDARSEG_NON_DRIVABLE)][:, :2]
            fitter = LocalGroundFitter(obstacle_pts, view.T_global_from_ego, labels[free], config)
        else:
            non_drivable_xy = np.zeros((0, 2))
            fitter = LocalGroundFitter(obstacle_pts, view.T_global_from_ego, None, config)
    else:
        points, labels = None, None
        obstacle_pts, non_drivable_xy = np.zeros((0, 3)), np.zeros((0, 2))
        fitter = LocalGroundFitter(None, view.T_global_from_ego, None, config)
    depth_m = None  # sparse scene depth from LiDAR: what hides a candidate (in_view, corners_unoccluded)
    if points is not None:
        depth_m = lidar_depth_image(transform_points(T_cam_from_global, points), view.K, view.width, view.height)

    lanes = sample.lanes if config.use_lanes else None
    placements: list[Placement] = []
    all_xy, all_rej = [], []
    placed_fp = np.zeros((0, 4, 2))
    n = config.n_candidates
    for wlh, category in zip(wlhs, categories):
        w, l, h = wlh
        r = rng.uniform(config.min_distance_m, config.max_distance_m, n)
        az = base + rng.uniform(-right, left, n)
        flip = rng.random(n) < config.opposite_heading_probability
        noise = np.radians(rng.normal(0.0, config.yaw_sigma_deg, n))
        xy = cam_xy + r[:, None] * np.stack([np.cos(az), np.sin(az)], axis=1)
        heading = yaw_ego + np.pi * flip
        on_lane = np.zeros(n, dtype=bool)
        if lanes is not None:
            lane_heading, on_lane = lanes.heading_at(xy, config.lane_max_distance_m)
            heading = np.where(on_lane, lane_heading, heading)
        yaw = np.mod(heading + noise + np.pi, 2 * np.pi) - np.pi
        corners = footprint_corners(xy, yaw, l, w)
        rejected = np.full(n, "", dtype=object)

        def apply(name: str, idx: np.ndarray, ok: np.ndarray) -> np.ndarray:
            """Record the rejections of rule ``name`` among candidates ``idx``; return the survivors."""
            rejected[idx[~ok]] = name
            report[name] += int((~ok).sum())
            return idx[ok]

        # cheap vectorised pre-filters on the flat footprints of all candidates
        alive = apply("drivable", np.arange(n), rule_drivable(drivable, corners))
        alive = apply("annotated_boxes", alive, rule_box_clearance(
            corners[alive], box_fp, box_dyn, config.dynamic_clearance_m, config.static_clearance_m))
        # then, in sampling order and in chunks (the first survivor wins, so later chunks are only
        # evaluated when needed): stand each candidate on its local ground and apply every rule to the
        # box as placed (footprint of the tilted box, its corners in the camera)
        chosen = None
        for start in range(0, len(alive), _CHUNK):
            idx = alive[start:start + _CHUNK]
            planes = [fitter.fit(p) for p in xy[idx]]
            g_point = np.array([p.point_global for p in planes]).reshape(-1, 3)
            g_normal = np.array([p.normal_global for p in planes]).reshape(-1, 3)
            T_go = object_transforms(xy[idx], yaw[idx], g_point[:, 2], g_normal)
            centers = T_go[:, :3, 3] + 0.5 * h * T_go[:, :3, 2]
            rect = box_footprint_rect(T_go, wlh)
            T_co = T_cam_from_global[None] @ T_go
            corners_cam = np.einsum("nij,kj->nki", T_co[:, :3, :3], box_corners_object(wlh)) + T_co[:, None, :3, 3]
            k = np.arange(len(idx))  # positions in this chunk still alive

            def apply_k(name: str, ok: np.ndarray) -> np.ndarray:
                return k[np.isin(idx[k], apply(name, idx[k], ok))]

            k = apply_k("drivable", rule_drivable(drivable, rect[k]))
            k = apply_k("annotated_boxes", rule_box_clearance(
                rect[k], box_fp, box_dyn, config.dynamic_clearance_m, config.static_clearance_m))
            k = apply_k("distance", rule_distance(centers[k, :2], cam_xy, config.min_distance_m, config.max_distance_m))
            k = apply_k("lidar_obstacles", rule_obstacles(
                rect[k], g_point[k], g_normal[k], obstacle_pts, config.static_clearance_m,
                config.obstacle_min_height_m, config.obstacle_max_height_m, config.obstacle_max_points))
            k = apply_k("lidarseg", rule_lidarseg(rect[k], non_drivable_xy, config.static_clearance_m,
                                                  config.lidarseg_max_points))
            visible = visible_fraction_estimate(T_co[k], wlh, view.K, view.width, view.height, depth_m,
                                                config.occlusion_tolerance_m)
            k = apply_k("in_view", rule_in_view(corners_cam[k], view.K, view.width, view.height,
                                                config.min_visible_fraction, config.near_plane_m, visible))
            if config.require_unoccluded_corners and depth_m is not None:
                k = apply_k("corners_unoccluded", rule_corners_unoccluded(
                    corners_cam[k], view.K, depth_m, config.occlusion_tolerance_m))
            k = apply_k("mutual_collision", rule_mutual(rect[k], placed_fp, config.mutual_clearance_m))
            if len(k):
                j = k[0]
                chosen = (idx[j], T_go[j], centers[j], rect[j], g_normal[j], planes[j].source)
                rejected[idx[k[1:]]] = "unused"
                rejected[alive[start + _CHUNK:]] = "unused"  # passed the pre-filters, not evaluated further
                break

        if chosen is not None:
            i, T, center, fp, normal, g_source = chosen
            box = Box(center.copy(), wlh.copy(), rotation_to_quat(T[:3, :3]), category)
            edge = float(drivable.edge_distance(fp[None])[0])
            placements.append(Placement(
                T_global_from_object=T,
                box=box,
                wlh=wlh.copy(),
                ground_normal_global=normal.copy(),
                ground_source=str(g_source),
                drivable_source=drivable.source,
                drivable_confidence=drivable.confidence,
                attribute="vehicle.parked" if edge <= config.kerb_distance_m else "vehicle.moving",
                distance_m=float(np.linalg.norm(center[:2] - cam_xy)),
                edge_distance_m=edge,
                yaw_source="lane" if on_lane[i] else "ego",
                footprint_xy=fp.copy(),
            ))
            placed_fp = np.concatenate([placed_fp, fp[None]])
        all_xy.append(xy)
        all_rej.append(rejected)

    if len(placements) == len(wlhs):
        reason = None
    else:
        worst = ", ".join(f"{k}: {v}" for k, v in report.items() if v)
        reason = (f"placed {len(placements)} of {len(wlhs)} objects: no candidate passed every rule "
                  f"({len(wlhs) * n} candidates; rejected by {worst})")
    return PlacementResult(placements, report, reason, np.concatenate(all_xy), np.concatenate(all_rej), drivable,
                           config)
