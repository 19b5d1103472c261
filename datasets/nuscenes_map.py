"""The nuScenes map expansion's ``drivable_area`` layer as shapely geometry in global x/y.

File ``<dataroot>/maps/expansion/<location>.json`` (map expansion v1.x) holds, among other layers:

* ``node``: ``{token, x, y}`` -- vertices in the global (map) frame, metres (x east, y north);
* ``polygon``: ``{token, exterior_node_tokens, holes: [{node_tokens}]}``;
* ``drivable_area``: ``{token, polygon_tokens}`` (v1.0 files: a single ``polygon_token``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon, box
from shapely.strtree import STRtree

from .errors import DatasetError


def map_expansion_path(dataroot: str | Path, location: str) -> Path:
    """Path of the map expansion JSON of ``location`` (e.g. ``singapore-onenorth``)."""
    return Path(dataroot) / "maps" / "expansion" / f"{location}.json"


def read_drivable_area(path: str | Path) -> list[Polygon | MultiPolygon]:
    """Read the ``drivable_area`` layer of a map expansion file.

    Returns:
        One shapely (Multi)Polygon per ``drivable_area`` record, global x/y in metres (holes kept).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: map expansion file not found")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: map expansion file is not valid JSON ({e})") from None
    for layer in ("node", "polygon", "drivable_area"):
        if not isinstance(data, dict) or not isinstance(data.get(layer), list):
            raise DatasetError(f"{path}: map expansion has no '{layer}' layer (a list of records expected)")
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
                raise DatasetError(f"{path}: drivable_area refers to unknown polygon token '{token}'")
            rec = rings_by_polygon[token]
            exterior = ring(rec["exterior_node_tokens"], f"polygon '{token}'")
            holes = [ring(h["node_tokens"], f"hole of polygon '{token}'") for h in rec.get("holes", [])]
            poly = Polygon(exterior, [h for h in holes if len(h) >= 3])
            return poly if poly.is_valid else _polygonal(shapely.make_valid(poly))

        areas = []
        for rec in data["drivable_area"]:
            tokens = rec["polygon_tokens"] if "polygon_tokens" in rec else [rec["polygon_token"]]
            polys = [polygon(t) for t in tokens]
            areas.append(polys[0] if len(polys) == 1 else shapely.union_all(polys))
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, DatasetError):
            raise
        raise DatasetError(f"{path}: malformed map expansion record ({type(e).__name__}: {e})") from None
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
    def from_file(cls, path: str | Path) -> "DrivableArea":
        geometries = read_drivable_area(path)
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
