"""Lighting levels and the automatic choice between them.

Levels (cheapest first):

* ``L0`` — constant dome of the image's mean radiance (the paper's "no light" baseline);
* ``L1`` — sun from the ephemeris + parametric sky fitted to the image (distant light only);
* ``L2`` — L1's sun + the image-corrected sky dome + a small VSG volume around the placement
  (:data:`L2_GRID`: 40 m half extent, dense at the placement);
* ``L3`` — the full VSG volume (:data:`L3_GRID`: 300 x 300 x 80 m, log-projected around the camera).

``auto`` predicts, for an upward-facing surface at the placement (a few points around it), each level's
relative error of the irradiance plus its error of the sun's share of it (the part that casts the object's
shadow), against the best available prediction, from a cheap 2.5D occluder height map (LiDAR + unprojected
pixels + the street-canyon prior) marched towards the sun and over the sky. It picks the cheapest level
whose predicted error is within ``AUTO_TOLERANCE`` of the best one; the numbers go into the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .volume import LogGrid

LEVELS = ("L0", "L1", "L2", "L3")
AUTO_TOLERANCE = 0.05
L3_GRID = LogGrid(shape=(128, 128, 32), half_extent_xy_m=150.0, z_min_m=-4.0, z_max_m=76.0)
L2_GRID = LogGrid(shape=(64, 64, 24), half_extent_xy_m=40.0, z_min_m=-4.0, z_max_m=36.0, log_scale_xy_m=3.0)
BLOCKED_MARCH_ELEMENTS = 1_000_000  # (point, direction, step) samples marched at once by HeightMap.blocked (~50 MB)
WALL_RHO = 0.25  # assumed albedo of occluders when predicting the light they reflect


@dataclass(frozen=True)
class HeightMap:
    """2.5D occluders: the highest structure per square cell, volume frame (z up, metres).

    Attributes:
        heights_m: (n, n) float32 top height per cell (0 where nothing stands).
        cell_m: cell size; the map covers ``[-half_extent, half_extent]^2`` around the volume origin.
    """

    heights_m: np.ndarray
    cell_m: float
    half_extent_m: float

    @staticmethod
    def from_points(points_vol: np.ndarray, cell_m: float = 1.0, half_extent_m: float = 150.0,
                    min_height_m: float = 0.3) -> "HeightMap":
        n = int(round(2 * half_extent_m / cell_m))
        h = np.zeros((n, n), np.float32)
        p = np.asarray(points_vol, dtype=np.float64)
        p = p[p[:, 2] >= min_height_m] if len(p) else p
        if len(p):
            i = np.floor((p[:, 0] + half_extent_m) / cell_m).astype(np.int64)
            j = np.floor((p[:, 1] + half_extent_m) / cell_m).astype(np.int64)
            ok = (i >= 0) & (i < n) & (j >= 0) & (j < n)
            np.maximum.at(h.reshape(-1), i[ok] * n + j[ok], p[ok, 2].astype(np.float32))
        return HeightMap(h, float(cell_m), float(half_extent_m))

    def merged(self, other: "HeightMap") -> "HeightMap":
        """The map of both maps' structures (the higher per cell): ``from_points`` of both point sets."""
        if (other.cell_m, other.half_extent_m, other.heights_m.shape) != (self.cell_m, self.half_extent_m,
                                                                          self.heights_m.shape):
            raise ValueError("HeightMap.merged: the maps' cells differ")
        return HeightMap(np.maximum(self.heights_m, other.heights_m), self.cell_m, self.half_extent_m)

    def raised(self, mask_fn, height_m: float) -> "HeightMap":
        """A copy with cells where ``mask_fn(heights, r_xy)`` is True raised to at least ``height_m``."""
        n = self.heights_m.shape[0]
        c = (np.arange(n) + 0.5) * self.cell_m - self.half_extent_m
        r = np.hypot(c[:, None], c[None, :])
        m = mask_fn(self.heights_m, r)
        return HeightMap(np.where(m, np.maximum(self.heights_m, height_m), self.heights_m).astype(np.float32),
                         self.cell_m, self.half_extent_m)

    def blocked(self, points: np.ndarray, dirs: np.ndarray, box_lo: np.ndarray | None = None,
                box_hi: np.ndarray | None = None, max_dist_m: float = 300.0) -> np.ndarray:
        """(M, D) bool: does a ray from each point (M, 3) along each unit direction (D, 3) hit a structure?

        Only structures inside the xy box ``[box_lo, box_hi]`` (default: the whole map) count.
        """
        whole, within = self.blocked_whole_and_within(points, dirs, box_lo, box_hi, max_dist_m)
        return whole if within is None else within

    def blocked_whole_and_within(self, points: np.ndarray, dirs: np.ndarray, box_lo: np.ndarray | None = None,
                                 box_hi: np.ndarray | None = None,
                                 max_dist_m: float = 300.0) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`blocked` by the whole map and by the structures inside the xy box ``[box_lo, box_hi]`` (None
        without a box), from one march: ((M, D) bool, (M, D) bool or None).

        The rays are marched in horizontal steps of half a cell, one direction at a time, and only as far as a
        hit is possible: until the ray rises above the map's highest structure (or 200 m) and, when every point
        is on the map, until it leaves the map; the steps left out could not hit, so the result is the one of
        marching all ``max_dist_m``. The march runs over blocks of points of at most ``BLOCKED_MARCH_ELEMENTS``
        (point, direction, step) samples, so its memory does not grow with the number of points.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        step = 0.5 * self.cell_m
        t = np.arange(1, int(max_dist_m / step) + 1) * step  # horizontal distance marched
        per_point = max(len(d) * len(t), 1)
        block = max(1, BLOCKED_MARCH_ELEMENTS // per_point)
        whole = np.zeros((len(pts), len(d)), dtype=bool)
        within = None if box_lo is None else np.zeros((len(pts), len(d)), dtype=bool)
        for start in range(0, len(pts), block):
            w, b = self._blocked_block(pts[start:start + block], d, t, box_lo, box_hi)
            whole[start:start + block] = w
            if within is not None:
                within[start:start + block] = b
        return whole, within

    def _march_steps(self, pts: np.ndarray, slope_xy: np.ndarray, slope_z: float, t: np.ndarray) -> int:
        """How many of the steps ``t`` (T,) can hit for points (m, 3) along one direction (horizontal unit
        ``slope_xy`` (2,), rise per horizontal metre ``slope_z``): a superset of the steps with a hit."""
        top = min(float(self.heights_m.max(initial=0.0)), 200.0)  # a hit needs z below both
        reach = float(t[-1]) if len(t) else 0.0
        if slope_z > 0.0:
            reach = min(reach, (top - float(pts[:, 2].min())) / slope_z)
        half = self.half_extent_m
        on_map = (np.abs(pts[:, :2]) < half).all()
        if on_map:  # from a point on the map, a ray that has left it never returns
            with np.errstate(divide="ignore"):
                exits = [np.where(s > 0, (half - pts[:, k]) / s, np.where(s < 0, (-half - pts[:, k]) / s, np.inf))
                         for k, s in enumerate(slope_xy)]
            reach = min(reach, float(np.minimum(*exits).max()))
        if reach < 0.0:
            return 0
        margin = 1e-6 * (abs(reach) + 1.0) + self.cell_m  # rounding of the marched positions and heights
        return int(np.searchsorted(t, reach + margin, side="right"))

    def _blocked_block(self, pts: np.ndarray, d: np.ndarray, t: np.ndarray, box_lo: np.ndarray | None,
                       box_hi: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`blocked_whole_and_within` for one block of points (m, 3), directions (D, 3), marched
        distances (T,)."""
        horiz = np.maximum(np.linalg.norm(d[:, :2], axis=1), 1e-6)
        n = self.heights_m.shape[0]
        whole = np.zeros((len(pts), len(d)), dtype=bool)
        within = None if box_lo is None else np.zeros((len(pts), len(d)), dtype=bool)
        for j in range(len(d)):
            slope_xy = d[j, :2] / horiz[j]
            slope_z = d[j, 2] / horiz[j]
            k = self._march_steps(pts, slope_xy, float(slope_z), t)
            if k == 0:
                continue
            tj = t[:k]
            pos = pts[:, None, :2] + (tj[None, :, None] * slope_xy[None, None, :])
            z = pts[:, None, 2] + tj[None, :] * slope_z
            ij = np.floor((pos + self.half_extent_m) / self.cell_m).astype(np.int64)
            inside = ((ij >= 0) & (ij < n)).all(axis=-1)
            ij = np.clip(ij, 0, n - 1)
            h = self.heights_m[ij[..., 0], ij[..., 1]]
            hit = inside & (h > z) & (z < 200.0)
            whole[:, j] = hit.any(axis=-1)
            if within is not None:
                inbox = ((pos >= box_lo[:2]) & (pos <= box_hi[:2])).all(axis=-1)
                within[:, j] = (hit & inbox).any(axis=-1)
        return whole, within


def _hemisphere_dirs(n_el: int = 4, n_az: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Upper-hemisphere directions (D, 3) with cosine-weighted quadrature weights (D,) summing to 1."""
    el_edges = np.linspace(0.0, np.pi / 2, n_el + 1)
    el = 0.5 * (el_edges[:-1] + el_edges[1:])
    az = (np.arange(n_az) + 0.5) * 2 * np.pi / n_az
    E, A = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    # cosine-weighted solid angle of each band: integral of sin(el) cos(el) d(el)
    band = 0.5 * (np.sin(el_edges[1:]) ** 2 - np.sin(el_edges[:-1]) ** 2)
    w = np.repeat(band[:, None], n_az, axis=1).reshape(-1) / n_az
    return d, w / w.sum()


def region_points(centre_vol: np.ndarray, half_size_m: float = 2.5, n: int = 3, height_m: float = 0.05) -> np.ndarray:
    """(n*n, 3) ground points around a placement (volume frame) at which levels are compared."""
    c = np.linspace(-half_size_m, half_size_m, n)
    gx, gy = np.meshgrid(c, c)
    p = np.stack([gx.ravel() + centre_vol[0], gy.ravel() + centre_vol[1], np.full(gx.size, height_m)], axis=1)
    return p


def predicted_errors(hmap: HeightMap, points_vol: np.ndarray, sun_dir: np.ndarray | None, e_sun: float,
                     e_sky_h: float, l0_irradiance: float | None, l2_centre_xy: np.ndarray) -> tuple[dict, dict]:
    """Predicted error per level at points (M, 3) on the ground (upward normal), and the evidence behind it.

    ``e_sun`` is the sun's irradiance facing it and ``e_sky_h`` the open sky's horizontal irradiance (same
    units; ``l0_irradiance`` too). Returns ({level: error}, evidence dict).
    """
    dirs, w = _hemisphere_dirs()
    sun_ok = sun_dir is not None and e_sun > 0 and sun_dir[2] > 0
    all_dirs = np.concatenate([dirs, sun_dir[None]]) if sun_ok else dirs
    l2 = np.array([*l2_centre_xy, 0.0])
    R2 = np.full(3, 40.0)
    block3, block2 = hmap.blocked_whole_and_within(points_vol, all_dirs, l2 - R2, l2 + R2)
    e_sun_h = e_sun * sun_dir[2] if sun_ok else 0.0
    wall = WALL_RHO * (0.5 * e_sky_h + 0.25 * e_sun_h)  # pi x radiance of a lit wall

    def irradiance(block: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        m = len(points_vol)
        sky_blocked = np.zeros(m) if block is None else block[:, : len(dirs)] @ w
        sun_vis = np.ones(m) if block is None or not sun_ok else 1.0 - block[:, -1]
        e_dir = e_sun_h * sun_vis
        return e_dir + e_sky_h * (1.0 - sky_blocked) + wall * sky_blocked, e_dir

    best, best_dir = irradiance(block3)
    share_best = best_dir / np.maximum(best, 1e-12)
    errors = {}
    for level, block in (("L1", None), ("L2", block2), ("L3", block3)):
        e, e_dir = irradiance(block)
        err = np.abs(e - best) / np.maximum(best, 1e-12) + np.abs(e_dir / np.maximum(e, 1e-12) - share_best)
        errors[level] = float(err.mean())
    if l0_irradiance is not None:
        err0 = np.abs(l0_irradiance - best) / np.maximum(best, 1e-12) + share_best
        errors["L0"] = float(err0.mean())
    evidence = {
        "points": int(len(points_vol)),
        "sun_blocked_fraction": float(block3[:, -1].mean()) if sun_ok else None,
        "sun_blocked_fraction_within_l2": float(block2[:, -1].mean()) if sun_ok else None,
        "sky_blocked_fraction": float((block3[:, : len(dirs)] @ w).mean()),
        "shadow_boundary": bool(sun_ok and 0 < block3[:, -1].sum() < len(points_vol)),
    }
    return errors, evidence


def choose_level(errors: dict, tolerance: float = AUTO_TOLERANCE) -> tuple[str, str]:
    """The cheapest level whose predicted error is within ``tolerance`` of the best; (level, reason)."""
    best = min(errors.values())
    for level in LEVELS:
        if level in errors and errors[level] <= best + tolerance:
            listing = ", ".join(f"{k} {errors[k]:.3f}" for k in LEVELS if k in errors)
            return level, (f"auto: {level} is the cheapest level within {tolerance:.2f} of the best predicted "
                           f"error (irradiance + sun-share error at the placement: {listing})")
    raise AssertionError("unreachable")
