"""The surfaces objects of each class stand on, around one camera: lane, kerb, road edge, sidewalk, crossing.

Everything is measured against the drivable area (:class:`DrivableArea`) with a signed distance to its edge,
``s`` (metres, positive on the road, negative off it):

* ``lane``: the footprint grown by the class's ``lane_margin_m`` is on the road.
* ``kerb``: the footprint is on the road, within ``kerb_distance_m`` of its edge (parked).
* ``road_edge``: the footprint's centre has ``s`` in ``ROAD_EDGE_BAND_M`` (straddling the edge; partly on the road).
* ``sidewalk``: the footprint is off the road and on a map ``walkway`` when the map has that layer, else where the
  nearest static lidarseg point is ``flat.sidewalk`` when the sweep is labelled, else in the band ``sidewalk_band_m`` off the
  road's edge (what a kerb-side pavement usually is; the LiDAR obstacle rule keeps walls and poles out).
* ``crossing``: the footprint is on a map ``ped_crossing``.

Off-road zones need a real road edge: a map or lidarseg drivable area (not the LiDAR-ground corridor, whose
edge is only the corridor's).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import shapely

from streetaug.augment.core import check_shape
from scipy.spatial import cKDTree

from streetaug.datasets.nuscenes_format import CATEGORY_NAMES, LIDARSEG_SIDEWALK
from streetaug.datasets.sample import CameraView, Sample

from .class_rules import ClassRule
from .config import PlacementConfig
from .drivable import DrivableArea, polygons_near

ROAD_EDGE_BAND_M = (-0.6, 1.0)  # centre's signed distance to the road edge of the road_edge zone
CLUSTER_TAPER_M = 2.0  # members of a line (a work zone's taper) may reach this much farther into the road
LIDARSEG_STATIC = tuple(i for i, n in enumerate(CATEGORY_NAMES) if n.startswith(("flat.", "static.")))


def grow_footprints(corners_xy: np.ndarray, margin_m: float) -> np.ndarray:
    """Footprints (N, 4, 2) (corner order of :func:`~streetaug.placement.rules.footprint_corners`) grown by
    ``margin_m`` on every side."""
    corners_xy = np.asarray(corners_xy, dtype=np.float64)
    if margin_m == 0 or len(corners_xy) == 0:
        return corners_xy
    ex = corners_xy[:, 0] - corners_xy[:, 3]  # length direction
    ey = corners_xy[:, 0] - corners_xy[:, 1]  # width direction
    ux = ex / np.maximum(np.linalg.norm(ex, axis=1, keepdims=True), 1e-9)
    uy = ey / np.maximum(np.linalg.norm(ey, axis=1, keepdims=True), 1e-9)
    sx = np.array([1, 1, -1, -1])[None, :, None]
    sy = np.array([1, -1, -1, 1])[None, :, None]
    return corners_xy + margin_m * (sx * ux[:, None] + sy * uy[:, None])


@dataclass(frozen=True, eq=False)
class SurfaceZones:
    """The zones of one camera's surroundings (global x/y).

    Attributes:
        drivable: the road.
        walkway: the map's walkway polygons near the camera, or None.
        crossings: the map's pedestrian crossings near the camera, or None.
        lidarseg_sidewalks: the lidarseg evidence of sidewalks, or None: a :class:`LabelledGround` whose
            nearest-label test says whether a place is sidewalk.
        kerb_distance_m: the kerb zone's width.
    """

    drivable: DrivableArea
    walkway: shapely.Geometry | None = None
    crossings: shapely.Geometry | None = None
    lidarseg_sidewalks: "LabelledGround | None" = None
    kerb_distance_m: float = 1.0

    @property
    def has_road_edge(self) -> bool:
        """Whether the drivable area's edge is a real one (map or lidarseg), so off-road zones make sense."""
        return self.drivable.confidence in ("high", "medium")

    @property
    def sidewalk_source(self) -> str | None:
        """``"map-walkway"``, ``"lidarseg"``, ``"kerb-band"`` or None (no real road edge)."""
        if self.walkway is not None:
            return "map-walkway"
        if self.lidarseg_sidewalks is not None:
            return "lidarseg"
        return "kerb-band" if self.has_road_edge else None

    def unavailable(self, zone: str) -> str | None:
        """Why ``zone`` cannot be used here (None when it can)."""
        if zone in ("lane", "kerb"):
            return None
        if zone == "crossing":
            return None if self.crossings is not None else "the map has no ped_crossing here"
        if not self.has_road_edge:
            return f"the drivable area ({self.drivable.source}) has no real road edge"
        return None

    # ------------------------------------------------------------------ signed distance to the road edge
    @functools.cached_property
    def _grid_sdf(self) -> np.ndarray:
        g = np.pad(self.drivable.grid, 1).astype(np.uint8)
        inside = cv2.distanceTransform(g, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
        outside = cv2.distanceTransform(1 - g, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
        return (np.where(self.drivable.grid, inside - 0.5, 0.5 - outside) * self.drivable.resolution_m).astype(np.float64)

    def signed_distance(self, xy: np.ndarray) -> np.ndarray:
        """(N,) signed distance (m) of global x/y points (N, 2) to the road edge: + on the road, - off it."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        area = self.drivable
        if area.region is not None:
            d = area.boundary_distance(xy)  # = shapely.distance(points, boundary), exactly
            return np.where(shapely.contains_xy(area.region, xy[:, 0], xy[:, 1]), d, -d)
        ix, iy, inside = area._cells(xy)
        out = np.full(len(xy), -1e3)
        out[inside] = self._grid_sdf[iy[inside], ix[inside]]
        return out

    def on_lidarseg_sidewalk(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: global x/y points (N, 2) the lidarseg evidence calls sidewalk (:class:`LabelledGround`)."""
        return self.lidarseg_sidewalks.is_sidewalk(xy)

    def road_normal(self, xy: np.ndarray, step_m: float = 0.5) -> np.ndarray:
        """(N, 2) unit direction in which the signed distance grows (towards the road's inside) at points (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n = len(xy)
        s = self.signed_distance(np.concatenate([xy + [step_m, 0], xy - [step_m, 0], xy + [0, step_m],
                                                 xy - [0, step_m]]))  # one call for the four steps
        g = np.c_[s[:n] - s[n:2 * n], s[2 * n:3 * n] - s[3 * n:]]
        return g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-9)

    def edge_tangent(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) unit direction along the road's edge at points (N, 2) (the road normal turned by 90 deg)."""
        n = self.road_normal(xy)
        return np.c_[-n[:, 1], n[:, 0]]

    # ------------------------------------------------------------------ zone tests
    def plausible_centres(self, zone: str, xy: np.ndarray, wlh: np.ndarray, rule: ClassRule) -> np.ndarray:
        """(N,) bool: a cheap test of candidate centres (N, 2) for ``zone`` (sampling keeps these first)."""
        s = self.signed_distance(xy)
        half_w, half_diag = 0.5 * float(wlh[0]), 0.5 * float(np.hypot(wlh[0], wlh[1]))
        if zone == "lane":
            return s >= half_w + rule.lane_margin_m
        if zone == "kerb":
            return (s >= half_w - 0.1) & (s <= half_diag + self.kerb_distance_m + 0.5)
        if zone == "road_edge":
            return (s >= ROAD_EDGE_BAND_M[0]) & (s <= ROAD_EDGE_BAND_M[1])
        if zone == "sidewalk":
            off = s < -rule.sidewalk_band_m[0]
            if self.walkway is not None:
                return off & shapely.contains_xy(self.walkway, xy[:, 0], xy[:, 1])
            if self.lidarseg_sidewalks is not None:
                return off & self.on_lidarseg_sidewalk(xy)
            return off & (s >= -(rule.sidewalk_band_m[1] - half_w))
        if zone == "crossing":
            return shapely.contains_xy(self.crossings, xy[:, 0], xy[:, 1])
        raise ValueError(f"unknown zone {zone!r}")

    def footprints_in(self, zone: str, corners_xy: np.ndarray, rule: ClassRule, member: bool = False) -> np.ndarray:
        """(N,) bool: whether each footprint (N, 4, 2) lies in ``zone`` as the module docstring defines it.

        ``member``: the footprints are later members of a cluster, whose ``road_edge`` band reaches
        ``CLUSTER_TAPER_M`` farther into the road (a taper of cones closing a lane).
        """
        corners_xy = np.asarray(corners_xy, dtype=np.float64)
        check_shape(corners_xy, ("N", 4, 2), "corners_xy")
        N = len(corners_xy)
        if N == 0:
            return np.zeros(0, dtype=bool)
        area = self.drivable
        centre = corners_xy.mean(axis=1)
        if zone == "lane":
            return area.contains_footprints(grow_footprints(corners_xy, rule.lane_margin_m))
        if zone == "kerb":
            return area.contains_footprints(corners_xy) & (area.edge_distance(corners_xy) <= self.kerb_distance_m)
        if zone == "road_edge":
            s = self.signed_distance(centre)
            return (s >= ROAD_EDGE_BAND_M[0]) & (s <= ROAD_EDGE_BAND_M[1] + (CLUSTER_TAPER_M if member else 0.0))
        pts = np.concatenate([corners_xy, centre[:, None]], axis=1).reshape(-1, 2)  # (N * 5, 2)
        if zone == "sidewalk":
            s = self.signed_distance(pts).reshape(N, 5)
            ok = np.all(s <= -rule.sidewalk_band_m[0], axis=1)
            if area.region is not None:  # the whole footprint, edges included, keeps the band's near side
                ok &= shapely.distance(shapely.polygons(corners_xy), area.region) >= rule.sidewalk_band_m[0]
            if self.walkway is not None:
                return ok & shapely.contains_xy(self.walkway, pts[:, 0], pts[:, 1]).reshape(N, 5).all(axis=1)
            if self.lidarseg_sidewalks is not None:
                return ok & self.on_lidarseg_sidewalk(pts).reshape(N, 5).all(axis=1)
            return ok & np.all(s >= -rule.sidewalk_band_m[1], axis=1)
        if zone == "crossing":
            grown = shapely.buffer(self.crossings, 0.3)
            return shapely.contains_xy(grown, pts[:, 0], pts[:, 1]).reshape(N, 5).all(axis=1)
        raise ValueError(f"unknown zone {zone!r}")


SIDEWALK_REACH_M = 2.5  # a place is sidewalk when its nearest static lidarseg point is, within this distance


@dataclass(frozen=True, eq=False)
class LabelledGround:
    """The static lidarseg points (``flat.*``, ``static.*``) around a camera, for a nearest-label test.

    A place is sidewalk when its nearest such point (x/y) is ``flat.sidewalk`` and closer than
    ``SIDEWALK_REACH_M``: the sparse far rings leave metres between points, which a cell grid would call holes.

    Attributes:
        xy: (P, 2) global x/y of the points; ``is_sidewalk_point`` (P,) bool.
    """

    xy: np.ndarray
    is_sidewalk_point: np.ndarray

    @functools.cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(self.xy)

    def is_sidewalk(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool for global x/y points (N, 2)."""
        d, i = self._tree.query(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return (d <= SIDEWALK_REACH_M) & self.is_sidewalk_point[np.minimum(i, len(self.xy) - 1)]


def _lidarseg_sidewalks(sample: Sample, center_xy: np.ndarray, roi_m: float) -> LabelledGround | None:
    lidar = sample.lidar
    if lidar is None or lidar.labels is None:
        return None
    static = np.isin(lidar.labels, LIDARSEG_STATIC)
    xy = lidar.points_global[static, :2]
    near = np.linalg.norm(xy - center_xy, axis=1) <= roi_m
    sidewalk = lidar.labels[static][near] == LIDARSEG_SIDEWALK
    if sidewalk.sum() < 20:
        return None
    return LabelledGround(xy[near], sidewalk)


def surface_zones(sample: Sample, view: CameraView, drivable: DrivableArea, config: PlacementConfig) -> SurfaceZones:
    """The zones around ``view``'s camera: ``drivable`` with the map's walkways and crossings, lidarseg sidewalks."""
    cam_xy = view.T_global_from_cam[:2, 3]
    return SurfaceZones(drivable, polygons_near(list(sample.walkways_global), cam_xy, config.map_roi_m),
                        polygons_near(list(sample.ped_crossings_global), cam_xy, config.map_roi_m),
                        _lidarseg_sidewalks(sample, cam_xy, config.map_roi_m), config.kerb_distance_m)


__all__ = ["CLUSTER_TAPER_M", "LabelledGround", "SIDEWALK_REACH_M", "ROAD_EDGE_BAND_M", "SurfaceZones", "grow_footprints", "surface_zones"]
