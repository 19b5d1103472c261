"""Re-check final placements against every rule, independently of :mod:`streetaug.placement.rules`.

The audit starts from what a user gets, the labelled 3D box (``Placement.box``: centre, wlh, rotation),
and re-derives each rule with different code: the footprint is the exact convex hull of the box's 8
corners in global x/y (not the rules' bounding rectangle), distances are shapely polygon/point
distances with round (Minkowski) margins, points in annotated boxes are tested per box in its frame,
the in-view fraction is an OpenCV convex-polygon intersection, and grid drivable areas are checked
cell by cell with shapely. The rules are at least as strict as these definitions, so every final
placement must pass every check: the benchmark counts the ones that do not.

Not re-derived here: the occlusion part of ``in_view`` (the share of the box hidden behind nearer LiDAR
returns); the benchmark checks it through the renderer's own depth test (``visible_fraction`` of the
rendered object).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np
import shapely

from streetaug.augment.core import quat_to_rotation, transform_points
from streetaug.datasets.nuscenes_format import LIDARSEG_GROUND, LIDARSEG_NON_DRIVABLE, VEHICLE_PARKED
from streetaug.datasets.sample import Box, CameraView, Sample

from .class_rules import ClassRule, ClassRules, read_class_rules
from .config import PlacementConfig
from .drivable import MAP_SOURCES, DrivableArea
from .parking import parked_gap_m
from .place import OFF_ROAD_ZONES, Placement
from .zones import CLUSTER_TAPER_M, ROAD_EDGE_BAND_M, SurfaceZones, surface_zones

AUDITED_RULES = ("surface", "distance", "annotated_boxes", "lidar_obstacles", "lidarseg", "in_view",
                 "corners_unoccluded", "mutual_collision")


@dataclass(frozen=True)
class Audit:
    """Outcome of re-checking one placement.

    Attributes:
        passed: rule name -> whether the placement satisfies it (rules that do not apply are absent).
        measured: the quantities the checks compared (metres, counts, fractions), for reports.
    """

    passed: dict[str, bool] = field(default_factory=dict)
    measured: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return all(self.passed.values())


def box_hull_xy(box: Box) -> shapely.Polygon:
    """Shapely polygon: the convex hull of the box's 8 corners in global x/y (its vertical projection)."""
    return shapely.convex_hull(shapely.multipoints(box.corners()[:, :2]))


def _points_in_any_box(points: np.ndarray, boxes: Sequence[Box], margin_m: float) -> np.ndarray:
    inside = np.zeros(len(points), dtype=bool)
    for b in boxes:
        local = (points - b.center) @ quat_to_rotation(b.rotation)  # rows: R^T p
        inside |= np.all(np.abs(local) <= np.asarray(b.wlh)[[1, 0, 2]] / 2 + margin_m, axis=1)
    return inside


def _grid_contains(area: DrivableArea, hull) -> bool:
    x0, y0, x1, y1 = hull.bounds
    res = area.resolution_m
    ox, oy = area.grid_origin_xy
    ix = np.arange(int(np.floor((x0 - ox) / res)), int(np.floor((x1 - ox) / res)) + 1)
    iy = np.arange(int(np.floor((y0 - oy) / res)), int(np.floor((y1 - oy) / res)) + 1)
    gx, gy = np.meshgrid(ix, iy)
    gx, gy = gx.ravel(), gy.ravel()
    cells = shapely.box(ox + gx * res, oy + gy * res, ox + (gx + 1) * res, oy + (gy + 1) * res)
    touched = shapely.area(shapely.intersection(cells, hull)) > 1e-9
    H, W = area.grid.shape
    in_grid = (gx >= 0) & (gx < W) & (gy >= 0) & (gy < H)
    drivable = np.zeros(len(gx), dtype=bool)
    drivable[in_grid] = area.grid[gy[in_grid], gx[in_grid]]
    return bool(np.all(drivable[touched]))


