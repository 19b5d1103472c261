"""The task a worker process runs (local pool or Dask): one sample, with its failure handling and accounting.

A task is (sample token, cameras, the sample's table rows): the driver cuts the rows out of the tables
(:class:`TableSlicer`), so a worker never parses the whole tables (GBs for trainval) and needs only
the source files (images, LiDAR, map) on its file system. The work itself is :mod:`.job`.

Caches per worker process, all bounded: one reader per dataset (and its parsed map, one per location),
asset files and their BVHs (the ``assets`` loader's LRU cache; the renderer keeps each BVH on its asset);
procedural objects only for ``--tracks`` (a sample's own are forgotten after it: :func:`release_sample_assets`).
Lighting and scene depth are computed once per sample and camera and shared by every object rendered there.
"""

from __future__ import annotations

import os
import resource
import socket
import sys
import time
from dataclasses import replace
from pathlib import Path

from streetaug.datasets.nuscenes import NuScenesReader

from .config import BatchConfig
from .execute import release_free_heap, tune_malloc
from .row import LogRow

_READERS: dict[tuple[str, str], NuScenesReader] = {}


class TableSlicer:
    """Cuts out of a reader's tables the rows that building one ``Sample`` reads."""

    def __init__(self, reader: NuScenesReader) -> None:
        self.reader = reader
        self._lidarseg = {r.get("sample_data_token", ""): r for r in reader.table("lidarseg")}
        self._whole = {t: reader.table(t) for t in ("sensor", "category", "attribute", "visibility", "map")}

    def cameras(self, token: str) -> list[str]:
        """Channels of the sample's keyframe camera images, sorted."""
        return sorted(self.reader.keyframe_sample_data(token, "camera"))

    def tables(self, token: str, sweeps: bool = False) -> dict[str, list[dict]]:
        """The rows of sample ``token`` (with ``sweeps``: its non-keyframe ``sample_data`` rows too)."""
        r = self.reader
        sample = r.get("sample", token)
        scene = r.get("scene", sample["scene_token"])
        sds = [sd for sd in r.sample_data_rows(token) if sweeps or sd.get("is_key_frame")]
        anns = r.annotation_rows(token)
        return {
            **self._whole,
            "sample": [sample] + ([r.get("sample", sample["prev"])] if sweeps and sample.get("prev") else []),
            "scene": [scene],
            "log": [r.get("log", scene["log_token"])],
            "sample_data": sds,
            "calibrated_sensor": _unique(r.get("calibrated_sensor", sd["calibrated_sensor_token"]) for sd in sds),
            "ego_pose": _unique(r.get("ego_pose", sd["ego_pose_token"]) for sd in sds),
            "sample_annotation": anns,
            "instance": _unique(r.get("instance", a["instance_token"]) for a in anns),
            "lidarseg": [self._lidarseg[sd["token"]] for sd in sds if sd["token"] in self._lidarseg],
        }


def _unique(rows) -> list[dict]:
    return list({row["token"]: row for row in rows}.values())


def dataset_reader(config: BatchConfig) -> NuScenesReader:
    """This process's reader of ``config``'s dataset (one kept at a time)."""
    key = (config.dataroot, config.version)
    if key not in _READERS:
        _READERS.clear()  # one dataset per worker at a time
        _READERS[key] = NuScenesReader(config.dataroot, config.version)
    return _READERS[key]


