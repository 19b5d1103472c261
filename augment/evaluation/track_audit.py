"""Audit a ``streetaug batch --tracks`` output against its source: are the tracks where they should be, seen
where they should be seen, with the right velocities?

Independent of the planner's own checks: it re-reads the source dataset (annotated boxes, LiDAR, cameras,
map) and the output (``tracks/*.json``, ``augment_log.jsonl``, ``labels/``), and recomputes:

* **should be visible**: the track's box at a keyframe, in a camera, is in front of it and its occlusion-aware
  visible fraction (a 16 x 16 ray lattice over the box against the LiDAR scene depth,
  :func:`~streetaug.placement.rules.visible_fraction_estimate`) is >= ``VISIBLE_MIN``; **rendered**: the
  camera's labels name the track with a 2D box. ``recall`` = rendered / should be visible (the frames where
  the renderer agrees the track shows); ``rendered_unexpected`` the converse.
* **pop-in/out**: a track that should be visible in some camera at the keyframe just before its span starts or
  just after it ends (at its first / last pose: it would appear from nothing / vanish in view).
* **rule violations** per annotated keyframe: footprint off the drivable area, closer than ``MIN_GAP_M`` to an
  annotated box of that keyframe, overlapping the ego's footprint at that time, or another track.
* **velocity**: the devkit's ``box_velocity`` (difference of the neighbouring annotations over their time
  difference) of each new annotation against the trajectory's velocity at that keyframe.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import shapely

from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.placement.config import PlacementConfig
from streetaug.placement.drivable import drivable_area_for_sample
from streetaug.placement.rules import box_corners_object, box_footprint_rect, box_footprints, \
    visible_fraction_estimate
from streetaug.placement.scene import scene_depth
from streetaug.placement.track import ego_footprint

from ..batch.tracks import SceneTracks, saved_scene_tracks
from ..core import PinholeCamera

VISIBLE_MIN = 0.2  # a track counts as "should be visible" in a camera from this occlusion-aware fraction up
MIN_GAP_M = 0.5  # closer than this to an annotated box is a violation (the planner keeps 1-2 m)


def _rendered(out_dir: Path) -> dict[tuple[str, str, str], list[float]]:
    """(track key, sample token, camera) -> bbox_2d of every labelled track in the output's images."""
    seen = {}
    for row in (json.loads(line) for line in (out_dir / "augment_log.jsonl").read_text().splitlines() if line):
        if row.get("status") != "ok" or len(row.get("files") or []) < 2:
            continue
        labels = json.loads((out_dir / row["files"][1]).read_text())
        for obj in labels.get("objects", []):
            if obj.get("track") and obj.get("bbox_2d"):
                seen[(obj["track"], row["sample_token"], row["camera"])] = obj["bbox_2d"]
    return seen


def _logged(out_dir: Path) -> tuple[set[str], dict[tuple[str, str], dict]]:
    """(samples with a finished row, (track key, sample token) -> its logged object)."""
    done, objects = set(), {}
    for row in (json.loads(line) for line in (out_dir / "augment_log.jsonl").read_text().splitlines() if line):
        if row.get("status") in ("ok", "skipped"):
            done.add(row["sample_token"])
        for o in row.get("objects") or []:
            if o.get("track"):
                objects[(o["track"], row["sample_token"])] = o
    return done, objects


def visible_fractions(sample, T_global_from_object: np.ndarray, wlh: np.ndarray,
                      cameras: tuple[str, ...] = ()) -> dict[str, float]:
    """camera -> the occlusion-aware visible fraction of a box (object frame ``T_global_from_object``) there."""
    out = {}
    for channel, view in sorted(sample.cameras.items()):
        if cameras and channel not in cameras:
            continue
        T_co = view.T_cam_from_global @ T_global_from_object
        corners = (T_co[:3, :3] @ box_corners_object(wlh).T).T + T_co[:3, 3]
        out[channel] = 0.0
        if np.all(corners[:, 2] > 0.1):
            out[channel] = float(visible_fraction_estimate(T_co[None], wlh, PinholeCamera(view.K, view.width,
                                                                                          view.height),
                                                           scene_depth(sample, view), 1.0)[0])
    return out