def _surface_ok(p: Placement, hull, rule: ClassRule, road, area: DrivableArea, zones: SurfaceZones,
                config: PlacementConfig) -> bool:
    """Whether the box's vertical projection ``hull`` lies in the placement's zone (shapely, own definitions)."""
    tol = 1e-6
    centre = shapely.Point(*p.box.center[:2])
    if p.zone in ("lane", "kerb"):
        grown = hull.buffer(rule.lane_margin_m) if p.zone == "lane" and rule.lane_margin_m > 0 else hull
        on_road = bool(road.contains(grown)) if road is not None else _grid_contains(area, grown)
        if p.zone == "lane":
            return on_road
        edge = hull.distance(road.boundary) if road is not None else float(area.edge_distance(p.footprint_xy[None])[0])
        return on_road and edge <= config.kerb_distance_m + tol
    if p.zone == "crossing":
        return zones.crossings is not None and bool(zones.crossings.buffer(0.3 + tol).contains(hull))
    if road is not None:
        d_centre = centre.distance(road.boundary) * (1.0 if road.contains(centre) else -1.0)
    else:
        d_centre = float(zones.signed_distance(p.box.center[None, :2])[0])
    if p.zone == "road_edge":
        taper = CLUSTER_TAPER_M if p.cluster_of >= 0 else 0.0
        return ROAD_EDGE_BAND_M[0] - tol <= d_centre <= ROAD_EDGE_BAND_M[1] + taper + tol
    if p.zone == "sidewalk":
        if road is not None:
            if road.intersects(hull) or hull.distance(road) < rule.sidewalk_band_m[0] - 1e-3:
                return False
            far = max(shapely.Point(*xy).distance(road) for xy in np.asarray(hull.exterior.coords))
        else:
            s = zones.signed_distance(np.asarray(hull.exterior.coords)[:, :2])
            if np.any(s > -rule.sidewalk_band_m[0] + 1e-3):
                return False
            far = float(-s.min())
        if zones.walkway is not None:
            return bool(zones.walkway.buffer(tol).contains(hull))
        if zones.lidarseg_sidewalks is not None:
            return bool(zones.on_lidarseg_sidewalk(np.asarray(hull.exterior.coords)[:, :2]).all())
        return far <= rule.sidewalk_band_m[1] + 1e-3
    return False


def _inside_fraction_cv(corners_cam: np.ndarray, K: np.ndarray, width: int, height: int) -> float:
    uv = corners_cam @ K.T
    uv = (uv[:, :2] / uv[:, 2:]).astype(np.float32)
    hull = cv2.convexHull(uv)
    area = cv2.contourArea(hull)
    if area <= 0:
        return 0.0
    image = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]],
                     np.float32)
    inter, _ = cv2.intersectConvexConvex(hull, image)
    return float(inter / area)


def _top_corners_occluded(corners_cam: np.ndarray, points_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                          tolerance_m: float, spread_px: int = 3) -> bool:
    """Whether any top corner has a LiDAR point within ``spread_px`` pixels nearer by > tolerance."""
    pts = points_cam[points_cam[:, 2] > 0.1]
    uv = pts @ K.T
    pu, pv = np.round(uv[:, 0] / uv[:, 2]), np.round(uv[:, 1] / uv[:, 2])
    for c in corners_cam[[0, 1, 4, 5]]:
        if c[2] <= 0:
            continue
        u, v = np.round(K[0, 0] * c[0] / c[2] + K[0, 2]), np.round(K[1, 1] * c[1] / c[2] + K[1, 2])
        if not (0 <= u < width and 0 <= v < height):
            continue
        near = (np.abs(pu - u) <= spread_px) & (np.abs(pv - v) <= spread_px) & (pu >= 0) & (pu < width) \
            & (pv >= 0) & (pv < height)
        if np.any(pts[near, 2] < c[2] - tolerance_m):
            return True
    return False


