"""One sample's work in a worker: choose its assets, insert into its cameras, write its files, make its rows."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import CameraView, Sample

from ..assets.scene_paint import scene_paint_mix
from ..assets.select import select_assets
from ..pipeline import InsertOptions, SamplePlacement, insert_into_sample, insert_placed_into_sample, item_seed, \
    place_in_sample
from .config import BatchConfig
from .layout import output_file
from .row import LogRow
from .tracks import SceneTracks, track_asset
from .write import plan_rows, with_file_checks, write_camera, write_lidar


def insert_options(config: BatchConfig) -> InsertOptions:
    """The insertion options of a batch."""
    return InsertOptions(quality=config.quality, level=config.level, seed=config.seed,
                         yaw_sigma_deg=config.yaw_sigma_deg, ev=config.ev, match_camera=config.match_camera,
                         class_rules=config.class_rules)


def readable_views(sample: Sample, cameras: list[str], fail_fast: bool = False
                   ) -> tuple[list[CameraView], dict[str, str]]:
    """The sample's views of ``cameras`` whose image decodes, and camera -> why the others cannot be read.

    A camera whose image is corrupt (or missing, or above the size limits) fails alone: the sample's other
    cameras share the lighting and placement of the readable views only. With ``fail_fast`` the first
    error is raised.
    """
    views, failed = [], {}
    for c in cameras:
        if c not in sample.cameras:
            continue
        view = sample.cameras[c]
        try:
            _ = view.image
        except Exception as e:  # noqa: BLE001 - logged as this camera's failure
            if fail_fast:
                raise
            failed[c] = f"{c}: {type(e).__name__}: {e}".splitlines()[0][:300]
            continue
        views.append(view)
    return views, failed


def readable_views_and_failures(sample: Sample, token: str, cameras: list[str], fail_fast: bool = False
                                ) -> tuple[list[CameraView], dict[str, LogRow]]:
    """:func:`readable_views` with a failed log row for each camera whose image cannot be read."""
    views, unreadable = readable_views(sample, cameras, fail_fast)
    return views, {c: LogRow(token, c, "failed", reason, sample_data_token=sample.cameras[c].sample_data_token)
                   for c, reason in unreadable.items()}


def augment_sample(reader: NuScenesReader, config: BatchConfig, out_dir: Path, token: str, cameras: list[str],
                   dry_run: bool = False, fail_fast: bool = False) -> list[LogRow]:
    """Augment ``cameras`` of sample ``token`` (``reader`` holds its table rows) into ``out_dir``.

    Returns one row per camera (with ``dry_run``: the planned placements, nothing rendered or written); a
    camera whose image cannot be read gets a failed row, the others go on without it.
    Raises whatever else fails; the caller logs it.
    """
    t0 = time.perf_counter()
    sample = reader.sample(token)
    views, failed = readable_views_and_failures(sample, token, cameras, fail_fast)
    mix = config.class_mix
    procedural = config.asset is None and config.assets_dir is None
    paint = scene_paint_mix(sample) if procedural else None  # the sample's own cars, seen by all its cameras
    assets = {v.channel: select_assets(item_seed(config.seed, "asset", token, v.channel), config.n_objects,
                                       config.asset, config.assets_dir, config.asset_front, config.asset_length, mix,
                                       class_sizes=config.class_sizes, location=sample.location, paint_weights=paint)
              for v in views}
    options = insert_options(config)
    load_s = time.perf_counter() - t0
    if not views:
        return [failed.get(c) or LogRow(token, c, "skipped", f"camera {c} not in this sample") for c in cameras]
    if dry_run:
        planned = plan_rows(token, [c for c in cameras if c not in failed], place_in_sample(sample, views, assets,
                                                                                              options))
        return ordered(cameras, planned, failed)
    result = insert_into_sample(sample, views, assets, options)
    rows = write_sample(out_dir, reader, sample, views, [c for c in cameras if c not in failed], result, load_s,
                        config.version)
    return ordered(cameras, with_file_checks(out_dir, rows), failed)


def write_sample(out_dir: Path, reader: NuScenesReader, sample: Sample, views: list[CameraView], cameras: list[str],
                 result, load_s: float, version: str) -> list[LogRow]:
    """Write a sample's LiDAR sweep with its objects and each of ``cameras``' image and labels; their log rows
    (the sample's shared ``load`` and ``lidar`` seconds divided among its cameras)."""
    t_lidar = time.perf_counter()
    lidar = write_lidar(out_dir, reader, sample, result, version)
    shared_s = {"load": load_s, "lidar": time.perf_counter() - t_lidar}  # per sample: shared by its cameras
    per_camera = {k: v / max(len(views), 1) for k, v in shared_s.items()}
    names = {v.channel: output_file(reader.get("sample_data", v.sample_data_token)["filename"], v.channel,
                                    v.sample_data_token) for v in views}
    return [write_camera(out_dir, sample, c, result, per_camera, lidar, names.get(c)) for c in cameras]


def ordered(cameras: list[str], rows: list[LogRow], failed: dict[str, LogRow]) -> list[LogRow]:
    """One row per camera in the order of ``cameras``: the failed cameras' rows among the others."""
    by_camera = {r.camera: r for r in rows}
    return [failed[c] if c in failed else by_camera[c] for c in cameras]


def augment_track_sample(reader: NuScenesReader, config: BatchConfig, out_dir: Path, token: str, cameras: list[str],
                         scene: SceneTracks, dry_run: bool = False, fail_fast: bool = False) -> list[LogRow]:
    """Render the tracks of ``scene`` annotated at sample ``token`` into its ``cameras`` (``--tracks``).

    Every track annotated here is logged once (on the first readable camera's row) with its instance
    (``track``) and velocity, whether or not a camera sees it (its visibility then says so, as nuScenes).
    """
    if scene.failed:  # inconsistent scene tables: every sample of the scene fails with the reason
        return [LogRow(token, c, "failed", scene.reason or "the scene's tracks could not be planned") for c in cameras]
    t0 = time.perf_counter()
    sample = reader.sample(token)
    views, failed = readable_views_and_failures(sample, token, cameras, fail_fast)
    here = scene.at(token)
    if not views:
        return [failed.get(c) or LogRow(token, c, "skipped", f"camera {c} not in this sample") for c in cameras]
    if not here:
        reason = "no track is annotated at this keyframe" + (f" ({scene.reason})" if scene.reason else "")
        return ordered(cameras, [LogRow(token, c, "skipped", reason, sample_data_token=sample.cameras[c].sample_data_token)
                                 for c in cameras if c not in failed and c in sample.cameras]
                       + [LogRow(token, c, "skipped", f"camera {c} not in this sample") for c in cameras
                          if c not in sample.cameras], failed)
    cam_xy = views[0].T_global_from_cam[:2, 3]
    placements = [t.placement_at(token, i, cam_xy) for i, t in enumerate(here)]
    # the assets of the tracks annotated here only (each track's asset is its own draw)
    assets = [track_asset(config, scene.scene_token, t.track_index, sample.location) for t in here]
    load_s = time.perf_counter() - t0
    if dry_run:
        placed = SamplePlacement(placements, [views[0].channel] * len(placements), assets, {}, {})
        rows = plan_rows(token, [c for c in cameras if c not in failed], placed)
        return ordered(cameras, _with_tracks(rows, here, scene, token), failed)
    label_fields = [{"track": f"{scene.scene_token}/{t.track_index}", "track_index": t.track_index,
                     "motion": t.motion, "velocity": [round(float(v), 6) for v in t.velocity_global[t.index_of(token)]]}
                    for t in here]
    result = insert_placed_into_sample(sample, views, placements, assets, insert_options(config), label_fields)
    rows = write_sample(out_dir, reader, sample, views, [c for c in cameras if c not in failed], result, load_s,
                        config.version)
    if config.sweeps:
        from .sweep_render import render_sweeps  # deferred: only with --sweeps

        sweeps = render_sweeps(out_dir, reader, sample, views, here, assets, label_fields, result.shared_lighting,
                               insert_options(config))
        lidar_files = sweeps.by_channel.get("LIDAR_TOP", [])
        rows = [replace(r, files=tuple(dict.fromkeys((*r.files, *sweeps.by_channel.get(r.camera, []), *lidar_files))),
                        sweep_files={t: f for t, f in sweeps.files.items()
                                     if f in sweeps.by_channel.get(r.camera, []) or f in lidar_files},
                        sweeps_note=sweeps.note, timing_s={**r.timing_s, "sweeps": sweeps.seconds / len(rows)})
                for r in rows]
    return ordered(cameras, with_file_checks(out_dir, _with_tracks(rows, here, scene, token)), failed)


def _with_tracks(rows: list[LogRow], here: list, scene: SceneTracks, token: str) -> list[LogRow]:
    """The rows with each logged object named by its track (index, instance key, velocity at ``token``)."""
    out = []
    for row in rows:
        if row.objects:
            objects = []
            for o in row.objects:
                track = here[o.object_index]
                i = track.index_of(token)
                objects.append(replace(o, object_index=track.track_index, attribute=track.attribute_at(i),
                                       track=f"{scene.scene_token}/{track.track_index}",
                                       velocity=[round(float(v), 6) for v in track.velocity_global[i]]))
            row = replace(row, objects=tuple(objects))
        out.append(row)
    return out