def audit_scene(reader: NuScenesReader, scene: SceneTracks, rendered: dict, done: set[str], logged: dict,
                cameras: tuple[str, ...] = ()) -> dict:
    """The audit figures of one scene's tracks over its rendered keyframes (see the module docstring)."""
    order = list(scene.sample_tokens)
    should = got = unexpected = 0
    pops, violations, frames_checked = [], defaultdict(int), 0
    lidar_pts = []
    samples = {t: reader.sample(t) for t in order if t in done}
    for track in scene.tracks:
        key = f"{scene.scene_token}/{track.track_index}"
        for i, token in enumerate(track.sample_tokens):
            if token not in samples:
                continue
            sample = samples[token]
            T = track.T_global_from_object[i]
            for channel, vis in visible_fractions(sample, T, track.wlh, cameras).items():
                expected = vis >= VISIBLE_MIN
                shown = (key, token, channel) in rendered
                should += expected
                got += expected and shown
                unexpected += shown and not expected
            # rules, re-checked on the output
            frames_checked += 1
            fp = shapely.Polygon(box_footprint_rect(T[None], track.wlh)[0])
            view0 = sample.cameras[sorted(sample.cameras)[0]]
            drivable, _ = drivable_area_for_sample(sample, view0, PlacementConfig())
            if drivable is None or not drivable.contains_footprints(np.asarray(fp.exterior.coords)[:4][None])[0]:
                violations["off_drivable"] += 1
            boxes = box_footprints(list(sample.boxes))
            if len(boxes) and min(fp.distance(shapely.Polygon(b)) for b in boxes) < MIN_GAP_M:
                violations["annotated_box"] += 1
            if fp.intersects(shapely.Polygon(ego_footprint(view0.T_global_from_ego))):
                violations["ego"] += 1
            for other in scene.tracks:
                j = other.index_of(token)
                if other is not track and j is not None and fp.intersects(shapely.Polygon(
                        box_footprint_rect(other.T_global_from_object[j][None], other.wlh)[0])):
                    violations["other_track"] += 1
            o = logged.get((key, token))
            if o is not None:
                lidar_pts.append(int(o.get("num_lidar_pts") or 0))
        first, last = order.index(track.sample_tokens[0]), order.index(track.sample_tokens[-1])
        for at, pose, kind in ((first - 1, 0, "pop-in"), (last + 1, -1, "pop-out")):
            neighbour = order[at] if 0 <= at < len(order) else None
            if neighbour in samples and any(v >= VISIBLE_MIN for v in visible_fractions(
                    samples[neighbour], track.T_global_from_object[pose], track.wlh, cameras).values()):
                pops.append({"track": track.track_index, "at": at, "kind": kind})
    return {"should_be_visible": should, "rendered_when_visible": got,
            "recall": round(got / should, 4) if should else None, "rendered_unexpected": unexpected,
            "pops": pops, "frames_checked": frames_checked, "violations": dict(violations),
            "lidar_pts": lidar_pts}


def velocity_errors(out_dir: Path, version: str, scenes: list[SceneTracks], seed: int) -> list[float]:
    """|devkit box_velocity - trajectory velocity| (m/s) of every new annotation with a neighbour."""
    from nuscenes.nuscenes import NuScenes  # the devkit: a test oracle, not a dependency

    from streetaug.datasets.nuscenes_format import new_token

    nusc = NuScenes(version=version, dataroot=str(out_dir), verbose=False)
    errors = []
    for scene in scenes:
        for track in scene.tracks:
            token = new_token("instance", seed, "track", f"{scene.scene_token}/{track.track_index}")
            try:
                inst = nusc.get("instance", token)
            except KeyError:
                continue
            if inst["nbr_annotations"] < 2:
                continue
            ann = inst["first_annotation_token"]
            while ann:
                row = nusc.get("sample_annotation", ann)
                v = nusc.box_velocity(ann)
                i = track.index_of(row["sample_token"])
                if np.all(np.isfinite(v[:2])):
                    errors.append(float(np.linalg.norm(v[:2] - track.velocity_global[i, :2])))
                ann = row["next"]
    return errors


def audit_tracks(out_dir: str | Path, dataroot: str | Path, version: str, cameras: tuple[str, ...] = ()) -> dict:
    """Audit every scene of a ``--tracks`` output (see the module docstring); figures per scene and pooled."""
    out_dir = Path(out_dir)
    reader = NuScenesReader(dataroot, version)
    rendered = _rendered(out_dir)
    done, logged = _logged(out_dir)
    scenes = saved_scene_tracks(out_dir)
    per_scene = {s.scene_name or s.scene_token: audit_scene(reader, s, rendered, done, logged, cameras)
                 for s in scenes}
    should = sum(s["should_be_visible"] for s in per_scene.values())
    got = sum(s["rendered_when_visible"] for s in per_scene.values())
    frames = sum(s["frames_checked"] for s in per_scene.values())
    pts = [p for s in per_scene.values() for p in s["lidar_pts"]]
    keyframes = [len(t.sample_tokens) for s in scenes for t in s.tracks]
    return {"tracks": len(keyframes), "keyframes_per_track_median": float(np.median(keyframes)) if keyframes else None,
            "should_be_visible": should, "recall": round(got / should, 4) if should else None,
            "rendered_unexpected": sum(s["rendered_unexpected"] for s in per_scene.values()),
            "pops": sum(len(s["pops"]) for s in per_scene.values()), "frames_checked": frames,
            "violations": sum(sum(s["violations"].values()) for s in per_scene.values()),
            "violations_per_frame": round(sum(sum(s["violations"].values()) for s in per_scene.values())
                                          / max(frames, 1), 4),
            "lidar_pts_median": float(np.median(pts)) if pts else None,
            "lidar_pts_nonzero_fraction": round(float(np.mean(np.array(pts) > 0)), 4) if pts else None,
            "per_scene": per_scene}


__all__ = ["MIN_GAP_M", "VISIBLE_MIN", "audit_scene", "audit_tracks", "velocity_errors"]
