"""Writing generated scenes as a nuScenes v1.0 dataset: tables, lidarseg index and map expansion.

Only deterministic content: tokens are md5 hashes of descriptive strings, JSON keys are sorted,
floats are rounded to fixed precision, nothing depends on the current time.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from streetaug.augment.core import rotation_to_quat, write_bytes_atomic
from streetaug.datasets.nuscenes_format import ATTRIBUTES, CATEGORY_NAMES, VISIBILITY_LEVELS, content_token

# Map canvas sizes (metres) of the nuScenes map expansion (public devkit facts).
CANVAS_EDGE = {
    "boston-seaport": [2979.5, 2118.1],
    "singapore-onenorth": [1585.6, 2025.0],
    "singapore-hollandvillage": [2808.3, 2922.9],
    "singapore-queenstown": [3228.6, 3687.1],
}
MAP_LAYERS_LIST = (
    "carpark_area", "drivable_area", "lane", "lane_connector", "lane_divider", "line", "node",
    "ped_crossing", "polygon", "road_block", "road_divider", "road_segment", "stop_line",
    "traffic_light", "walkway",
)
MAP_LAYERS_DICT = ("arcline_path_3", "connectivity")


def _r(x: Any, nd: int) -> Any:
    """Round floats (scalars or nested sequences) to ``nd`` decimals, as plain Python types."""
    a = np.asarray(x, dtype=np.float64)
    return np.round(a, nd).tolist() if a.ndim else float(np.round(a, nd))


def dumps(obj: Any) -> bytes:
    return (json.dumps(obj, indent=1, sort_keys=True) + "\n").encode()


@dataclass
class NuScenesTables:
    """Accumulates the rows of every table; :meth:`write` stores them under ``dataroot/version``."""

    version: str
    rows: dict[str, list[dict]] = field(default_factory=dict)
    map_polygons: dict[str, list[np.ndarray]] = field(default_factory=dict)
    map_lanes: dict[str, list[tuple[np.ndarray, np.ndarray, float]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("attribute", "calibrated_sensor", "category", "ego_pose", "instance", "log", "map",
                     "sample", "sample_annotation", "sample_data", "scene", "sensor", "visibility", "lidarseg"):
            self.rows.setdefault(name, [])
        self.rows["category"] = [
            {"token": content_token("category", n), "name": n, "index": i, "description": f"nuScenes class {n}."}
            for i, n in enumerate(CATEGORY_NAMES)
        ]
        self.rows["attribute"] = [
            {"token": content_token("attribute", n), "name": n, "description": d} for n, d in ATTRIBUTES.items()
        ]
        self.rows["visibility"] = [
            {"token": t, "level": lvl, "description": f"visibility of whole object is {lvl[1:].replace('-', ' to ')} %"}
            for t, (lvl, _) in VISIBILITY_LEVELS.items()
        ]

    # ------------------------------------------------------------------ rows

    def add_sensor(self, channel: str, modality: str) -> str:
        tok = content_token("sensor", channel)
        if all(r["token"] != tok for r in self.rows["sensor"]):
            self.rows["sensor"].append({"token": tok, "channel": channel, "modality": modality})
        return tok

    def add_log(self, name: str, logfile: str, location: str, date_captured: str) -> str:
        tok = content_token("log", name)
        self.rows["log"].append({"token": tok, "logfile": logfile, "vehicle": logfile.split("-")[0],
                                 "date_captured": date_captured, "location": location})
        return tok

    def add_scene(self, name: str, description: str, log_token: str, sample_token: str) -> str:
        tok = content_token("scene", name)
        self.rows["scene"].append({"token": tok, "name": name, "description": description, "log_token": log_token,
                                   "nbr_samples": 1, "first_sample_token": sample_token,
                                   "last_sample_token": sample_token})
        return tok

    def add_sample(self, sample_token: str, scene_token: str, timestamp_us: int) -> None:
        self.rows["sample"].append({"token": sample_token, "timestamp": int(timestamp_us), "scene_token": scene_token,
                                    "prev": "", "next": ""})

    def add_sample_data(self, scene_name: str, channel: str, modality: str, sample_token: str, timestamp_us: int,
                        filename: str, width: int, height: int, T_ego_from_sensor: np.ndarray,
                        T_global_from_ego: np.ndarray, K: np.ndarray | None) -> str:
        """Adds sample_data + its ego_pose (same token, as in nuScenes) + calibrated_sensor; returns the token."""
        sd_tok = content_token("sample_data", scene_name, channel)
        cs_tok = content_token("calibrated_sensor", scene_name, channel)
        self.rows["calibrated_sensor"].append({
            "token": cs_tok, "sensor_token": self.add_sensor(channel, modality),
            "translation": _r(T_ego_from_sensor[:3, 3], 6), "rotation": _r(rotation_to_quat(T_ego_from_sensor[:3, :3]), 10),
            "camera_intrinsic": [] if K is None else _r(K, 6),
        })
        self.rows["ego_pose"].append({
            "token": sd_tok, "timestamp": int(timestamp_us),
            "translation": _r(T_global_from_ego[:3, 3], 6), "rotation": _r(rotation_to_quat(T_global_from_ego[:3, :3]), 10),
        })
        self.rows["sample_data"].append({
            "token": sd_tok, "sample_token": sample_token, "ego_pose_token": sd_tok, "calibrated_sensor_token": cs_tok,
            "timestamp": int(timestamp_us), "fileformat": "pcd" if modality == "lidar" else "jpg",
            "is_key_frame": True, "height": int(height), "width": int(width), "filename": filename,
            "prev": "", "next": "",
        })
        return sd_tok

    def add_annotation(self, scene_name: str, index: int, sample_token: str, category: str, translation: np.ndarray,
                       size_wlh: np.ndarray, rotation: np.ndarray, attribute: str, num_lidar_pts: int,
                       visibility: str) -> str:
        ann_tok = content_token("sample_annotation", scene_name, index)
        inst_tok = content_token("instance", scene_name, index)
        self.rows["instance"].append({"token": inst_tok, "category_token": content_token("category", category),
                                      "nbr_annotations": 1, "first_annotation_token": ann_tok,
                                      "last_annotation_token": ann_tok})
        self.rows["sample_annotation"].append({
            "token": ann_tok, "sample_token": sample_token, "instance_token": inst_tok,
            "visibility_token": visibility, "attribute_tokens": [content_token("attribute", attribute)] if attribute else [],
            "translation": _r(translation, 3), "size": _r(size_wlh, 3), "rotation": _r(rotation, 10),
            "prev": "", "next": "", "num_lidar_pts": int(num_lidar_pts), "num_radar_pts": 0,
        })
        return ann_tok

    def add_lidarseg(self, lidar_sd_token: str) -> str:
        filename = f"lidarseg/{self.version}/{lidar_sd_token}_lidarseg.bin"
        self.rows["lidarseg"].append({"token": lidar_sd_token, "sample_data_token": lidar_sd_token, "filename": filename})
        return filename

    def add_map_polygon(self, location: str, log_token: str, polygon_xy: np.ndarray) -> None:
        """Register a drivable-area polygon (N, 2) global x/y of a log at ``location``."""
        self.map_polygons.setdefault(location, []).append(np.asarray(polygon_xy, dtype=np.float64))
        tok = content_token("map", location)
        row = next((r for r in self.rows["map"] if r["token"] == tok), None)
        if row is None:
            row = {"token": tok, "category": "semantic_prior", "filename": "", "log_tokens": []}
            self.rows["map"].append(row)
        if log_token not in row["log_tokens"]:
            row["log_tokens"].append(log_token)

    def add_map_lane(self, location: str, start_xy: np.ndarray, end_xy: np.ndarray, width_m: float) -> None:
        """Register a straight travel lane of ``location`` (centre line from ``start_xy`` to ``end_xy``)."""
        self.map_lanes.setdefault(location, []).append(
            (np.asarray(start_xy, dtype=np.float64), np.asarray(end_xy, dtype=np.float64), float(width_m)))

    # ------------------------------------------------------------------ output

    def map_expansion(self, location: str) -> dict:
        """The map expansion JSON of ``location``: node / polygon / drivable_area layers, the rest empty."""
        m: dict[str, Any] = {name: [] for name in MAP_LAYERS_LIST}
        m.update({name: {} for name in MAP_LAYERS_DICT})
        m["version"] = "1.3"
        m["canvas_edge"] = CANVAS_EDGE.get(location, [4000.0, 4000.0])
        for k, poly in enumerate(self.map_polygons.get(location, [])):
            node_tokens = []
            for j, (x, y) in enumerate(poly):
                nt = content_token("node", location, k, j)
                m["node"].append({"token": nt, "x": _r(x, 4), "y": _r(y, 4)})
                node_tokens.append(nt)
            pt = content_token("polygon", location, k)
            m["polygon"].append({"token": pt, "exterior_node_tokens": node_tokens, "holes": []})
            m["drivable_area"].append({"token": content_token("drivable_area", location, k), "polygon_tokens": [pt]})
        for k, (a, b, width) in enumerate(self.map_lanes.get(location, [])):
            # A lane: its area as a polygon, and its centre line as one straight arcline path ("LSR" with
            # zero-length arcs), the format of the nuScenes map expansion v1.3.
            d = (b - a) / np.linalg.norm(b - a)
            n = np.array([-d[1], d[0]]) * width / 2
            node_tokens = []
            for j, (x, y) in enumerate([a - n, b - n, b + n, a + n]):
                nt = content_token("lane_node", location, k, j)
                m["node"].append({"token": nt, "x": _r(x, 4), "y": _r(y, 4)})
                node_tokens.append(nt)
            pt = content_token("lane_polygon", location, k)
            m["polygon"].append({"token": pt, "exterior_node_tokens": node_tokens, "holes": []})
            lt = content_token("lane", location, k)
            m["lane"].append({"token": lt, "polygon_token": pt, "lane_type": "CAR", "from_edge_line_token": None,
                              "to_edge_line_token": None, "left_lane_divider_segments": [],
                              "right_lane_divider_segments": []})
            yaw = float(np.arctan2(d[1], d[0]))
            m["arcline_path_3"][lt] = [{
                "start_pose": [_r(a[0], 4), _r(a[1], 4), _r(yaw, 9)],
                "end_pose": [_r(b[0], 4), _r(b[1], 4), _r(yaw, 9)],
                "shape": "LSR", "radius": 999.0, "segment_length": [0.0, _r(float(np.linalg.norm(b - a)), 4), 0.0],
            }]
        return m

    def write(self, dataroot: Path) -> list[Path]:
        """Write every table to ``dataroot/version/*.json`` and the map expansions; returns the paths."""
        written = []
        table_dir = Path(dataroot) / self.version
        for name, rows in sorted(self.rows.items()):
            if name == "lidarseg" and not rows:
                continue
            path = table_dir / f"{name}.json"
            write_bytes_atomic(path, dumps(rows))
            written.append(path)
        for location in sorted(self.map_polygons):
            path = Path(dataroot) / "maps" / "expansion" / f"{location}.json"
            write_bytes_atomic(path, dumps(self.map_expansion(location)))
            written.append(path)
        return written