def audit_placements(sample: Sample, view: CameraView, placements: Sequence[Placement], drivable: DrivableArea,
                     config: PlacementConfig, class_rules: ClassRules | None = None) -> list[Audit]:
    """Re-check each of ``placements`` (one image's :class:`Placement` list) against every rule.

    Each placement is checked with its class's thresholds (``class_rules``, default the built-in table) and
    its zone; cluster members may be as close to their mates as the cluster's gap allows.

    Args:
        sample, view: where they were placed.
        drivable: the drivable area the placement used (``PlacementResult.drivable``).
        config: the thresholds used.
    """
    rules = class_rules or read_class_rules()
    base_config = config
    zones = surface_zones(sample, view, drivable, config) if drivable is not None else None
    cam_xy = view.T_global_from_cam[:2, 3]
    boxes = list(sample.boxes)
    box_hulls = [box_hull_xy(b) for b in boxes]
    lidar = sample.lidar
    points = lidar.points_global if lidar is not None else np.zeros((0, 3))
    labels = lidar.labels if lidar is not None else None
    free = points[~_points_in_any_box(points, boxes, 0.1)]
    non_drivable = points[np.isin(labels, LIDARSEG_NON_DRIVABLE)] if labels is not None else np.zeros((0, 3))
    road = None
    if drivable is not None and drivable.source in MAP_SOURCES:
        road = shapely.union_all(shapely.make_valid(np.asarray(sample.drivable_area_global, dtype=object)))
    free_pts = shapely.points(free[:, :2])
    non_drivable_pts = shapely.points(non_drivable[:, :2])
    hulls = [box_hull_xy(p.box) for p in placements]
    out = []
    non_ground = points[np.isin(labels, LIDARSEG_NON_DRIVABLE) & ~np.isin(labels, LIDARSEG_GROUND)] \
        if labels is not None else np.zeros((0, 3))
    non_ground_pts = shapely.points(non_ground[:, :2])
    mutual = [rules.classes[p.detection_class].config(base_config).mutual_clearance_m for p in placements]
    parking_gap = parked_gap_m(boxes, base_config.static_clearance_m)
    for i, (p, hull) in enumerate(zip(placements, hulls)):
        passed, measured = {}, {}
        rule = rules.classes[p.detection_class]
        config = rule.config(base_config)
        # surface: the whole vertical projection of the box in its class's zone
        passed["surface"] = _surface_ok(p, hull, rule, road, drivable, zones, config)
        if p.zone in OFF_ROAD_ZONES:
            passed["surface"] &= p.ground_source != "ego-plane"
        # distance camera -> box centre
        d = float(np.hypot(*(p.box.center[:2] - cam_xy)))
        measured["distance_m"] = d
        passed["distance"] = config.min_distance_m <= d <= config.max_distance_m
        # annotated boxes by class
        # (a car parking by the kerb as the scene's do keeps only the parking gap from parked vehicles)
        beside = [p.zone == "kerb" and rule.zone_weights == "scene" and VEHICLE_PARKED in b.attributes for b in boxes]
        gaps_dyn = [hull.distance(h) for b, h, x in zip(boxes, box_hulls, beside) if b.is_dynamic and not x]
        gaps_sta = [hull.distance(h) for b, h, x in zip(boxes, box_hulls, beside) if not b.is_dynamic and not x]
        gaps_parked = [hull.distance(h) for h, x in zip(box_hulls, beside) if x]
        measured["min_gap_dynamic_m"] = min(gaps_dyn, default=np.inf)
        measured["min_gap_static_m"] = min(gaps_sta, default=np.inf)
        measured["min_gap_parked_m"] = min(gaps_parked, default=np.inf)
        passed["annotated_boxes"] = (measured["min_gap_dynamic_m"] >= config.dynamic_clearance_m
                                     and measured["min_gap_static_m"] >= config.static_clearance_m
                                     and measured["min_gap_parked_m"] >= min(parking_gap, config.static_clearance_m))
        # unannotated LiDAR obstacles: height above the box's own ground plane, within the margin
        R = quat_to_rotation(p.box.rotation)
        bottom = p.box.center - 0.5 * p.wlh[2] * R[:, 2]
        if len(free):
            near = shapely.distance(hull, free_pts) <= config.static_clearance_m
            h = (free[near] - bottom) @ R[:, 2]
            n_obst = int(np.sum((h >= config.obstacle_min_height_m) & (h <= config.obstacle_max_height_m)))
        else:
            n_obst = 0
        measured["obstacle_points"] = n_obst
        passed["lidar_obstacles"] = n_obst <= config.obstacle_max_points
        if labels is not None:
            blocking, blocking_pts = (non_ground, non_ground_pts) if p.zone in OFF_ROAD_ZONES else \
                (non_drivable, non_drivable_pts)
            n_seg = int(np.sum(shapely.distance(hull, blocking_pts) <= config.static_clearance_m)) \
                if len(blocking) else 0
            measured["non_drivable_points"] = n_seg
            passed["lidarseg"] = n_seg <= config.lidarseg_max_points
        # in view
        corners_cam = transform_points(view.T_cam_from_global, p.box.corners())
        in_front = bool(np.all(corners_cam[:, 2] >= config.near_plane_m - 1e-9))
        frac = _inside_fraction_cv(corners_cam, view.K, view.width, view.height) if in_front else 0.0
        measured["inside_fraction"] = frac
        passed["in_view"] = in_front and frac >= config.min_visible_fraction - 1e-4
        if config.require_unoccluded_corners and len(points):
            passed["corners_unoccluded"] = not _top_corners_occluded(
                corners_cam, transform_points(view.T_cam_from_global, points), view.K, view.width, view.height,
                config.occlusion_tolerance_m)
        # other objects inserted into the same image
        cluster = p.cluster_of if p.cluster_of >= 0 else i
        mates = {j for j, q in enumerate(placements) if j == cluster or q.cluster_of == cluster}
        others = [(hull.distance(h), max(mutual[i], mutual[j])) for j, h in enumerate(hulls)
                  if j != i and j not in mates]
        measured["min_gap_inserted_m"] = min((g for g, _ in others), default=np.inf)
        passed["mutual_collision"] = all(g >= need for g, need in others) and all(
            hull.distance(hulls[j]) > 0 for j in mates if j != i)
        out.append(Audit(passed, measured))
    return out
