"""Tracks in a batch (``--tracks N``): N inserted instances per scene, planned once per scene, rendered per sample.

Planning runs as one task per scene (in a worker, like samples: :func:`~.worker.plan_scene`); its result is saved as
``OUTDIR/tracks/<scene token>.json`` (atomically) before any sample of the scene is rendered, so a rerun
renders exactly the same tracks (it reads the file instead of planning again) and a killed run never
duplicates or truncates a track: each sample's annotation of each track is logged with the sample.

Each track has one asset through the scene: drawn from (seed, "track-asset", scene token, track index), the
same in the planning task (its size) and in every sample's task (its mesh and paint).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.placement.track import Track

from ..core import InputError, read_json, write_json_atomic
from .config import BatchConfig

TRACKS_FOLDER = "tracks"
TRACKS_SCHEMA = "streetaug.tracks/1"


def tracks_file(out_dir: Path, scene_token: str) -> Path:
    return Path(out_dir) / TRACKS_FOLDER / f"{scene_token}.json"


def track_rng(seed: int, *keys: str) -> np.random.Generator:
    from ..pipeline.options import item_seed  # deferred: the pipeline imports torch

    return item_seed(seed, *keys)


def track_asset(config: BatchConfig, scene_token: str, index: int, location: str | None = None):
    """The asset of track ``index`` of the scene: its own draw (seed, "track-asset", scene token, index), so one
    track's asset is built without the others'. With a class mix, procedural pedestrians stand and
    two-wheelers have no rider (only vehicles move in tracks); procedural cars carry the plates of the
    scene's ``location``."""
    from ..assets.select import select_assets  # deferred: trimesh, procedural meshes

    return select_assets(track_rng(config.seed, "track-asset", scene_token, str(index)), 1, config.asset,
                         config.assets_dir, config.asset_front, config.asset_length, config.class_mix, still=True,
                         class_sizes=config.class_sizes, location=location)[0]


def track_assets(config: BatchConfig, scene_token: str, n: int, location: str | None = None) -> list:
    """The asset of each of the scene's ``n`` tracks (:func:`track_asset`; the same in every task)."""
    return [track_asset(config, scene_token, i, location) for i in range(n)]


@dataclass(frozen=True)
class SceneTracks:
    """The planned tracks of one scene (what ``tracks/<scene token>.json`` holds).

    Attributes:
        scene_token, scene_name: the scene.
        sample_tokens: the keyframes planned over (time order).
        tracks: the planned tracks.
        report: rule -> rejected candidates; reason: why fewer than asked (None = all), or why the scene failed.
        traffic_side: the side traffic keeps and why.
        failed: the scene could not be planned (inconsistent tables): its samples are skipped with ``reason``.
        seconds: planning wall time.
    """

    scene_token: str
    scene_name: str
    sample_tokens: tuple[str, ...]
    tracks: tuple[Track, ...]
    report: dict[str, int] = field(default_factory=dict)
    reason: str | None = None
    traffic_side: str = ""
    failed: bool = False
    seconds: float = 0.0

    def to_json(self) -> dict:
        return {"schema": TRACKS_SCHEMA, "scene_token": self.scene_token, "scene_name": self.scene_name,
                "sample_tokens": list(self.sample_tokens), "tracks": [t.to_json() for t in self.tracks],
                "report": self.report, "reason": self.reason, "traffic_side": self.traffic_side,
                "failed": self.failed, "seconds": round(self.seconds, 3)}

    @classmethod
    def from_json(cls, doc: dict, path: Path) -> "SceneTracks":
        if doc.get("schema") != TRACKS_SCHEMA:
            raise InputError(f"{path}: expected schema {TRACKS_SCHEMA!r}, got {doc.get('schema')!r}; "
                             "remove the file to plan the scene again")
        return cls(doc["scene_token"], doc.get("scene_name", ""), tuple(doc["sample_tokens"]),
                   tuple(Track.from_json(t) for t in doc["tracks"]), dict(doc.get("report") or {}),
                   doc.get("reason"), doc.get("traffic_side", ""), bool(doc.get("failed")),
                   float(doc.get("seconds", 0.0)))

    def at(self, sample_token: str) -> list[Track]:
        """The tracks annotated at ``sample_token``, in track order."""
        return [t for t in self.tracks if t.index_of(sample_token) is not None]


