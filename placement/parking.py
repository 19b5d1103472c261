"""How a sample's own vehicles park, for the kerb zone: how often a class parks, and how it stands at the road edge.

Two statistics of the annotated boxes of one sample, per detection class, so a placement follows the street it
is in rather than one table for every city:

* the **parked share** (:func:`parked_share`): of the class's boxes with a vehicle attribute, the share that is
  ``vehicle.parked`` (``moving`` and ``stopped`` ones are in a lane). :func:`with_parked_share` turns it into the
  weights of a rule's ``lane`` and ``kerb`` zones, with the rule's own split as a prior worth
  ``PRIOR_OBJECTS`` boxes (a sample without such boxes keeps the table's weights);
* the **parking style** (:class:`ParkingStyle`): each parked box's heading against the road edge and its
  centre's signed distance to it (a row of cars in perpendicular bays stands at 90 deg, 2.5 m in; kerb-side
  parking at 0 or 180 deg, about 1 m in). A kerb candidate takes the style of the nearest parked box within
  ``STYLE_REACH_M`` (:func:`kerb_poses`); without one it stands along the edge;
* the **row** (:func:`row_neighbour`): a kerb candidate standing in the row of a parked box (the gap between them at
  most one car length) takes that box's heading, the full direction, nose-in or nose-out as it stands. The style
  alone, measured against the edge's local tangent, turned cars round where that tangent turns between two cars of
  one row: on scene-0916 only 42 % of the kerb cars stood within 30 deg of their nearest parked neighbour's heading
  (its annotated parked cars: 80 %), 85 % with the row (``benchmarks/bench_placement_views.py``);
* the **parking gap** (:func:`parked_gap_m`): how close parked vehicles stand to their nearest parked neighbour
  (scene-0916's bays: median 0.76 m); a kerb placement keeps that from parked vehicles, not the clearance from
  moving things.

Angles: ``yaw_to_edge_rad`` is the heading minus the direction of the edge tangent
(:meth:`~streetaug.placement.zones.SurfaceZones.edge_tangent`: the road on its left), in (-pi, pi]; signed
distances are + on the road (:meth:`~streetaug.placement.zones.SurfaceZones.signed_distance`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from streetaug.datasets.nuscenes_format import VEHICLE_MOVING, VEHICLE_PARKED, VEHICLE_STOPPED
from streetaug.datasets.sample import Box

from .class_rules import ClassRule
from .rules import box_corners, box_transform, footprint_corners
from .zones import SurfaceZones

PRIOR_OBJECTS = 2.0  # weight of the class table's lane/kerb split, in annotated boxes
STYLE_REACH_M = 30.0  # a kerb candidate takes the style of a parked box at most this far away
STYLE_MAX_ROI_FRACTION = 0.8  # parked boxes beyond this fraction of the map's clip radius are not measured
KERB_INSET_M = 0.05  # a styled footprint is moved this far inside the road edge (the kerb zone is on the road)
PARKED_GAP_QUANTILE = 0.25  # of the parked vehicles' gaps to their nearest parked neighbour: a kerb car's clearance
MIN_PARKED_GAP_M = 0.3
MIN_PARKED_FOR_GAP = 3


def _yaw(box: Box) -> float:
    R = box_transform(box)
    return float(np.arctan2(R[1, 0], R[0, 0]))


def _wrap(angle_rad: np.ndarray) -> np.ndarray:
    return np.mod(np.asarray(angle_rad, float) + np.pi, 2 * np.pi) - np.pi


def parked_share(boxes: Sequence[Box], categories: set[str]) -> tuple[int, int]:
    """(parked, with a vehicle attribute) counts of the boxes whose category is in ``categories``."""
    states = [a for b in boxes if b.category in categories for a in b.attributes
              if a in (VEHICLE_PARKED, VEHICLE_MOVING, VEHICLE_STOPPED)]
    return sum(a == VEHICLE_PARKED for a in states), len(states)


def with_parked_share(rule: ClassRule, n_parked: int, n_vehicles: int) -> ClassRule:
    """``rule`` with its ``lane`` / ``kerb`` weights split as ``(n_parked + PRIOR_OBJECTS p0) / (n_vehicles +
    PRIOR_OBJECTS)`` (p0 = the rule's own kerb share of the two; their sum kept). Unchanged unless the rule has
    ``zone_weights: scene`` and both zones."""
    z = rule.zones
    if rule.zone_weights != "scene" or "lane" not in z or "kerb" not in z:
        return rule
    total = z["lane"] + z["kerb"]
    p = (n_parked + PRIOR_OBJECTS * z["kerb"] / total) / (n_vehicles + PRIOR_OBJECTS)
    return dataclasses.replace(rule, zones={**z, "lane": total * (1.0 - p), "kerb": total * p})


def parked_gap_m(boxes: Sequence[Box], static_clearance_m: float) -> float:
    """The clearance (m) a kerb placement keeps from parked vehicles: the ``PARKED_GAP_QUANTILE`` quantile of the
    footprint gaps of the sample's parked vehicles (any class) to their nearest parked neighbour, within
    [``MIN_PARKED_GAP_M``, ``static_clearance_m``]; ``static_clearance_m`` with fewer than ``MIN_PARKED_FOR_GAP``."""
    import shapely

    parked = [b for b in boxes if b.category.startswith("vehicle.") and VEHICLE_PARKED in b.attributes]
    if len(parked) < MIN_PARKED_FOR_GAP:
        return float(static_clearance_m)
    polys = shapely.polygons(np.stack([box_corners(b)[[0, 1, 5, 4], :2] for b in parked]))
    d = shapely.distance(polys[:, None], polys[None, :])  # (P, P); tens of boxes
    np.fill_diagonal(d, np.inf)
    gap = float(np.quantile(d.min(axis=1), PARKED_GAP_QUANTILE))
    return float(np.clip(gap, MIN_PARKED_GAP_M, static_clearance_m))


@dataclass(frozen=True)
class ParkingStyle:
    """How the parked boxes of one class stand at the road edge (see the module docstring).

    Attributes:
        xy: (P, 2) float64 the centres of those by the edge, global x/y (m).
        yaw_to_edge_rad: (P,) heading minus the edge tangent's direction at the centre, (-pi, pi].
        centre_edge_m: (P,) signed distance of the centre to the road edge (m, + on the road).
        row_xy: (Q, 2) float64 the centres of every parked box of the class in range (by an edge or not), global x/y.
        row_yaw_rad: (Q,) their headings (rad, global, the full direction: nose-in and nose-out differ by pi).
        row_wl: (Q, 2) their widths and lengths (m). A kerb candidate in their row takes the heading of its row
            neighbour (:func:`row_neighbour`).
    """

    xy: np.ndarray
    yaw_to_edge_rad: np.ndarray
    centre_edge_m: np.ndarray
    row_xy: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    row_yaw_rad: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    row_wl: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))


def row_neighbour(style: ParkingStyle, xy: np.ndarray, length_m: float, width_m: float) -> np.ndarray:
    """(N,) int the parked box (index into ``style.row_*``) whose row each candidate at ``xy`` (N, 2) stands in, -1
    for none.

    A candidate of ``length_m`` x ``width_m`` standing as parked box j does (its heading) is in j's row when the gap
    between their boxes, along and across j's heading (the larger of the two), is at most one candidate length: beside
    it with a free bay or two of a perpendicular row between, or nose to tail with one free bay of a parallel row; not
    across an aisle or a road, which are wider than a car is long. Of several, the nearest by centre distance.
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    out = np.full(len(xy), -1, dtype=np.int64)
    if len(style.row_xy) == 0 or len(xy) == 0:
        return out
    d = xy[:, None] - style.row_xy[None]  # (N, Q, 2)
    c, s = np.cos(style.row_yaw_rad), np.sin(style.row_yaw_rad)
    along = np.abs(d[..., 0] * c + d[..., 1] * s)  # (N, Q) along j's heading
    across = np.abs(-d[..., 0] * s + d[..., 1] * c)
    w_j, l_j = style.row_wl[:, 0], style.row_wl[:, 1]
    gap = np.maximum(along - (l_j + length_m) / 2, across - (w_j + width_m) / 2)
    dist = np.where(gap <= length_m, np.hypot(along, across), np.inf)
    j = dist.argmin(axis=1)
    found = np.isfinite(dist[np.arange(len(xy)), j])
    out[found] = j[found]
    return out


def parking_style(zones: SurfaceZones, boxes: Sequence[Box], categories: set[str], camera_xy: np.ndarray,
                  roi_m: float, kerb_distance_m: float) -> ParkingStyle | None:
    """The style of the ``vehicle.parked`` boxes of ``categories`` within ``STYLE_MAX_ROI_FRACTION`` x ``roi_m``
    of the camera whose footprint comes within ``kerb_distance_m`` + 0.5 m of the road edge (those the kerb zone
    can imitate; a car in the middle of a car park is not at a kerb). None when there is none."""
    parked = [b for b in boxes if b.category in categories and VEHICLE_PARKED in b.attributes
              and np.hypot(*(b.center[:2] - camera_xy)) <= STYLE_MAX_ROI_FRACTION * roi_m]
    if not parked:
        return None
    xy = np.array([b.center[:2] for b in parked], float)
    yaw = np.array([_yaw(b) for b in parked])
    wl = np.array([b.wlh[:2] for b in parked], float)
    fp = np.stack([footprint_corners(c[None], np.array([y]), float(b.wlh[1]), float(b.wlh[0]))[0]
                   for c, y, b in zip(xy, yaw, parked)])  # (P, 4, 2); tens of boxes
    s_min = zones.signed_distance(fp.reshape(-1, 2)).reshape(-1, 4).min(axis=1)
    near = s_min <= kerb_distance_m + 0.5
    t = zones.edge_tangent(xy[near]) if near.any() else np.zeros((0, 2))
    rel = _wrap(yaw[near] - np.arctan2(t[:, 1], t[:, 0]))
    return ParkingStyle(xy[near], rel, zones.signed_distance(xy[near]) if near.any() else np.zeros(0), xy, yaw, wl)


def kerb_poses(zones: SurfaceZones, style: ParkingStyle | None, xy: np.ndarray, heading_rad: np.ndarray,
               length_m: float, width_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kerb poses of candidates at ``xy`` (N, 2): (xy (N, 2), heading (N,) rad, styled (N,) bool).

    A candidate with a parked box by the edge within ``STYLE_REACH_M`` takes the style of the nearest one (its
    heading against the edge, its centre's distance in from the edge), then moves inwards until its footprint is
    ``KERB_INSET_M`` inside the road (styled). The others keep their place and stand along the edge, in whichever of
    its two directions is nearer to ``heading_rad`` (N,) (the lane's, or the ego's or its opposite). Then a
    candidate standing in the row of a parked box (:func:`row_neighbour`, at its styled place) takes that box's
    heading, the full direction (nose-in or nose-out as its neighbour; the edge's tangent, which the style is
    measured against, can turn round between two cars of one row where the edge bends), and is styled too.
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    normal = zones.road_normal(xy)
    tangent = np.c_[-normal[:, 1], normal[:, 0]]  # zones.edge_tangent(xy), from the same normal
    edge_yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
    along = np.where(np.cos(np.asarray(heading_rad, float) - edge_yaw) >= 0, edge_yaw, edge_yaw + np.pi)
    out_xy, out_yaw = xy.copy(), _wrap(along)
    styled = np.zeros(len(xy), dtype=bool)
    if style is None or len(xy) == 0:
        return out_xy, out_yaw, styled
    if len(style.xy):
        d = np.linalg.norm(xy[:, None] - style.xy[None], axis=2)  # (N, P)
        j = d.argmin(axis=1)
        styled = d[np.arange(len(xy)), j] <= STYLE_REACH_M
        s = zones.signed_distance(xy)
        moved = xy + (style.centre_edge_m[j] - s)[:, None] * normal
        yaw = _wrap(edge_yaw + style.yaw_to_edge_rad[j])
        moved = moved + _inset(zones, moved, yaw, length_m, width_m)[:, None] * normal
        out_xy[styled], out_yaw[styled] = moved[styled], yaw[styled]
    row = row_neighbour(style, out_xy, length_m, width_m)
    rowed = row >= 0
    if rowed.any():
        yaw = style.row_yaw_rad[row[rowed]]
        n = zones.road_normal(out_xy[rowed])
        out_xy[rowed] = out_xy[rowed] + _inset(zones, out_xy[rowed], yaw, length_m, width_m)[:, None] * n
        out_yaw[rowed] = _wrap(yaw)
        styled = styled | rowed
    return out_xy, out_yaw, styled


def _inset(zones: SurfaceZones, xy: np.ndarray, yaw: np.ndarray, length_m: float, width_m: float) -> np.ndarray:
    """(N,) how far (m) to move footprints at ``xy`` (N, 2) with ``yaw`` (N,) along the road normal so that they are
    ``KERB_INSET_M`` inside the road (0 for those already are)."""
    fp = footprint_corners(xy, yaw, length_m, width_m)
    s_corner = zones.signed_distance(fp.reshape(-1, 2)).reshape(-1, 4).min(axis=1)
    return np.maximum(KERB_INSET_M - s_corner, 0.0)


__all__ = ["KERB_INSET_M", "MIN_PARKED_GAP_M", "PRIOR_OBJECTS", "parked_gap_m", "ParkingStyle", "STYLE_REACH_M", "kerb_poses", "parked_share",
           "parking_style", "row_neighbour", "with_parked_share"]
