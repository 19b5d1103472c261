"""nuScenes tables of a generated scene *through time*: samples, keyframes and sweeps, annotation tracks.

Extends :class:`NuScenesTables` (which writes one keyframe per scene) with the rows a sequence needs,
linked as in nuScenes:

- ``scene``: ``nbr_samples``, ``first_sample_token``, ``last_sample_token``; ``sample``: ``prev`` / ``next``.
- ``calibrated_sensor``: one row per scene and channel; ``sample_data`` + ``ego_pose`` (same token): one
  row per captured frame, keyframe or sweep, ``prev`` / ``next`` chaining every frame of a channel in time
  order (keyframes and sweeps alike, see :meth:`SequenceTables.link_frames`).
- ``instance``: ``nbr_annotations``, ``first`` / ``last_annotation_token``; ``sample_annotation``: ``prev`` /
  ``next`` along the instance's samples in time order (see :meth:`SequenceTables.link_annotations`).

Tokens are md5 hashes of descriptive strings (deterministic, see ``content_token``).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from streetaug.augment.core import rotation_to_quat
from streetaug.datasets.nuscenes_format import content_token

from .nuscenes_tables import NuScenesTables, _r


class SequenceTables(NuScenesTables):
    """:class:`NuScenesTables` with multi-sample scenes, sweeps and annotation tracks."""

    def add_sequence_scene(self, name: str, description: str, log_token: str, sample_tokens: list[str]) -> str:
        """Add a scene of ``sample_tokens`` (time order); returns the scene token."""
        tok = content_token("scene", name)
        self.rows["scene"].append({"token": tok, "name": name, "description": description, "log_token": log_token,
                                   "nbr_samples": len(sample_tokens), "first_sample_token": sample_tokens[0],
                                   "last_sample_token": sample_tokens[-1]})
        return tok

    def add_linked_sample(self, sample_token: str, scene_token: str, timestamp_us: int, prev: str, next_: str) -> None:
        """Add a ``sample`` row with its ``prev`` / ``next`` sample tokens ('' at the ends)."""
        self.rows["sample"].append({"token": sample_token, "timestamp": int(timestamp_us), "scene_token": scene_token,
                                    "prev": prev, "next": next_})

    def add_calibrated_sensor(self, scene_name: str, channel: str, modality: str, T_ego_from_sensor: np.ndarray,
                              K: np.ndarray | None) -> str:
        """Add the calibration (sensor -> ego, intrinsics for cameras) of a channel in a scene; returns its token."""
        cs_tok = content_token("calibrated_sensor", scene_name, channel)
        self.rows["calibrated_sensor"].append({
            "token": cs_tok, "sensor_token": self.add_sensor(channel, modality),
            "translation": _r(T_ego_from_sensor[:3, 3], 6),
            "rotation": _r(rotation_to_quat(T_ego_from_sensor[:3, :3]), 10),
            "camera_intrinsic": [] if K is None else _r(K, 6),
        })
        return cs_tok

    def add_frame(self, scene_name: str, channel: str, modality: str, calibrated_sensor_token: str,
                  sample_token: str, timestamp_us: int, filename: str, width: int, height: int,
                  T_global_from_ego: np.ndarray, is_key_frame: bool) -> str:
        """Add one captured frame: a ``sample_data`` row and its ``ego_pose`` (same token, as in nuScenes).

        ``prev`` / ``next`` are left empty; :meth:`link_frames` fills them once every frame is added.
        Returns the token.
        """
        sd_tok = content_token("sample_data", scene_name, channel, int(timestamp_us))
        self.rows["ego_pose"].append({
            "token": sd_tok, "timestamp": int(timestamp_us), "translation": _r(T_global_from_ego[:3, 3], 6),
            "rotation": _r(rotation_to_quat(T_global_from_ego[:3, :3]), 10),
        })
        self.rows["sample_data"].append({
            "token": sd_tok, "sample_token": sample_token, "ego_pose_token": sd_tok,
            "calibrated_sensor_token": calibrated_sensor_token, "timestamp": int(timestamp_us),
            "fileformat": "pcd" if modality == "lidar" else "jpg", "is_key_frame": bool(is_key_frame),
            "height": int(height), "width": int(width), "filename": filename, "prev": "", "next": "",
        })
        return sd_tok

    def link_frames(self) -> None:
        """Chain the ``sample_data`` rows of each calibrated sensor (= scene x channel) by timestamp."""
        by_sensor: dict[str, list[dict]] = defaultdict(list)
        for row in self.rows["sample_data"]:
            by_sensor[row["calibrated_sensor_token"]].append(row)
        for rows in by_sensor.values():
            rows.sort(key=lambda r: r["timestamp"])
            for a, b in zip(rows[:-1], rows[1:]):
                a["next"], b["prev"] = b["token"], a["token"]

    def add_track_annotation(self, scene_name: str, index: int, sample_index: int, sample_token: str,
                             category: str, translation: np.ndarray, size_wlh: np.ndarray, rotation: np.ndarray,
                             attribute: str, num_lidar_pts: int, visibility: str) -> str:
        """Add the annotation of object ``index`` at sample ``sample_index`` (its instance on first use).

        ``prev`` / ``next`` and the instance's counts are set by :meth:`link_annotations`. Returns the token.
        """
        ann_tok = content_token("sample_annotation", scene_name, index, sample_index)
        inst_tok = content_token("instance", scene_name, index)
        if all(r["token"] != inst_tok for r in self.rows["instance"]):
            self.rows["instance"].append({"token": inst_tok, "category_token": content_token("category", category),
                                          "nbr_annotations": 0, "first_annotation_token": "",
                                          "last_annotation_token": ""})
        self.rows["sample_annotation"].append({
            "token": ann_tok, "sample_token": sample_token, "instance_token": inst_tok,
            "visibility_token": visibility,
            "attribute_tokens": [content_token("attribute", attribute)] if attribute else [],
            "translation": _r(translation, 3), "size": _r(size_wlh, 3), "rotation": _r(rotation, 10),
            "prev": "", "next": "", "num_lidar_pts": int(num_lidar_pts), "num_radar_pts": 0,
        })
        return ann_tok

    def link_annotations(self) -> None:
        """Chain each instance's annotations by their sample's timestamp; set the instance's counts and ends."""
        t_sample = {r["token"]: r["timestamp"] for r in self.rows["sample"]}
        by_instance: dict[str, list[dict]] = defaultdict(list)
        for row in self.rows["sample_annotation"]:
            by_instance[row["instance_token"]].append(row)
        for inst in self.rows["instance"]:
            rows = sorted(by_instance[inst["token"]], key=lambda r: t_sample[r["sample_token"]])
            for a, b in zip(rows[:-1], rows[1:]):
                a["next"], b["prev"] = b["token"], a["token"]
            inst["nbr_annotations"] = len(rows)
            inst["first_annotation_token"] = rows[0]["token"] if rows else ""
            inst["last_annotation_token"] = rows[-1]["token"] if rows else ""
