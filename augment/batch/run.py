"""The batch driver: plan, resume, dispatch samples to workers, log, and write the nuScenes dataset.

Only the driver writes the log and the tables; workers write images and labels (atomically). Output
folder (see :mod:`streetaug.datasets.nuscenes_writer` for the tables and links)::

    OUTDIR/batch_config.json              what was asked (a rerun must ask the same to resume)
    OUTDIR/samples/<CAMERA>/<name>        augmented images; OUTDIR/labels/<CAMERA>/<stem>.json their labels
    OUTDIR/samples/LIDAR_TOP/<name>       the sample's LiDAR sweep with the inserted objects in it
    OUTDIR/lidarseg_augmented/<version>/  its lidarseg labels (objects' points relabelled), with lidarseg
    OUTDIR/<version>/*.json, source, maps the nuScenes dataset: NuScenes(version, dataroot=OUTDIR)
    OUTDIR/augment_log.jsonl              one line per attempted image (sample_token, camera, status, reason,
                                          timing_s, objects placed in that camera's view, ...)
    OUTDIR/summary.json, contact_sheet.png
    OUTDIR/tracks/<scene token>.json       ``--tracks``: each scene's planned tracks (a rerun renders the same)
    OUTDIR/tracks_sheet.png               ``--tracks``: each track through time
    OUTDIR/shards/<I>-of-<N>/             per-shard log and summary (``--shard``; ``merge`` joins them)
    OUTDIR/plan.jsonl                     ``--dry-run``: planned placements only
"""

from __future__ import annotations

import shutil
import time
from itertools import chain
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterable

from tqdm import tqdm

from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.nuscenes_writer import InsertedObject, link_source, write_augmented_tables
from streetaug.datasets.nuscenes_format import visibility_token

from ..core import InputError, write_json_atomic
from ..core.lock import OutputLock
from ..core.paths import refuse_output_inside
from .config import BatchConfig, RunOptions, check_and_save_config, load_config
from .execute import run_dask, run_inline, run_processes
from .layout import (LIDARSEG_FOLDER, LOG_FILE, PLAN_FILE, SUMMARY_FILE, check_unique_outputs, labels_file,
                     output_file, shard_dir)
from .log import append_rows, compact_log, done_samples, latest_rows, read_log, write_log
from .report import contact_sheet, summarize, worker_timeline
from .row import LogRow
from .tracks import SceneTracks, read_scene_tracks, saved_scene_tracks, scene_groups, scene_tables, \
    summarize_tracks, write_scene_tracks
from .track_sheet import track_sheet
from .worker import TableSlicer, plan_scene, process_sample



# The tables a sample's rows are cut from (TableSlicer): read (and their tokens checked) before dispatching.
SLICED_TABLES = ("sample", "scene", "log", "sample_data", "calibrated_sensor", "ego_pose", "sample_annotation",
                 "instance", "sensor", "category", "attribute", "visibility", "map")


def _echo_none(_: str) -> None:
    pass


def planned_samples(reader: NuScenesReader, limit: int | None, shard: tuple[int, int] | None = None) -> list[str]:
    """Sample tokens to process, in scene order: the first ``limit``, then every N-th from I for shard I/N."""
    tokens = reader.sample_tokens()
    if limit is not None:
        tokens = tokens[:limit]
    if shard is not None:
        tokens = tokens[shard[0]::shard[1]]
    return tokens


def _check_cameras(reader: NuScenesReader, cameras: tuple[str, ...]) -> None:
    known = sorted({s["channel"] for s in reader.table("sensor") if s.get("modality") == "camera"})
    unknown = [c for c in cameras if c not in known]
    if unknown:
        raise InputError(f"--cameras: unknown camera(s) {', '.join(unknown)}; cameras of this dataset: "
                         f"{', '.join(known)} (or 'all')")


def _remove_stale_temp_files(out_dir: Path, version: str) -> None:
    """Temporary files a killed run left behind (never seen under their final names)."""
    for pattern in ("samples/*/.*.tmp*", "labels/*/.*.tmp*", f"{LIDARSEG_FOLDER}/*/.*.tmp*", ".*.tmp*"):
        for path in out_dir.glob(pattern):
            if path.is_file():
                path.unlink(missing_ok=True)
    for pattern in (f".{version}.tmp-*", f".{version}.old-*"):
        for path in out_dir.glob(pattern):
            shutil.rmtree(path, ignore_errors=True)


