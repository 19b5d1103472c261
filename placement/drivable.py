"""Where the road is: a drivable area in global x/y from the best source a sample offers.

Sources, best first:

* ``"map"``: the map expansion's ``drivable_area`` polygons (``Sample.drivable_area_global``), clipped to a
  disc around the camera. Confidence ``"high"``.
* ``"map-raster"``: the same from the base release's semantic-prior raster (``Sample.map_source`` ==
  ``"semantic-prior raster"``: 0.1 m pixels vectorised, edges within about a pixel). Confidence ``"high"``.
* ``"lidarseg"``: LiDAR points labelled ``flat.driveable_surface`` (24), rasterised to a bird's-eye grid.
  Far LiDAR rings are metres apart, so along each azimuth bin the cells between two consecutive
  drivable points (no other labelled point between them, gap below ``ray_fill_max_gap_m``) are filled,
  between a drivable and a blocking point up to their midpoint (nearest-label boundary), then a
  morphological closing joins neighbouring azimuths. Confidence ``"medium"``.
* ``"lidar-ground"``: the same grid from LiDAR points near the ego's ground plane (ego z = 0) inside
  the ego corridor (|y_ego| < ``corridor_half_width_m``); anything higher blocks the fill. Confidence ``"low"``.

Grid convention: cell ``grid[iy, ix]`` covers global ``x in [x0 + ix res, x0 + (ix + 1) res)`` and
``y in [y0 + iy res, y0 + (iy + 1) res)`` with ``(x0, y0) = grid_origin_xy``; outside the grid is not drivable.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import shapely
from scipy.spatial import cKDTree

from streetaug.augment.core import check_shape, invert_transform, transform_points
from streetaug.datasets.nuscenes_format import LIDARSEG_DRIVEABLE, LIDARSEG_EGO, LIDARSEG_NOISE
from streetaug.datasets.sample import CameraView, Sample

from .config import PlacementConfig

# placement source of each Sample.map_source; all map sources are polygons (DrivableArea.region)
MAP_SOURCE_NAMES = {"expansion": "map", "semantic-prior raster": "map-raster"}
MAP_SOURCES = tuple(MAP_SOURCE_NAMES.values())
_MAX_BLOCKER_HEIGHT_M = 3.0  # points higher above the ego ground (canopies, signs) do not block the road


@dataclass(frozen=True)
class DrivableArea:
    """A drivable region in the global x/y plane (metres).

    Attributes:
        source: ``"map"``, ``"map-raster"``, ``"lidarseg"`` or ``"lidar-ground"``.
        confidence: ``"high"``, ``"medium"`` or ``"low"``.
        region: shapely (Multi)Polygon in global x/y (polygon sources), else None.
        grid: (H, W) bool bird's-eye grid (grid sources), else None.
        grid_origin_xy: (2,) float64 global x/y of the grid's corner (cell (0, 0) lower-left), metres.
        resolution_m: grid cell size in metres.
    """

    source: str
    confidence: str
    region: shapely.Geometry | None = None
    grid: np.ndarray | None = None
    grid_origin_xy: np.ndarray | None = None
    resolution_m: float = 0.25

    # ------------------------------------------------------------------ queries
    def contains_points(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: whether global x/y points (N, 2) are drivable."""
        xy = np.asarray(xy, dtype=np.float64)
        check_shape(xy, ("N", 2), "xy")
        if self.region is not None:
            return shapely.contains_xy(self.region, xy[:, 0], xy[:, 1])
        ix, iy, inside = self._cells(xy)
        out = np.zeros(len(xy), dtype=bool)
        out[inside] = self.grid[iy[inside], ix[inside]]
        return out

    def contains_footprints(self, corners_xy: np.ndarray) -> np.ndarray:
        """(M,) bool: whether each whole footprint (corners (M, 4, 2), global x/y, in order) is drivable.

        Polygon sources test polygon containment (all corners and edges); grid sources are exact too:
        every cell the footprint overlaps with positive area must be drivable (separating-axis test of
        each cell square against the footprint; cells outside the grid are not drivable).
        """
        corners_xy = np.asarray(corners_xy, dtype=np.float64)
        check_shape(corners_xy, ("M", 4, 2), "corners_xy")
        if len(corners_xy) == 0:
            return np.zeros(0, dtype=bool)
        if self.region is not None:
            return shapely.contains(self.region, shapely.polygons(corners_xy))
        # fast reject: a strictly interior point in a non-drivable cell means that cell overlaps the footprint
        centre = corners_xy.mean(axis=1, keepdims=True)
        interior = _footprint_lattice(centre + 0.999 * (corners_xy - centre), self.resolution_m)
        ok = self.contains_points(interior.reshape(-1, 2)).reshape(interior.shape[:2]).all(axis=1)
        result = np.zeros(len(corners_xy), dtype=bool)
        if ok.any():
            result[ok] = self._grid_contains_exact(corners_xy[ok])
        return result

    def _grid_contains_exact(self, corners_xy: np.ndarray) -> np.ndarray:
        fp, ix, iy = _cells_in_bounds(corners_xy, self.grid_origin_xy, self.resolution_m)
        H, W = self.grid.shape
        inside = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        good = np.zeros(len(fp), dtype=bool)
        good[inside] = self.grid[iy[inside], ix[inside]]
        fp, ix, iy = fp[~good], ix[~good], iy[~good]  # only non-drivable cells can fail a footprint
        hit = _rect_overlaps_cell(corners_xy[fp], self.grid_origin_xy + np.stack([ix, iy], 1) * self.resolution_m,
                                  self.resolution_m)
        return np.bincount(fp[hit], minlength=len(corners_xy)) == 0

    def edge_distance(self, corners_xy: np.ndarray) -> np.ndarray:
        """(M,) float64 distance (m) from each footprint to the nearest non-drivable place (0 if it overlaps)."""
        corners_xy = np.asarray(corners_xy, dtype=np.float64)
        check_shape(corners_xy, ("M", 4, 2), "corners_xy")
        if len(corners_xy) == 0:
            return np.zeros(0)
        if self.region is not None:
            polys = shapely.polygons(corners_xy)
            d = shapely.distance(polys, shapely.boundary(self.region))
            return np.where(shapely.contains(self.region, polys), d, 0.0)
        dist = cv2.distanceTransform(
            np.pad(self.grid, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE
        )[1:-1, 1:-1] * self.resolution_m
        pts = _footprint_lattice(corners_xy, self.resolution_m / 2.0)
        ix, iy, inside = self._cells(pts.reshape(-1, 2))
        d = np.zeros(len(inside))
        d[inside] = dist[iy[inside], ix[inside]]
        # distanceTransform measures centre-to-centre; subtract half a cell for the distance to the edge
        return np.maximum(d.reshape(pts.shape[:2]).min(axis=1) - 0.5 * self.resolution_m, 0.0)

    @functools.cached_property
    def _edge_segments(self) -> tuple[np.ndarray, shapely.STRtree, cKDTree]:
        """The region boundary's segments (S, 2, 2) (end points; zero-length ones left out), an R-tree of their
        bounding boxes and a k-d tree of their end points."""
        segments = []
        for line in shapely.get_parts(shapely.boundary(self.region)):
            c = shapely.get_coordinates(line)
            seg = np.stack([c[:-1], c[1:]], axis=1)
            segments.append(seg[np.any(seg[:, 0] != seg[:, 1], axis=1)])
        seg = np.concatenate(segments)
        lo, hi = seg.min(axis=1), seg.max(axis=1)
        return seg, shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])), cKDTree(seg.reshape(-1, 2))

    def boundary_distance(self, xy: np.ndarray) -> np.ndarray:
        """(N,) float64 distance (m) of global x/y points (N, 2) to the region's boundary (polygon sources).

        The same numbers as ``shapely.distance(shapely.points(xy), shapely.boundary(region))``: GEOS measures a
        point against a line string segment by segment (``Distance::pointToSegment``, whose arithmetic is repeated
        here) and keeps the minimum, which is exact; only the segments that can be the nearest are measured,
        those whose bounding box meets the square of half side the distance to the nearest segment end.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.full(len(xy), np.inf)
        if len(xy) == 0:
            return out
        seg, tree, ends = self._edge_segments
        bound = ends.query(xy)[0] * (1.0 + 1e-9) + 1e-9
        pi, si = tree.query(shapely.box(xy[:, 0] - bound, xy[:, 1] - bound, xy[:, 0] + bound, xy[:, 1] + bound))
        px, py = xy[pi, 0], xy[pi, 1]
        ax, ay, bx, by = seg[si, 0, 0], seg[si, 0, 1], seg[si, 1, 0], seg[si, 1, 1]
        len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay)
        r = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2
        s = ((ay - py) * (bx - ax) - (ax - px) * (by - ay)) / len2
        to_a = np.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
        to_b = np.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
        d = np.where(r <= 0.0, to_a, np.where(r >= 1.0, to_b, np.abs(s) * np.sqrt(len2)))
        np.minimum.at(out, pi, d)
        return out

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rel = (xy - self.grid_origin_xy) / self.resolution_m
        ix = np.floor(rel[:, 0]).astype(np.int64)
        iy = np.floor(rel[:, 1]).astype(np.int64)
        H, W = self.grid.shape
        inside = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        return ix, iy, inside


def _cells_in_bounds(
    corners_xy: np.ndarray, origin_xy: np.ndarray, res: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(footprint index (K,), ix (K,), iy (K,)): every grid cell of each footprint's (M, 4, 2) bounding box."""
    lo = np.floor((corners_xy.min(axis=1) - origin_xy) / res).astype(np.int64)  # (M, 2)
    hi = np.floor((corners_xy.max(axis=1) - origin_xy) / res).astype(np.int64)
    nx, ny = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    fp = np.repeat(np.arange(len(corners_xy)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    return fp, lo[fp, 0] + k % nx[fp], lo[fp, 1] + k // nx[fp]


def _rect_overlaps_cell(rect: np.ndarray, cell_lo: np.ndarray, res: float) -> np.ndarray:
    """(K,) bool: whether rectangles (K, 4, 2) and square cells [lo, lo + res]^2 (K, 2) overlap with positive area.

    Separating-axis test: two convex polygons overlap iff their projections overlap on every edge
    normal of both (here x, y and the rectangle's two edge directions).
    """
    cell_pts = cell_lo[:, None, :] + np.array([[0, 0], [res, 0], [res, res], [0, res]], float)[None]  # (K, 4, 2)
    e1, e2 = rect[:, 1] - rect[:, 0], rect[:, 3] - rect[:, 0]
    hit = np.ones(len(rect), dtype=bool)
    for axis in (np.array([1.0, 0.0])[None], np.array([0.0, 1.0])[None], np.c_[-e1[:, 1], e1[:, 0]],
                 np.c_[-e2[:, 1], e2[:, 0]]):
        axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        pa = (rect * axis[:, None, :]).sum(axis=2)
        pb = (cell_pts * axis[:, None, :]).sum(axis=2)
        hit &= np.minimum(pa.max(axis=1), pb.max(axis=1)) - np.maximum(pa.min(axis=1), pb.min(axis=1)) > 1e-9
    return hit


def _footprint_lattice(corners_xy: np.ndarray, spacing_m: float) -> np.ndarray:
    """Points (M, S, 2) covering each quadrilateral footprint (M, 4, 2), boundary included."""
    side = np.linalg.norm(corners_xy - np.roll(corners_xy, -1, axis=1), axis=2).max()
    n = int(np.ceil(side / max(spacing_m, 1e-3))) + 1
    a, b = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    a, b = a.ravel(), b.ravel()
    w = np.stack([(1 - a) * (1 - b), a * (1 - b), a * b, (1 - a) * b], axis=1)  # (S, 4) bilinear weights
    return np.einsum("sk,mkd->msd", w, corners_xy)


# ---------------------------------------------------------------------- builders


def drivable_from_map(polygons: list, center_xy: np.ndarray, roi_m: float,
                      source: str = "map") -> DrivableArea | None:
    """Union of the map's drivable polygons (global x/y) within ``roi_m`` of ``center_xy``; None if empty.

    ``source``: ``"map"`` (map expansion) or ``"map-raster"`` (semantic-prior raster), see ``MAP_SOURCES``.
    """
    if source not in MAP_SOURCES:
        raise ValueError(f"drivable_from_map: source must be one of {MAP_SOURCES}, got {source!r}")
    region = polygons_near(polygons, center_xy, roi_m)
    return None if region is None else DrivableArea(source=source, confidence="high", region=region)


def polygons_near(polygons, center_xy: np.ndarray, roi_m: float) -> shapely.Geometry | None:
    """The union of map polygons (global x/y) clipped to the disc of radius ``roi_m`` around ``center_xy``
    (prepared for fast queries); None when nothing of positive area is left."""
    if not polygons:
        return None
    roi = shapely.Point(float(center_xy[0]), float(center_xy[1])).buffer(roi_m, quad_segs=16)
    geoms = np.asarray(polygons, dtype=object)
    geoms = geoms[shapely.intersects(geoms, roi)]
    if len(geoms) == 0:
        return None
    region = shapely.intersection(shapely.union_all(shapely.make_valid(geoms)), roi)
    if region.is_empty or region.area <= 0:
        return None
    shapely.prepare(region)
    return region


def _ray_fill_grid(
    drivable_xy: np.ndarray,
    blocker_xy: np.ndarray,
    sensor_xy: np.ndarray,
    config: PlacementConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Bird's-eye grid (H, W) bool and its origin (2,) from drivable and blocking points (global x/y)."""
    res = config.grid_resolution_m
    lo = sensor_xy - config.map_roi_m
    hi = sensor_xy + config.map_roi_m
    W = int(np.ceil((hi[0] - lo[0]) / res))
    H = int(np.ceil((hi[1] - lo[1]) / res))
    all_xy = np.concatenate([drivable_xy, blocker_xy])
    is_drv = np.concatenate([np.ones(len(drivable_xy), bool), np.zeros(len(blocker_xy), bool)])
    rel = all_xy - sensor_xy
    rng_m = np.hypot(rel[:, 0], rel[:, 1])
    az_bin = np.floor(np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) / config.azimuth_bin_deg).astype(np.int64)
    order = np.lexsort((rng_m, az_bin))
    az_s, r_s, d_s, xy_s = az_bin[order], rng_m[order], is_drv[order], all_xy[order]
    # consecutive drivable pairs on the same azimuth bin, close enough: fill the segment between them
    # (a drivable point next to a blocking one fills up to the midpoint: nearest-label boundary)
    near = (az_s[1:] == az_s[:-1]) & (r_s[1:] - r_s[:-1] < config.ray_fill_max_gap_m)
    both = near & d_s[1:] & d_s[:-1]
    d_then_b = near & d_s[:-1] & ~d_s[1:]
    b_then_d = near & ~d_s[:-1] & d_s[1:]
    mid = 0.5 * (xy_s[:-1] + xy_s[1:])
    a = np.concatenate([xy_s[:-1][both], xy_s[:-1][d_then_b], xy_s[1:][b_then_d]])
    b = np.concatenate([xy_s[1:][both], mid[d_then_b], mid[b_then_d]])
    seg_len = np.linalg.norm(b - a, axis=1)
    steps = np.ceil(seg_len / (0.5 * res)).astype(np.int64) + 1
    seg_id = np.repeat(np.arange(len(a)), steps)
    frac = (np.arange(steps.sum()) - np.repeat(np.cumsum(steps) - steps, steps)) / np.maximum(
        np.repeat(steps - 1, steps), 1
    )
    fill_xy = a[seg_id] + (b - a)[seg_id] * frac[:, None]
    pts = np.concatenate([drivable_xy, fill_xy])
    ix = np.floor((pts[:, 0] - lo[0]) / res).astype(np.int64)
    iy = np.floor((pts[:, 1] - lo[1]) / res).astype(np.int64)
    keep = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
    grid = np.zeros((H, W), dtype=np.uint8)
    grid[iy[keep], ix[keep]] = 1
    r = max(int(round(config.closing_radius_m / res)), 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    grid = cv2.morphologyEx(grid, cv2.MORPH_CLOSE, kernel)
    return grid.astype(bool), lo


def drivable_from_lidarseg(
    points_global: np.ndarray,
    labels: np.ndarray,
    T_global_from_ego: np.ndarray,
    sensor_xy: np.ndarray,
    config: PlacementConfig,
) -> DrivableArea | None:
    """Grid drivable area from lidarseg labels (class 24 drivable; other classes block); None if no class-24 point."""
    check_shape(points_global, ("N", 3), "points_global")
    labels = np.asarray(labels)
    check_shape(labels, (len(points_global),), "lidarseg labels")
    drv = labels == LIDARSEG_DRIVEABLE
    if not drv.any():
        return None
    z_ego = transform_points(invert_transform(T_global_from_ego), points_global)[:, 2]
    block = (~drv) & (labels != LIDARSEG_NOISE) & (labels != LIDARSEG_EGO) & (z_ego < _MAX_BLOCKER_HEIGHT_M)
    grid, origin = _ray_fill_grid(points_global[drv, :2], points_global[block, :2], sensor_xy, config)
    return DrivableArea("lidarseg", "medium", grid=grid, grid_origin_xy=origin, resolution_m=config.grid_resolution_m)


def drivable_from_lidar_ground(
    points_global: np.ndarray,
    T_global_from_ego: np.ndarray,
    sensor_xy: np.ndarray,
    config: PlacementConfig,
    min_points: int = 50,
) -> DrivableArea | None:
    """Low-confidence grid: points near the ego ground plane inside the ego corridor; None if too few."""
    check_shape(points_global, ("N", 3), "points_global")
    p_ego = transform_points(invert_transform(T_global_from_ego), points_global)
    corridor = np.abs(p_ego[:, 1]) < config.corridor_half_width_m
    ground = corridor & (np.abs(p_ego[:, 2]) < config.lidar_ground_band_m)
    block = (p_ego[:, 2] >= config.lidar_ground_band_m + config.obstacle_min_height_m * 0.5) & (
        p_ego[:, 2] < _MAX_BLOCKER_HEIGHT_M
    )
    if ground.sum() < min_points:
        return None
    grid, origin = _ray_fill_grid(points_global[ground, :2], points_global[block, :2], sensor_xy, config)
    return DrivableArea("lidar-ground", "low", grid=grid, grid_origin_xy=origin, resolution_m=config.grid_resolution_m)


def drivable_area_for_sample(sample: Sample, view: CameraView,
                             config: PlacementConfig) -> tuple[DrivableArea | None, str | None]:
    """The best drivable area of ``sample`` around ``view``'s camera, or (None, reason).

    Args:
        view: the camera being augmented.
    """
    cam_xy = view.T_global_from_cam[:2, 3]
    tried = []
    polygons = sample.drivable_area_global
    if polygons:
        kind = sample.map_source or "expansion"  # samples built without a reader: polygons of a map expansion
        if kind not in MAP_SOURCE_NAMES:
            raise ValueError(f"Sample.map_source must be one of {sorted(MAP_SOURCE_NAMES)} or None, got {kind!r}")
        source = MAP_SOURCE_NAMES[kind]
        area = drivable_from_map(polygons, cam_xy, config.map_roi_m, source)
        if area is not None:
            return area, None
        what = "map" if source == "map" else "semantic-prior raster map"
        tried.append(f"{what} has no drivable polygon within {config.map_roi_m:g} m of the camera")
    else:
        tried.append("no map")
    lidar = sample.lidar
    if lidar is None:
        return None, "no drivable area: " + ", ".join(tried + ["no lidarseg", "no LiDAR"])
    points = lidar.points_global
    sensor_xy = lidar.T_global_from_lidar[:2, 3]
    if lidar.labels is not None:
        area = drivable_from_lidarseg(points, lidar.labels, lidar.T_global_from_ego, sensor_xy, config)
        if area is not None:
            return area, None
        tried.append("lidarseg has no flat.driveable_surface point")
    else:
        tried.append("no lidarseg")
    area = drivable_from_lidar_ground(points, lidar.T_global_from_ego, sensor_xy, config)
    if area is not None:
        return area, None
    tried.append("LiDAR ground fit found too few ground points in the ego corridor")
    return None, "no drivable area: " + ", ".join(tried)
