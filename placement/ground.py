"""Local ground under a placement, fitted from LiDAR, with the ego's ground plane as the fallback.

In nuScenes ego frames the ground is z = 0 (the ego pose sits on the road), so the ego ground plane
in global coordinates passes through the ego origin with normal = the ego's +z axis.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from streetaug.augment.core import check_shape
from streetaug.datasets.nuscenes_format import LIDARSEG_DRIVEABLE, LIDARSEG_GROUND

from .config import PlacementConfig


@dataclass(frozen=True)
class GroundPlane:
    """A local ground plane in the global frame.

    Attributes:
        point_global: (3,) float64 the plane point below the query x/y, metres.
        normal_global: (3,) float64 unit normal pointing up (z > 0).
        source: ``"lidarseg"`` (fit on driveable-surface points, else all flat.* points), ``"lidar-plane"``
            (robust fit on low points), ``"boxes"`` (the bottoms of the annotated objects nearby, where
            the LiDAR fit disagreed with them) or ``"ego-plane"`` (fallback: the ego's z = 0 plane).
        n_points: LiDAR points (annotated boxes, for ``"boxes"``) supporting the fit (0 for the fallback).
    """

    point_global: np.ndarray
    normal_global: np.ndarray
    source: str
    n_points: int = 0

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """Plane z (N,) at global x/y points (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n, p = self.normal_global, self.point_global
        return p[2] - (n[0] * (xy[:, 0] - p[0]) + n[1] * (xy[:, 1] - p[1])) / n[2]


def _plane_at(xy: np.ndarray, normal: np.ndarray, through: np.ndarray, source: str, n_points: int) -> GroundPlane:
    normal = normal / np.linalg.norm(normal)
    if normal[2] < 0:
        normal = -normal
    z = through[2] - (normal[0] * (xy[0] - through[0]) + normal[1] * (xy[1] - through[1])) / normal[2]
    return GroundPlane(np.array([xy[0], xy[1], z]), normal, source, n_points)


def ego_ground_plane(T_global_from_ego: np.ndarray, xy: np.ndarray) -> GroundPlane:
    """The ego's z = 0 plane (global frame), evaluated below global x/y ``xy`` (2,)."""
    check_shape(T_global_from_ego, (4, 4), "T_global_from_ego")
    return _plane_at(np.asarray(xy, float), T_global_from_ego[:3, 2].copy(), T_global_from_ego[:3, 3], "ego-plane", 0)


def _height_on_level(up: np.ndarray, level: float, xy: np.ndarray) -> float:
    """z below global x/y ``xy`` (2,) of the plane ``up . p = level`` (normal ``up``, e.g. the ego's)."""
    return float((level - up[:2] @ xy) / up[2])


def _fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane through points (N, 3): (normal (3,), centroid (3,))."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[-1]
    return (n if n[2] > 0 else -n), c


ILL_POSED_GAP = 1e-6  # of the largest scatter eigenvalue: a smaller gap between the two smallest leaves the normal open


def _fit_planes(points: np.ndarray, seg: np.ndarray, use: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares planes through the groups of points (K, 3) (group ``seg`` (K,), only where ``use`` (K,)):
    (normals (G, 3) with z > 0, centroids (G, 3)); groups without points get nan."""
    s, p = seg[use], points[use]
    n = np.bincount(s, minlength=n_groups).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.stack([np.bincount(s, p[:, d], minlength=n_groups) for d in range(3)], axis=1) / n[:, None]
    q = p - c[s]
    scatter = np.zeros((n_groups, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            scatter[:, a, b] = scatter[:, b, a] = np.bincount(s, q[:, a] * q[:, b], minlength=n_groups)
    empty = n == 0
    scatter[empty] = np.eye(3)
    w, v = np.linalg.eigh(scatter)  # eigenvalues ascending: the smallest one's vector is the normal
    normal = v[:, :, 0]
    normal = np.where(normal[:, 2:3] > 0, normal, -normal)
    normal[empty] = np.nan
    # where the two smallest eigenvalues (nearly) coincide (points on a line) the normal is not determined by
    # the points: there take :func:`_fit_plane`'s choice, so both ways give the same plane
    for g in np.flatnonzero(~empty & (w[:, 1] - w[:, 0] <= ILL_POSED_GAP * np.maximum(w[:, 2], 1e-300))):
        normal[g], c[g] = _fit_plane(p[s == g])
    return normal, c


def _group_sorted(values: np.ndarray, seg: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(values sorted within each group, each group's first index in that order (G,), group sizes (G,))."""
    order = np.lexsort((values, seg))
    n = np.bincount(seg, minlength=n_groups)
    return values[order], np.concatenate([[0], np.cumsum(n)[:-1]]), n


def _group_percentile(values: np.ndarray, seg: np.ndarray, n_groups: int, q: float) -> np.ndarray:
    """(G,) ``np.percentile(values[seg == g], q)`` (linear interpolation, the same arithmetic) of every group;
    nan for empty groups."""
    v, start, n = _group_sorted(values, seg, n_groups)
    out = np.full(n_groups, np.nan)
    has = n > 0
    quantile = np.true_divide(q, 100)
    virtual = (n[has] - 1) * quantile  # numpy's "linear" method
    below = np.floor(virtual)
    gamma = virtual - below
    lo = np.clip(below.astype(np.int64), 0, n[has] - 1)
    hi = np.clip(below.astype(np.int64) + 1, 0, n[has] - 1)
    a, b = v[start[has] + lo], v[start[has] + hi]
    diff = b - a
    out[has] = np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma)
    return out


def _group_median(values: np.ndarray, seg: np.ndarray, n_groups: int) -> np.ndarray:
    """(G,) ``np.median`` of every group of ``values``; nan for empty groups."""
    v, start, n = _group_sorted(values, seg, n_groups)
    out = np.full(n_groups, np.nan)
    has = n > 0
    a = v[start[has] + (n[has] - 1) // 2]
    b = v[start[has] + n[has] // 2]
    out[has] = np.where(n[has] % 2 == 1, a, (a + b) / 2)
    return out


class LocalGroundFitter:
    """Fits the ground plane under query points from one LiDAR sweep (global frame).

    Args:
        points_global: (N, 3) float64 LiDAR points, global frame, metres.
        T_global_from_ego: (4, 4) ego pose used for the fallback plane and the tilt check.
        labels: (N,) lidarseg labels or None; with labels only flat.driveable_surface points are used
            (all flat.* points where those are too few).
        config: thresholds (``ground_radius_m``, ``ground_min_points``, ``ground_inlier_m``, ``ground_max_tilt_deg``,
            ``ground_max_offset_m``, ``ground_max_offset_per_m``, ``ground_box_radius_m``, ``ground_box_tolerance_m``).
        box_bottoms_global: (M, 3) bottom centres of the sample's annotated vehicles (each a height of the
            ground a car stands on, measured by the annotators; people stand on sidewalks and platforms too,
            so they are left out: on scene-0916 they lifted a car 0.6 m), or None.

    Pass only points outside the annotated boxes: a car roof is no ground.  Far from the ego the LiDAR
    sees little road (sparse rings, the ground hidden behind parked cars), and the lowest points there
    can be a hedge, a wall top or an embankment: on the real scene-0916 such fits put cars 0.7-3.3 m
    above the annotated cars around them.  Where annotated objects stand within ``ground_box_radius_m``,
    a fitted height more than ``ground_box_tolerance_m`` from theirs gives way to theirs.
    """

    def __init__(
        self,
        points_global: np.ndarray | None,
        T_global_from_ego: np.ndarray,
        labels: np.ndarray | None = None,
        config: PlacementConfig = PlacementConfig(),
        box_bottoms_global: np.ndarray | None = None,
    ) -> None:
        self.T_global_from_ego = np.asarray(T_global_from_ego, dtype=np.float64)
        self.config = config
        bottoms = np.zeros((0, 3)) if box_bottoms_global is None else np.asarray(box_bottoms_global, np.float64)
        check_shape(bottoms.reshape(-1, 3), ("M", 3), "box_bottoms_global")
        self.box_bottoms = bottoms.reshape(-1, 3)
        self.box_tree = cKDTree(self.box_bottoms[:, :2]) if len(self.box_bottoms) else None
        self.use_labels = labels is not None
        self.point_sets: list[tuple[np.ndarray, cKDTree]] = []  # tried in order
        if points_global is not None and len(points_global):
            points_global = np.asarray(points_global, dtype=np.float64)
            check_shape(points_global, ("N", 3), "points_global")
            if labels is None:
                sets = [points_global]
            else:
                labels = np.asarray(labels)
                check_shape(labels, (len(points_global),), "lidarseg labels")
                # the road itself first (a car stands on it); all flat.* classes where the road is too sparse
                sets = [points_global[labels == LIDARSEG_DRIVEABLE], points_global[np.isin(labels, LIDARSEG_GROUND)]]
            self.point_sets = [(p, cKDTree(p[:, :2])) for p in sets if len(p)]

    def with_config(self, config: PlacementConfig) -> "LocalGroundFitter":
        """This fitter (same points and trees) with other thresholds, e.g. a smaller ``ground_radius_m``."""
        other = object.__new__(LocalGroundFitter)
        other.__dict__.update(self.__dict__)
        other.config = config
        return other

    def fit(self, xy: np.ndarray, check_by_boxes: bool = True) -> GroundPlane:
        """Ground plane below global x/y ``xy`` (2,); falls back to the ego plane when LiDAR is insufficient.

        The fit uses points within ``ground_radius_m``; where the far LiDAR rings are too sparse the
        radius grows to 2x and 3x before falling back. A fitted plane whose height below ``xy`` differs from
        the ego's ground plane by more than ``ground_max_offset_m + ground_max_offset_per_m * distance``
        (distance from the ego, metres) is rejected (canopies, roofs, walls seen without the road).  Then the
        annotated vehicles nearby have the last word on the height (see the class docstring) unless
        ``check_by_boxes`` is False (tracks: see :func:`~.track.stand_heights`).
        """
        xy = np.asarray(xy, dtype=np.float64)
        plane = self._fit_lidar(xy)
        return self._checked_by_boxes(plane, xy) if check_by_boxes else plane

    def fit_many(self, xy: np.ndarray, check_by_boxes: bool = True) -> list[GroundPlane]:
        """:meth:`fit` below each of the global x/y points (M, 2), all at once.

        The same rules in the same order (radius 1x, 2x, 3x over the point sets, the offset check, the boxes'
        word), each step on every point still without a plane in one array pass: the neighbours of all points
        in one tree query, the low-point percentile, the plane fits (centroid and the smallest eigenvector of
        the 3x3 scatter matrix, batched; :meth:`fit` takes the smallest singular vector of the centred points,
        the same plane up to rounding) and the inlier rounds per point group. The planes equal :meth:`fit`'s up
        to float rounding (same sources and point counts; ``tests/placement/test_ground_batch.py``).
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        M = len(xy)
        T = self.T_global_from_ego
        ego = [ego_ground_plane(T, p) for p in xy]
        max_offset = [self.config.ground_max_offset_m + self.config.ground_max_offset_per_m * float(
            np.linalg.norm(p - T[:2, 3])) for p in xy]
        planes: list[GroundPlane | None] = [None] * M
        pending = np.arange(M)
        for scale in (1.0, 2.0, 3.0):
            for points, tree in self.point_sets:
                if not len(pending):
                    break
                fitted = self._fit_within_many(points, tree, xy[pending], self.config.ground_radius_m * scale)
                done = np.zeros(len(pending), dtype=bool)
                for i, (m, plane) in enumerate(zip(pending, fitted)):
                    if plane is not None and abs(plane.point_global[2] - ego[m].point_global[2]) <= max_offset[m]:
                        planes[m], done[i] = plane, True
                pending = pending[~done]
        for m in pending:
            planes[m] = ego[m]
        if check_by_boxes and self.box_tree is not None and M:
            near = self.box_tree.query_ball_point(xy, self.config.ground_box_radius_m)
            for m in range(M):
                if near[m]:
                    planes[m] = self._checked_by_boxes(planes[m], xy[m], near[m])
        return planes

    def _fit_within_many(self, points: np.ndarray, tree: cKDTree, xy: np.ndarray,
                         radius_m: float) -> list[GroundPlane | None]:
        """:meth:`_fit_within` for each of the points ``xy`` (M, 2), in array passes over all their neighbours."""
        cfg = self.config
        M = len(xy)
        out: list[GroundPlane | None] = [None] * M
        lists = tree.query_ball_point(xy, radius_m, return_sorted=False)
        counts = np.fromiter((len(x) for x in lists), dtype=np.int64, count=M)
        live = counts >= cfg.ground_min_points
        if not live.any():
            return out
        groups = np.flatnonzero(live)
        seg = np.repeat(np.arange(len(groups)), counts[groups])
        pts = points[np.fromiter(itertools.chain.from_iterable(lists[groups]), dtype=np.int64, count=int(counts[groups].sum()))]
        G = len(groups)
        up = self.T_global_from_ego[:3, 2]
        source = "lidarseg" if self.use_labels else "lidar-plane"
        if self.use_labels:
            cand = np.ones(len(pts), dtype=bool)
        else:
            rel_h = pts @ up
            cand = rel_h <= _group_percentile(rel_h, seg, G, 5.0)[seg] + 0.4
        ok = np.bincount(seg[cand], minlength=G) >= cfg.ground_min_points
        normal, centroid = _fit_planes(pts, seg, cand & ok[seg], G)
        band = max(cfg.ground_inlier_m, 1e-3)
        inl = cand
        for _ in range(3):
            res = np.einsum("kd,kd->k", pts - centroid[seg], normal[seg])
            inl = (np.abs(res) < band) & ok[seg]
            ok &= np.bincount(seg[inl], minlength=G) >= cfg.ground_min_points
            inl &= ok[seg]
            normal, centroid = _fit_planes(pts, seg, inl, G)
        n_inl = np.bincount(seg[inl], minlength=G)
        xy_in = pts[inl, :2]
        s_in = seg[inl]
        mean_xy = np.stack([np.bincount(s_in, xy_in[:, d], minlength=G) for d in (0, 1)], axis=1) / np.maximum(n_inl, 1)[:, None]
        dxy = xy_in - mean_xy[s_in]
        cov = np.zeros((G, 2, 2))
        for a in (0, 1):
            for b in (0, 1):
                cov[:, a, b] = np.bincount(s_in, dxy[:, a] * dxy[:, b], minlength=G)
        cov /= np.maximum(n_inl - 1, 1)[:, None, None]
        spread = np.linalg.eigvalsh(cov)[:, 0]
        line = ok & (spread < 0.5**2)
        med = _group_median(pts[inl] @ up, s_in, G) if line.any() else np.zeros(G)
        tilt = np.degrees(np.arccos(np.clip(np.abs(normal @ up), -1.0, 1.0)))
        for g in np.flatnonzero(ok):
            m = groups[g]
            if line[g]:
                z = _height_on_level(up, float(med[g]), xy[m])
                out[m] = _plane_at(xy[m], up.copy(), np.array([xy[m, 0], xy[m, 1], z]), source, int(n_inl[g]))
            elif tilt[g] <= cfg.ground_max_tilt_deg:
                out[m] = _plane_at(xy[m], normal[g], centroid[g], source, int(n_inl[g]))
        return out

    def _fit_lidar(self, xy: np.ndarray) -> GroundPlane:
        ego = ego_ground_plane(self.T_global_from_ego, xy)
        max_offset = self.config.ground_max_offset_m + self.config.ground_max_offset_per_m * float(
            np.linalg.norm(xy - self.T_global_from_ego[:2, 3]))
        for scale in (1.0, 2.0, 3.0):
            for points, tree in self.point_sets:
                plane = self._fit_within(points, tree, xy, self.config.ground_radius_m * scale)
                # a "ground" far above or below the ego's road (a canopy, a roof) is not the road
                if plane is not None and abs(plane.point_global[2] - ego.point_global[2]) <= max_offset:
                    return plane
        return ego

    def _checked_by_boxes(self, plane: GroundPlane, xy: np.ndarray, near: list[int] | None = None) -> GroundPlane:
        """``plane``, or a plane at the height of the annotated objects within ``ground_box_radius_m`` of ``xy``
        (their median offset from the ego's ground plane, carried to ``xy``; ``plane``'s tilt kept) where
        ``plane`` is more than ``ground_box_tolerance_m`` from it."""
        if self.box_tree is None:
            return plane
        if near is None:
            near = self.box_tree.query_ball_point(xy, self.config.ground_box_radius_m)
        if not near:
            return plane
        bottoms = self.box_bottoms[np.asarray(near)]
        up = self.T_global_from_ego[:3, 2]
        origin = self.T_global_from_ego[:3, 3]
        offset = float(np.median((bottoms - origin) @ up))  # heights above the ego's ground plane
        z_boxes = _height_on_level(up, offset + up @ origin, xy)  # that offset, below xy
        if abs(plane.height_at(xy[None])[0] - z_boxes) <= self.config.ground_box_tolerance_m:
            return plane
        return _plane_at(xy, plane.normal_global.copy(), np.array([xy[0], xy[1], z_boxes]), "boxes", len(near))

    def _fit_within(self, points: np.ndarray, tree: cKDTree, xy: np.ndarray, radius_m: float) -> GroundPlane | None:
        cfg = self.config
        idx = tree.query_ball_point(xy, radius_m)
        if len(idx) < cfg.ground_min_points:
            return None
        pts = points[np.asarray(idx)]
        up = self.T_global_from_ego[:3, 2]
        source = "lidarseg" if self.use_labels else "lidar-plane"
        if self.use_labels:
            cand = pts
        else:
            # low points: within 0.4 m of the 5th percentile height (measured along the ego's up)
            rel_h = pts @ up
            cand = pts[rel_h <= np.percentile(rel_h, 5) + 0.4]
        if len(cand) < cfg.ground_min_points:
            return None
        normal, centroid = _fit_plane(cand)
        for _ in range(3):
            res = (pts - centroid) @ normal
            inl = pts[np.abs(res) < max(cfg.ground_inlier_m, 1e-3)]
            if len(inl) < cfg.ground_min_points:
                return None
            normal, centroid = _fit_plane(inl)
        spread = np.linalg.eigvalsh(np.cov((inl[:, :2] - inl[:, :2].mean(0)).T))
        if spread[0] < 0.5**2:
            # points on one scan line: trust only the height, keep the ego's tilt (plane up . p = median)
            d = float(np.median(inl @ up))
            z = _height_on_level(up, d, xy)
            return _plane_at(xy, up.copy(), np.array([xy[0], xy[1], z]), source, len(inl))
        tilt = np.degrees(np.arccos(np.clip(abs(normal @ up), -1.0, 1.0)))
        if tilt > cfg.ground_max_tilt_deg:
            return None
        return _plane_at(xy, normal, centroid, source, len(inl))