def planned_outputs(reader: NuScenesReader, tokens: list[str], cameras: tuple[str, ...]) -> dict[str, list[str]]:
    """sample_data token -> the output files it would get (camera images and labels of ``cameras``, all when
    empty, and the LiDAR sweep) for the samples ``tokens``. A filename that is no relative path inside the
    dataroot is left out here: its sample fails alone, with the reader's message."""
    outputs: dict[str, list[str]] = {}
    for token in tokens:
        rows = [(c, sd) for c, sd in reader.keyframe_sample_data(token, "camera").items()
                if not cameras or c in cameras]
        lidar = reader.lidar_sample_data(token)
        if lidar is not None:
            rows.append((reader.sensor_of(lidar).get("channel", "LIDAR_TOP"), lidar))
        for channel, sd in rows:
            try:
                file = output_file(sd.get("filename", ""), channel, sd["token"])
            except InputError:
                continue
            outputs[sd["token"]] = [file] if sd is lidar else [file, labels_file(file)]
    return outputs


def check_assets(config: BatchConfig) -> None:
    """Load ``--asset`` or every asset of ``--assets`` once before any work, so that a broken file stops the
    batch at once with its name (instead of failing every image that drew it); likewise the class mix and
    class rules, and, with both a folder and a class mix, that every weighted class has a file."""
    from streetaug.placement.class_rules import read_class_rules

    mix = config.class_mix
    read_class_rules(config.class_rules)
    if config.class_sizes is not None:
        from ..assets.class_sizes import read_class_sizes
        from ..assets.classes import CLASS_CATEGORIES
        from ..core import InputError

        table = read_class_sizes(config.class_sizes)
        for name in (mix.classes if mix is not None else ()):
            missing = [c for c, _, _ in CLASS_CATEGORIES[name] if c not in table and name != "car"]
            if missing:
                raise InputError(f"{config.class_sizes}: no size entry for {', '.join(missing)} (class {name!r}); "
                                 "add it or drop the class from --classes")
    if config.asset is None and config.assets_dir is None:
        return
    if mix is not None and config.assets_dir is not None:
        import numpy as np

        from ..assets.select import select_assets

        select_assets(np.random.default_rng(0), 1, None, config.assets_dir, config.asset_front, config.asset_length,
                      mix)
    from ..assets.loader import list_assets  # deferred: trimesh and scipy, only when assets are given
    from ..assets.select import load_asset_options

    files = [Path(config.asset)] if config.asset is not None else list_assets(config.assets_dir)
    for file in files:
        load_asset_options(file, config.asset_front, config.asset_length)


def run_batch(config: BatchConfig, out_dir: str | Path, run: RunOptions = RunOptions(),
              echo: Callable[[str], None] = _echo_none) -> dict:
    """Augment the samples of ``config`` into ``out_dir``; resume whatever an earlier run finished.

    One run per output: the run holds ``OUT/.streetaug.lock`` (a shard: ``OUT/shards/I-of-N/.streetaug.lock``,
    so the shards of one output run side by side) from before it writes anything until it ends.

    Returns the summary (also ``summary.json``; for a shard ``shards/I-of-N/summary.json``; with
    ``dry_run`` the plan's summary, and ``plan.jsonl``).

    Raises:
        InputError: ``out_dir`` is inside the source or contains it, another run holds the lock, the options
            differ from the folder's earlier run, two inputs would map to one output, a given asset is broken.
    """
    out_dir = Path(out_dir)
    refuse_output_inside(out_dir, config.dataroot)
    config = replace(config, cameras=tuple(dict.fromkeys(config.cameras)))  # CAM_FRONT,CAM_FRONT: once
    with OutputLock(shard_dir(out_dir, run.shard) if run.shard else out_dir, "batch"):
        return _run_locked(config, out_dir, run, echo)