def worker_id() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MiB.

    Linux: ``VmHWM`` (``ru_maxrss`` would include the parent's memory at fork: it survives exec).
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024


def release_sample_assets() -> None:
    """Forget the procedural objects this process built for a sample (objects per sample, not ``--tracks``).

    ``select_assets`` keeps the last 64 procedural cars (256 objects of a class mix) with their ray-tracing
    copies, ~3.5 MB each (2.5 MB mesh and BVH, the rest bounce data): up to 220 MB (cars) or ~900 MB per
    worker. A sample's objects are drawn from 4096 seeds per sample and camera, so a later sample finds
    one of them again in 1.6 % of its draws at best; a track's object is drawn again in every keyframe of its
    scene, so ``--tracks`` keeps them.
    """
    from ..assets.select import forget_procedural_assets  # deferred: the procedural generators

    forget_procedural_assets()


def process_sample(config: BatchConfig, out_dir: str, token: str, cameras: list[str], tables: dict,
                   dry_run: bool = False, fail_fast: bool = False, scene_tracks=None) -> list[LogRow]:
    """Augment ``cameras`` of sample ``token`` and write their images and labels under ``out_dir``.

    Returns one log row per camera (``status`` ok / skipped / failed; with ``dry_run`` planned /
    no_placement), with the sample's wall and CPU seconds shared evenly by its cameras (``seconds``,
    ``cpu_s``). A camera whose image cannot be read fails alone (the others are augmented without it);
    any other failure fails the whole sample (all its cameras), so a sample's cameras always show the same
    inserted objects; with ``fail_fast`` the error is raised instead. ``scene_tracks`` (``--tracks``): the
    :class:`~.tracks.SceneTracks` of the sample's scene, rendered instead of placing objects here.
    """
    tune_malloc()  # in every kind of worker (inline, local process, Dask), before the heavy allocations
    # Deferred: the pipeline loads torch (the learned sky model); the driver imports this module only to
    # send this function to its workers and must not pay for it.
    from .job import augment_sample, augment_track_sample

    started, t0, cpu0 = time.time(), time.perf_counter(), time.process_time()
    try:
        reader = dataset_reader(config).with_tables(tables)
        if scene_tracks is not None:
            rows = augment_track_sample(reader, config, Path(out_dir), token, cameras, scene_tracks, dry_run,
                                        fail_fast)
        else:
            rows = augment_sample(reader, config, Path(out_dir), token, cameras, dry_run, fail_fast)
    except Exception as e:  # noqa: BLE001 - one failing sample is logged and the batch goes on
        if fail_fast:
            raise
        reason = f"{type(e).__name__}: {e}".splitlines()[0][:300]
        rows = [LogRow(token, c, "failed", reason) for c in cameras]
    finally:
        if scene_tracks is None:
            release_sample_assets()
        release_free_heap()  # the sample's freed buffers: the next sample starts from its live memory
    n = max(len(rows), 1)
    seconds, cpu_s = (time.perf_counter() - t0) / n, (time.process_time() - cpu0) / n
    worker, rss = worker_id(), round(peak_rss_mb(), 1)
    span = (round(started, 3), round(started + time.perf_counter() - t0, 3))
    return [replace(row, timing_s=row.timing_s or {"total": seconds}, seconds=seconds, cpu_s=cpu_s, worker=worker,
                    peak_rss_mb=rss, task_span=span) for row in rows]


def plan_scene(config: BatchConfig, scene_token: str, scene_name: str, sample_tokens: list[str],
               tables: dict[str, list[dict]]) -> SceneTracks:
    """Plan ``config.tracks`` tracks through the keyframes ``sample_tokens`` of one scene (a worker task).

    ``tables``: the rows of those samples (:func:`scene_tables`). A scene whose tables are inconsistent (a
    missing ego pose, a sample without cameras, an unreadable LiDAR file) comes back ``failed`` with the
    reason; the batch skips its samples and goes on.
    """
    # deferred: the driver sends this function to workers and must not pay for the planner's imports
    from streetaug.placement.class_rules import read_class_rules
    from streetaug.placement.track import TrackConfig, plan_tracks, track_frames

    from .tracks import SceneTracks, track_assets, track_rng

    t0 = time.perf_counter()
    try:
        reader = dataset_reader(config).with_tables(tables)
        samples = [reader.sample(t) for t in sample_tokens]
        frames = track_frames(samples)
        assets = track_assets(config, scene_token, config.tracks, samples[0].location)
        plan = plan_tracks(frames, assets, track_rng(config.seed, "tracks", scene_token),
                           TrackConfig(), samples[0].location, read_class_rules(config.class_rules))
    except Exception as e:  # noqa: BLE001 - one inconsistent scene is skipped, the batch goes on
        reason = f"scene {scene_name or scene_token}: {type(e).__name__}: {e}".splitlines()[0][:300]
        return SceneTracks(scene_token, scene_name, tuple(sample_tokens), (), {}, reason, failed=True,
                           seconds=time.perf_counter() - t0)
    return SceneTracks(scene_token, scene_name, tuple(sample_tokens), tuple(plan.tracks), plan.report, plan.reason,
                       plan.traffic_side, seconds=time.perf_counter() - t0)
