"""The nuScenes map expansion: the ``drivable_area`` layer as shapely geometry, lane centre lines (global x/y).

File ``<dataroot>/maps/expansion/<location>.json`` (map expansion v1.x) holds, among other layers:

* ``node``: ``{token, x, y}`` -- vertices in the global (map) frame, metres (x east, y north);
* ``polygon``: ``{token, exterior_node_tokens, holes: [{node_tokens}]}``;
* ``drivable_area``: ``{token, polygon_tokens}`` (v1.0 files: a single ``polygon_token``);
* ``walkway``, ``ped_crossing``: ``{token, polygon_token}`` (sidewalks and zebra crossings, see :func:`read_area_layer`);
* ``lane`` / ``lane_connector``: ``{token, polygon_token, from_edge_line_token, to_edge_line_token, ...}``
  with centre lines in ``arcline_path_3`` (``{lane_token: [arcline path, ...]}``), see :func:`read_lanes`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon, box
from shapely.strtree import STRtree

from streetaug.augment.core import read_json

from .errors import DatasetError

if TYPE_CHECKING:  # scipy (~0.2 s to import) only when a lane look-up builds its tree
    from scipy.spatial import cKDTree


def map_expansion_path(dataroot: str | Path, location: str) -> Path:
    """Path of the map expansion JSON of ``location`` (e.g. ``singapore-onenorth``)."""
    return Path(dataroot) / "maps" / "expansion" / f"{location}.json"


def read_map_expansion(path: str | Path) -> dict:
    """The parsed JSON object of a map expansion file (clear errors when missing or malformed).

    Real map expansions are 100+ MB: parse once and hand the dict to :func:`read_drivable_area` and
    :func:`read_lanes` (their ``data`` argument).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: map expansion file not found")
    data = read_json(path)  # names the file when it is not JSON, not UTF-8 or nested too deeply
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: map expansion must be a JSON object")
    return data


def read_drivable_area(path: str | Path, data: dict | None = None) -> list[Polygon | MultiPolygon]:
    """Read the ``drivable_area`` layer of a map expansion file (``data``: its already parsed JSON).

    Returns:
        One shapely (Multi)Polygon per ``drivable_area`` record, global x/y in metres (holes kept).
    """
    return read_area_layer(path, "drivable_area", data)


AREA_LAYERS = ("drivable_area", "walkway", "ped_crossing", "carpark_area")


def read_area_layer(path: str | Path, layer: str, data: dict | None = None,
                    required: bool = True) -> list[Polygon | MultiPolygon]:
    """Read a polygon layer (``drivable_area``, ``walkway``, ``ped_crossing``, ...) of a map expansion file.

    Records carry ``polygon_token`` or ``polygon_tokens``; a record of several polygons is their union.
    Without ``required`` a missing layer reads as empty (older expansions lack some layers).

    Returns:
        One shapely (Multi)Polygon per record, global x/y in metres (holes kept).
    """
    path = Path(path)
    if data is None:
        data = read_map_expansion(path)
    if not required and isinstance(data, dict) and data.get(layer) is None:
        return []
    for name in ("node", "polygon", layer):
        if not isinstance(data, dict) or not isinstance(data.get(name), list):
            raise DatasetError(f"{path}: map expansion has no '{name}' layer (a list of records expected)")
    if not data[layer]:
        return []
    try:
        xy_by_node = {n["token"]: (float(n["x"]), float(n["y"])) for n in data["node"]}
        rings_by_polygon = {p["token"]: p for p in data["polygon"]}

        def ring(tokens: list[str], what: str) -> np.ndarray:
            missing = [t for t in tokens if t not in xy_by_node]
            if missing:
                raise DatasetError(f"{path}: {what} refers to unknown node token '{missing[0]}'")
            return np.array([xy_by_node[t] for t in tokens], dtype=np.float64)

        def polygon(token: str) -> Polygon:
            if token not in rings_by_polygon:
                raise DatasetError(f"{path}: {layer} refers to unknown polygon token '{token}'")
            rec = rings_by_polygon[token]
            exterior = ring(rec["exterior_node_tokens"], f"polygon '{token}'")
            holes = [ring(h["node_tokens"], f"hole of polygon '{token}'") for h in rec.get("holes", [])]
            poly = Polygon(exterior, [h for h in holes if len(h) >= 3])
            return poly if poly.is_valid else _polygonal(shapely.make_valid(poly))

        areas = []
        for rec in data[layer]:
            tokens = rec["polygon_tokens"] if "polygon_tokens" in rec else [rec["polygon_token"]]
            polys = [polygon(t) for t in tokens]
            areas.append(polys[0] if len(polys) == 1 else shapely.union_all(polys))
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, DatasetError):
            raise
        raise DatasetError(f"{path}: malformed map expansion record in '{layer}' ({type(e).__name__}: {e})") from None
    return areas