def _run_locked(config: BatchConfig, out_dir: Path, run: RunOptions, echo: Callable[[str], None]) -> dict:
    started = time.perf_counter()
    reader = NuScenesReader(config.dataroot, config.version)
    _check_cameras(reader, config.cameras)
    check_unique_outputs(planned_outputs(reader, planned_samples(reader, config.limit), config.cameras))
    check_assets(config)
    link_source(out_dir, config.dataroot)
    if not run.dry_run:
        check_and_save_config(out_dir, config)
    tokens = planned_samples(reader, config.limit, run.shard)
    slicer = TableSlicer(reader)

    def expected(token: str) -> list[str]:
        return list(config.cameras) or slicer.cameras(token)

    log_path = (shard_dir(out_dir, run.shard) if run.shard else out_dir) / LOG_FILE
    if run.shard is None:
        _remove_stale_temp_files(out_dir, config.version)
    done = set() if run.dry_run else done_samples(read_log(log_path), out_dir, expected)
    if not run.dry_run:
        compact_log(log_path, keep=lambda r: r.sample_token in done)
    pending = [t for t in tokens if t not in done]
    if done:
        echo(f"resuming: {len(tokens) - len(pending)} of {len(tokens)} samples already done")
    cameras = {t: expected(t) for t in pending}
    scenes: dict[str, SceneTracks] = {}
    if config.tracks:
        scenes = plan_scenes(config, out_dir, reader, slicer, pending, run, echo)
    scene_of = {t: reader.scene_of(t)["token"] for t in pending} if config.tracks else {}
    for name in SLICED_TABLES:  # a table-wide fault (e.g. a duplicated token) stops the batch before any work
        reader.check_table(name)  # large tables are scanned into their index, not parsed whole
    unsliceable: list[list[LogRow]] = []  # samples whose rows are missing: failed here, never dispatched

    def tasks_of():
        for t in pending:
            try:
                tables = slicer.tables(t, config.sweeps)
            except InputError as e:  # e.g. a missing ego pose or calibration row
                if run.fail_fast:
                    raise
                unsliceable.append([LogRow(t, c, "failed", str(e).splitlines()[0][:300]) for c in cameras[t]])
                continue
            yield (config, str(out_dir), t, cameras[t], tables, run.dry_run, run.fail_fast,
                   scenes.get(scene_of.get(t)))

    tasks = tasks_of()
    workers = max(1, min(run.workers, len(pending)))
    if run.scheduler or run.dask_local:
        executor = f"Dask {run.scheduler or f'LocalCluster({run.dask_local})'}"
        results = run_dask(process_sample, tasks, run.scheduler, run.dask_local, on_start=echo)
    elif workers > 1:
        executor = f"{workers} local processes"
        results = run_processes(process_sample, tasks, workers)
    else:
        executor = "1 process (inline)"
        results = run_inline(process_sample, tasks)
    results = chain(results, unsliceable)  # filled while the tasks are drawn: read after them
    n_workers = run.dask_local if run.dask_local else None if run.scheduler else workers
    return _collect(config, out_dir, run, reader, log_path, results, cameras, tokens, executor, n_workers,
                    time.perf_counter() - started)


def plan_scenes(config: BatchConfig, out_dir: Path, reader: NuScenesReader, slicer: TableSlicer,
                pending: list[str], run: RunOptions,
                echo: Callable[[str], None]) -> dict[str, SceneTracks]:
    """scene token -> its tracks, for the scenes of the ``pending`` samples (``--tracks``).

    A scene is planned over all its keyframes (whatever ``--limit`` or the shard renders of it), once: the plan
    is saved in ``tracks/<scene token>.json`` and a rerun reads it. Scenes are planned in parallel like
    samples. A scene that cannot be planned (inconsistent tables) is not saved: its samples fail with the
    reason, the rest goes on, and a rerun tries it again.
    """
    wanted = scene_groups(reader, pending)
    scenes, todo = {}, []
    for scene_token in wanted:
        tokens = reader.sample_tokens(scene_token)
        saved = read_scene_tracks(out_dir, scene_token, config, tokens)
        if saved is not None:
            scenes[scene_token] = saved
            continue
        name = reader.get("scene", scene_token).get("name", "")
        try:
            todo.append((config, scene_token, name, tokens, scene_tables(slicer, tokens)))
        except InputError as e:  # inconsistent tables (a missing ego pose, calibration, ...): the scene fails
            if run.fail_fast:
                raise
            scenes[scene_token] = SceneTracks(scene_token, name, tuple(tokens), (),
                                              reason=f"scene {name or scene_token}: {e}".splitlines()[0][:300],
                                              failed=True)
            write_scene_tracks(out_dir, scenes[scene_token], config)  # for the summary; a rerun plans it again
    if todo:
        echo(f"planning tracks in {len(todo)} scene(s)" + (f" ({len(scenes)} already planned)" if scenes else ""))
        workers = max(1, min(run.workers, len(todo)))
        results = run_processes(plan_scene, todo, workers) if workers > 1 else run_inline(plan_scene, todo)
        for planned in results:
            if run.fail_fast and planned.failed:
                raise InputError(planned.reason or f"scene {planned.scene_token}: planning failed")
            write_scene_tracks(out_dir, planned, config)  # a failed scene's file is for the summary only
            scenes[planned.scene_token] = planned
    return scenes