def plan_key(config: BatchConfig) -> dict:
    """What a scene's plan depends on: a saved plan made with other values is planned again."""
    return {"dataroot": config.dataroot, "version": config.version, "seed": config.seed, "tracks": config.tracks,
            "asset": config.asset, "assets_dir": config.assets_dir, "asset_front": config.asset_front,
            "asset_length": config.asset_length,
            **({"classes": config.classes, "class_weights": config.class_weights, "class_rules": config.class_rules,
                "class_sizes": config.class_sizes}
               if config.classes or config.class_weights or config.class_rules or config.class_sizes else {})}


def read_scene_tracks(out_dir: Path, scene_token: str, config: BatchConfig,
                      sample_tokens: list[str]) -> SceneTracks | None:
    """The saved plan of a scene, or None when there is none, it failed (planned again) or it was made for other
    options or samples."""
    path = tracks_file(out_dir, scene_token)
    if not path.is_file():
        return None
    doc = read_json(path)
    if doc.get("failed") or doc.get("plan_key") != plan_key(config) or list(doc.get("sample_tokens") or []) != list(sample_tokens):
        return None
    return SceneTracks.from_json(doc, path)


def saved_scene_tracks(out_dir: Path) -> list[SceneTracks]:
    """Every saved scene plan of ``out_dir`` (``tracks/*.json``), by file name."""
    return [SceneTracks.from_json(read_json(p), p) for p in sorted((Path(out_dir) / TRACKS_FOLDER).glob("*.json"))]


def write_scene_tracks(out_dir: Path, planned: SceneTracks, config: BatchConfig) -> None:
    write_json_atomic(tracks_file(out_dir, planned.scene_token), {**planned.to_json(), "plan_key": plan_key(config)})


def scene_groups(reader: NuScenesReader, tokens: list[str]) -> dict[str, list[str]]:
    """scene token -> its samples among ``tokens`` (time order), scenes in the order of ``tokens``."""
    groups: dict[str, list[str]] = {}
    for t in tokens:
        groups.setdefault(reader.scene_of(t)["token"], []).append(t)
    return groups


def scene_tables(slicer, tokens: list[str]) -> dict[str, list[dict]]:
    """The union of the per-sample table slices of ``tokens`` (rows deduplicated by token)."""
    merged: dict[str, dict] = {}
    for t in tokens:
        for name, rows in slicer.tables(t).items():
            table = merged.setdefault(name, {})
            for row in rows:
                table[row.get("token") or id(row)] = row
    return {name: list(rows.values()) for name, rows in merged.items()}


def summarize_tracks(planned: list[SceneTracks]) -> dict:
    """The tracks' part of ``summary.json``: per scene and overall."""
    keyframes = [len(t.sample_tokens) for s in planned for t in s.tracks]
    return {
        "scenes": len(planned),
        "scenes_failed": sum(s.failed for s in planned),
        "tracks": len(keyframes),
        "parked": sum(t.motion == "parked" for s in planned for t in s.tracks),
        "moving": sum(t.motion == "moving" for s in planned for t in s.tracks),
        "keyframes_per_track_median": float(np.median(keyframes)) if keyframes else None,
        "per_scene": {s.scene_name or s.scene_token: {
            "tracks": len(s.tracks), "keyframes": len(s.sample_tokens), "reason": s.reason,
            "traffic_side": s.traffic_side, "failed": s.failed,
            "directions": sorted({t.direction_source for t in s.tracks})} for s in planned},
    }


__all__ = ["SceneTracks", "TRACKS_FOLDER", "plan_key", "read_scene_tracks", "saved_scene_tracks", "scene_groups", "scene_tables",
           "summarize_tracks", "track_asset", "track_assets", "tracks_file", "write_scene_tracks"]