def _polygonal(geometry) -> Polygon | MultiPolygon:
    """Keep only the polygonal parts of a geometry (``make_valid`` may add stray lines or points)."""
    if isinstance(geometry, (Polygon, MultiPolygon)):
        return geometry
    parts = [g for g in getattr(geometry, "geoms", []) if isinstance(g, (Polygon, MultiPolygon))]
    return shapely.union_all(parts) if parts else Polygon()


@dataclass(frozen=True)
class DrivableArea:
    """The drivable area of one location with a spatial index.

    Attributes:
        geometries: shapely (Multi)Polygons in global x/y, metres, one per map record.
    """

    geometries: list
    tree: STRtree

    @classmethod
    def from_file(cls, path: str | Path, data: dict | None = None) -> "DrivableArea":
        geometries = read_drivable_area(path, data)
        return cls(geometries, STRtree(geometries))

    def near(self, xy_global: np.ndarray, radius_m: float):
        """Union of the drivable area clipped to the square of half-side ``radius_m`` around ``xy_global``.

        Args:
            xy_global: (2,) global x/y, metres.
            radius_m: half the side of the square, metres.

        Returns:
            A shapely geometry (possibly empty) in global x/y.
        """
        x, y = (float(v) for v in np.asarray(xy_global, dtype=np.float64)[:2])
        if not radius_m > 0:
            raise ValueError(f"radius_m must be positive, got {radius_m}")
        window = box(x - radius_m, y - radius_m, x + radius_m, y + radius_m)
        idx = self.tree.query(window)
        if len(idx) == 0:
            return Polygon()
        return shapely.union_all([self.geometries[i].intersection(window) for i in idx])

    def contains_xy(self, xy_global: np.ndarray) -> np.ndarray:
        """(N,) bool: which global x/y points (N, 2) lie on the drivable area."""
        xy = np.asarray(xy_global, dtype=np.float64).reshape(-1, 2)
        points = shapely.points(xy)
        inside = np.zeros(len(xy), dtype=bool)
        point_idx, _ = self.tree.query(points, predicate="intersects")
        inside[point_idx] = True
        return inside


# ---------------------------------------------------------------------- lanes

LANE_LAYERS = ("lane", "lane_connector")