def _collect(config: BatchConfig, out_dir: Path, run: RunOptions, reader: NuScenesReader, log_path: Path,
             results: Iterable[list[LogRow]], cameras: dict[str, list[str]], tokens: list[str],
             executor: str, n_workers: int | None = None, plan_s: float = 0.0) -> dict:
    """Log the results as they come, then write the plan, the shard's summary or the dataset.

    ``n_workers``: the executor's workers (None: a Dask scheduler's, counted from the results); ``plan_s``:
    the driver's seconds before the first dispatch (tables, checks, resume, track plans).
    """
    pending = list(cameras)
    t0, dispatched_at = time.perf_counter(), time.time()
    status: Counter = Counter()
    new_rows: list[LogRow] = []
    first_result_s = None  # worker start-up + the first sample
    with tqdm(total=sum(map(len, cameras.values())), unit="img", desc="plan" if run.dry_run else "augment",
              disable=not run.progress, dynamic_ncols=True, smoothing=0.05) as bar:
        for rows in results:
            if first_result_s is None:
                first_result_s, first_images = time.perf_counter() - t0, len(rows)
            if not run.dry_run:
                append_rows(log_path, rows)
            new_rows.extend(rows)
            status.update(r.status for r in rows)
            bar.update(len(rows))
            bar.set_postfix({k: status[k] for k in sorted(status)}, refresh=False)
    wall, ended_at = time.perf_counter() - t0, time.time()
    cpu_s = sum(r.cpu_s or 0.0 for r in new_rows)
    this_run = {"samples": len(pending), "images": len(new_rows), "resumed_samples": len(tokens) - len(pending),
                "wall_s": round(wall, 3),
                "images_per_s": round(len(new_rows) / wall, 4) if wall > 0 and new_rows else None,
                "executor": executor, "worker_cpu_s": round(cpu_s, 2),
                "first_result_s": None if first_result_s is None else round(first_result_s, 3),
                # after the first result: the rate a long run settles at (start-up excluded)
                "steady_images_per_s": round((len(new_rows) - first_images) / (wall - first_result_s), 4)
                if first_result_s is not None and wall > first_result_s and len(new_rows) > first_images else None,
                # worker CPU seconds per wall second: ~ the number of workers when none waits for a core
                "busy_workers": round(cpu_s / wall, 2) if wall > 0 else None,
                # the tasks' wall spans: busy_fraction ~ 1 when no worker waits for work (load-independent)
                "timeline": worker_timeline(new_rows, dispatched_at, ended_at, n_workers),
                "plan_s": round(plan_s, 3)}
    if run.dry_run:
        return _write_plan(out_dir, new_rows, tokens, this_run)
    if run.shard is not None:
        summary = summarize(read_log(log_path), {**this_run, "shard": f"{run.shard[0]}/{run.shard[1]}"})
        write_json_atomic(shard_dir(out_dir, run.shard) / SUMMARY_FILE, summary)
        return summary
    return finalize(out_dir, config, reader, read_log(log_path), this_run, run.contact_sheet)


def finalize(out_dir: Path, config: BatchConfig, reader: NuScenesReader, rows: list[LogRow], this_run: dict,
             contact_sheet_n: int = 12) -> dict:
    """Write the nuScenes tables, ``summary.json`` and the contact sheet from the final log rows."""
    started = time.perf_counter()
    order = {t: i for i, t in enumerate(reader.sample_tokens())}
    rows = sorted(latest_rows(rows).values(), key=lambda r: (order.get(r.sample_token, len(order)), r.camera))
    augmented = {r.sample_data_token: r.image for r in rows if r.status == "ok"}
    lidarseg, recounted = {}, {}
    objects = []
    for r in rows:
        if not r.done:
            continue
        augmented.update(r.sweep_files or {})  # --sweeps: the sweeps before the sample, with its tracks
        lidar = r.lidar
        if lidar is not None:  # the sample's sweep with its objects (the same entry on each camera row)
            augmented[lidar.sample_data_token] = lidar.file
            if lidar.lidarseg_file:
                lidarseg[lidar.sample_data_token] = lidar.lidarseg_file
            recounted.update(lidar.source_num_lidar_pts)
        for o in r.objects or ():
            box = o.box_global
            objects.append(InsertedObject(
                sample_token=r.sample_token, object_index=o.object_index, category=o.category,
                attribute=o.attribute, translation=box["translation"], size=box["size"],
                rotation=box["rotation"], visibility_token=visibility_token(o.visible_fraction), seed=config.seed,
                num_lidar_pts=int(o.num_lidar_pts or 0), instance_key=o.track))
    objects.sort(key=lambda o: (order.get(o.sample_token, len(order)), o.object_index))
    link_source(out_dir, config.dataroot)
    tables = write_augmented_tables(config.dataroot, config.version, out_dir, augmented, objects, lidarseg,
                                    recounted)
    summary = summarize(rows, this_run)
    sheet = contact_sheet(out_dir, rows, contact_sheet_n, config.seed)
    summary["outputs"] = {"tables": str(tables.relative_to(out_dir)), "log": LOG_FILE,
                          "contact_sheet": sheet.name if sheet else None}
    if config.tracks:
        scenes = saved_scene_tracks(out_dir)
        summary["tracks"] = summarize_tracks(scenes)
        if config.sweeps:
            notes = {r.sample_token: r.sweeps_note for r in rows if r.sweeps_note}
            summary["sweeps"] = {"files": len({t for r in rows for t in (r.sweep_files or {})}),
                                 "samples_not_rendered": len(notes),
                                 "reason": next(iter(notes.values()), None)}  # e.g. the files are absent
        tracks_sheet = track_sheet(out_dir, rows, scenes) if contact_sheet_n > 0 else None
        summary["outputs"]["tracks_sheet"] = tracks_sheet.name if tracks_sheet else None
    summary["this_run"]["finalize_s"] = round(time.perf_counter() - started, 3)  # tables, sheets (driver only)
    write_json_atomic(out_dir / SUMMARY_FILE, summary)
    return summary