@dataclass(frozen=True)
class LaneCenterlines:
    """Lane centre lines of a map expansion, densely sampled, with the direction of travel.

    Attributes:
        points_xy: (N, 2) float64 centre-line samples, global x/y, metres (spacing <= ``resolution_m``).
        heading_rad: (N,) float64 direction of travel at each sample, radians from global +x towards +y.
        lane_index: (N,) int64 index into ``tokens`` of the lane each sample belongs to.
        tokens: the ``lane`` / ``lane_connector`` tokens.
        resolution_m: sampling step along the centre lines.
    """

    points_xy: np.ndarray
    heading_rad: np.ndarray
    lane_index: np.ndarray
    tokens: tuple[str, ...]
    resolution_m: float = 0.5

    @functools.cached_property
    def _tree(self) -> cKDTree:
        from scipy.spatial import cKDTree

        return cKDTree(self.points_xy)

    def __len__(self) -> int:
        return len(self.tokens)

    def heading_at(self, xy_global: np.ndarray, max_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Direction of travel of the nearest centre line at global x/y points (M, 2).

        Returns:
            (heading_rad (M,) float64, found (M,) bool): ``found`` is False (heading NaN) where no
            centre-line sample lies within ``max_distance_m``.
        """
        xy = np.asarray(xy_global, dtype=np.float64).reshape(-1, 2)
        if len(self.points_xy) == 0 or len(xy) == 0:
            return np.full(len(xy), np.nan), np.zeros(len(xy), dtype=bool)
        dist, idx = self._tree.query(xy, distance_upper_bound=max_distance_m)
        found = np.isfinite(dist)
        heading = np.full(len(xy), np.nan)
        heading[found] = self.heading_rad[idx[found]]
        return heading, found


def _advance_pose(x: float, y: float, theta: float, curvature: float, s: np.ndarray):
    """Poses (x, y, theta) after driving arc lengths ``s`` (K,) at constant curvature (1/m, + = left)."""
    if abs(curvature) < 1e-9:
        return x + s * np.cos(theta), y + s * np.sin(theta), np.full_like(s, theta)
    th = theta + curvature * s
    return x + (np.sin(th) - np.sin(theta)) / curvature, y - (np.cos(th) - np.cos(theta)) / curvature, th


def discretize_arcline_path(path: dict, resolution_m: float = 0.5) -> np.ndarray:
    """Samples (K, 3) = (x, y, heading_rad) along one ``arcline_path_3`` record, ends included.

    Record: ``start_pose`` [x, y, yaw] (global, yaw rad from +x towards +y), ``shape`` (3 letters of
    L = left arc, S = straight, R = right arc), ``radius`` (m), ``segment_length`` (3 lengths, m).
    """
    x, y, th = (float(v) for v in path["start_pose"])
    shape = str(path["shape"])
    lengths = [float(v) for v in path["segment_length"]]
    radius = float(path["radius"])
    if len(shape) != 3 or len(lengths) != 3 or set(shape) - set("LSR") or radius <= 0 or min(lengths) < 0:
        raise ValueError(f"arcline path: expected shape of 3 letters L/S/R, 3 lengths >= 0, radius > 0; got "
                         f"shape {shape!r}, segment_length {lengths}, radius {radius}")
    out = [np.array([[x, y, th]])]
    for letter, length in zip(shape, lengths):
        if length <= 0:
            continue
        k = {"L": 1.0 / radius, "S": 0.0, "R": -1.0 / radius}[letter]
        n = max(int(np.ceil(length / resolution_m)), 1)
        s = np.linspace(0.0, length, n + 1)[1:]
        xs, ys, ths = _advance_pose(x, y, th, k, s)
        out.append(np.c_[xs, ys, ths])
        x, y, th = float(xs[-1]), float(ys[-1]), float(ths[-1])
    return np.concatenate(out)


def _straight_centreline(a_xy: np.ndarray, b_xy: np.ndarray, resolution_m: float) -> np.ndarray:
    """Samples (K, 3) of the straight line from ``a_xy`` to ``b_xy`` with its heading."""
    d = b_xy - a_xy
    n = max(int(np.ceil(np.linalg.norm(d) / resolution_m)), 1)
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    p = a_xy + t * d
    return np.c_[p, np.full(len(p), np.arctan2(d[1], d[0]))]


def read_lanes(path: str | Path, resolution_m: float = 0.5, data: dict | None = None) -> LaneCenterlines | None:
    """Lane centre lines of the ``lane`` and ``lane_connector`` layers of a map expansion file.

    Each lane's centre line comes from its ``arcline_path_3`` entry (``{lane_token: [path, ...]}``,
    map expansion v1.2+). A lane without arcline paths but with ``from_edge_line_token`` /
    ``to_edge_line_token`` (v1.0 files) gets the straight line between the midpoints of those two
    edge lines (the direction of travel is from the "from" edge to the "to" edge). Lanes with
    neither are skipped.

    ``data``: the file's already parsed JSON (see :func:`read_map_expansion`).

    Returns:
        The centre lines, or None when the file has no lane with a usable centre line (e.g. the
        nuScenes-mini excerpts, which carry only ``drivable_area``).
    """
    path = Path(path)
    if data is None:
        data = read_map_expansion(path)
    arclines = data.get("arcline_path_3") or {}
    if not isinstance(arclines, dict):
        raise DatasetError(f"{path}: 'arcline_path_3' must map lane tokens to lists of arcline paths")
    samples, tokens = [], []
    try:
        xy_by_node = {n["token"]: (float(n["x"]), float(n["y"])) for n in data.get("node", [])}
        lines = {ln["token"]: ln for ln in data.get("line", [])}

        def line_mid(token: str | None) -> np.ndarray | None:
            if not token or token not in lines:
                return None
            nodes = [xy_by_node[t] for t in lines[token].get("node_tokens", []) if t in xy_by_node]
            return np.mean(np.asarray(nodes), axis=0) if nodes else None

        for layer in LANE_LAYERS:
            records = data.get(layer) or []
            if not isinstance(records, list):
                raise DatasetError(f"{path}: '{layer}' must be a list of records")
            for rec in records:
                tok = rec["token"]
                if tok in arclines and arclines[tok]:
                    pts = np.concatenate([discretize_arcline_path(p, resolution_m) for p in arclines[tok]])
                else:
                    a, b = line_mid(rec.get("from_edge_line_token")), line_mid(rec.get("to_edge_line_token"))
                    if a is None or b is None or np.linalg.norm(b - a) < 1e-3:
                        continue
                    pts = _straight_centreline(a, b, resolution_m)
                samples.append(pts)
                tokens.append(tok)
    except (KeyError, TypeError, ValueError) as e:
        raise DatasetError(f"{path}: malformed lane record ({type(e).__name__}: {e})") from None
    if not samples:
        return None
    idx = np.concatenate([np.full(len(s), i, dtype=np.int64) for i, s in enumerate(samples)])
    allp = np.concatenate(samples)
    heading = np.mod(allp[:, 2] + np.pi, 2 * np.pi) - np.pi
    return LaneCenterlines(allp[:, :2].copy(), heading, idx, tuple(tokens), resolution_m)