def _write_plan(out_dir: Path, rows: list[LogRow], tokens: list[str], this_run: dict) -> dict:
    order = {t: i for i, t in enumerate(tokens)}
    rows = sorted(rows, key=lambda r: (order.get(r.sample_token, 0), r.camera))
    write_log(out_dir / PLAN_FILE, rows)
    summary = summarize(rows, this_run)
    summary["objects_planned"] = sum(len(r.objects or ()) for r in rows)
    summary["rejections"] = dict(sum((Counter(r.placement_report or {}) for r in rows), Counter()))
    return summary


def merge(out_dir: str | Path, allow_incomplete: bool = False, contact_sheet_n: int = 12,
          echo: Callable[[str], None] = _echo_none) -> dict:
    """Join the shards' logs of ``out_dir`` into ``augment_log.jsonl`` and write the dataset and summary.

    Raises:
        InputError: no batch in ``out_dir``, or planned samples were not processed by any shard (unless
            ``allow_incomplete``; their images then stay the source's).
    """
    out_dir = Path(out_dir)
    with OutputLock(out_dir, "merge"):
        return _merge_locked(out_dir, allow_incomplete, contact_sheet_n, echo)


def _merge_locked(out_dir: Path, allow_incomplete: bool, contact_sheet_n: int, echo: Callable[[str], None]) -> dict:
    config = load_config(out_dir)
    if config is None:
        raise InputError(f"{out_dir}: no batch_config.json; run 'streetaug batch --shard I/N --out {out_dir}' first")
    logs = sorted(out_dir.glob(f"shards/*/{LOG_FILE}"))
    if not logs:
        raise InputError(f"{out_dir / 'shards'}: no shard logs (shards/I-of-N/{LOG_FILE}); "
                         f"run 'streetaug batch --shard I/N --out {out_dir}' for every I first")
    rows = read_log(out_dir / LOG_FILE)
    for path in logs:
        rows.extend(read_log(path))
    reader = NuScenesReader(config.dataroot, config.version)
    slicer = TableSlicer(reader)
    latest = latest_rows(rows)
    attempted = {t for t in {t for t, _ in latest}
                 if all((t, c) in latest for c in (list(config.cameras) or slicer.cameras(t)))}
    planned = planned_samples(reader, config.limit)
    missing = [t for t in planned if t not in attempted]
    if missing and not allow_incomplete:
        raise InputError(f"{out_dir}: {len(missing)} of {len(planned)} planned samples have no result in "
                         f"{len(logs)} shard log(s) (e.g. {', '.join(missing[:3])}); run the missing shards "
                         "(or rerun failed ones: they resume), or merge with --allow-incomplete")
    kept = [r for r in latest.values() if r.sample_token in attempted]
    order = {t: i for i, t in enumerate(reader.sample_tokens())}
    kept.sort(key=lambda r: (order.get(r.sample_token, len(order)), r.camera))
    _remove_stale_temp_files(out_dir, config.version)
    write_log(out_dir / LOG_FILE, kept)
    echo(f"merged {len(logs)} shard log(s): {len(kept)} images of {len(attempted)} samples"
         + (f"; {len(missing)} samples missing" if missing else ""))
    return finalize(out_dir, config, reader, kept,
                    {"merged_shards": len(logs), "missing_samples": len(missing), "images": len(kept)},
                    contact_sheet_n)
