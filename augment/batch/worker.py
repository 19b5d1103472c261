"""One sample's work, run in a worker process (local pool or Dask): insert, write its files, return log rows.

A task is (sample token, cameras, the sample's table rows): the driver cuts the rows out of the tables
(:class:`TableSlicer`), so a worker never parses the whole tables (GBs for trainval) and needs only
the source files (images, LiDAR, map) on its file system.

Caches per worker process, all bounded: one reader per dataset (and its parsed map, one per location),
assets and their BVHs (LRU caches of ``assets`` / ``render``). Lighting and scene depth are computed
once per sample and camera and shared by every object rendered there.
"""

from __future__ import annotations

import os
import resource
import socket
import sys
import time
from pathlib import Path

import numpy as np

from streetaug.datasets.nuscenes import NuScenesReader

from ..core import write_image_rgb, write_json_atomic
from .config import BatchConfig

_READERS: dict[tuple[str, str], NuScenesReader] = {}
# Output folder of lidarseg labels that inserted objects changed (``lidarseg/`` links to the source's).
LIDARSEG_FOLDER = "lidarseg_augmented"


class TableSlicer:
    """Cuts out of a reader's tables the rows that building one ``Sample`` reads."""

    def __init__(self, reader: NuScenesReader) -> None:
        self.reader = reader
        self._lidarseg = {r.get("sample_data_token", ""): r for r in reader.table("lidarseg")}
        self._whole = {t: reader.table(t) for t in ("sensor", "category", "attribute", "visibility", "map")}

    def cameras(self, token: str) -> list[str]:
        """Channels of the sample's keyframe camera images, sorted."""
        return sorted(self.reader.keyframe_sample_data(token, "camera"))

    def tables(self, token: str) -> dict[str, list[dict]]:
        r = self.reader
        sample = r.get("sample", token)
        scene = r.get("scene", sample["scene_token"])
        sds = [sd for sd in r.sample_data_rows(token) if sd.get("is_key_frame")]
        anns = r.annotation_rows(token)
        return {
            **self._whole,
            "sample": [sample],
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


def _reader(config: BatchConfig) -> NuScenesReader:
    key = (config.dataroot, config.version)
    if key not in _READERS:
        _READERS.clear()  # one dataset per worker at a time
        _READERS[key] = NuScenesReader(config.dataroot, config.version)
    return _READERS[key]


def worker_id() -> str:
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


def process_sample(config: BatchConfig, out_dir: str, token: str, cameras: list[str], tables: dict,
                   dry_run: bool = False, fail_fast: bool = False) -> list[dict]:
    """Augment ``cameras`` of sample ``token`` and write their images and labels under ``out_dir``.

    Returns one log row per camera (``status`` ok / skipped / failed; with ``dry_run`` planned /
    no_placement), with the sample's wall and CPU seconds shared evenly by its cameras (``seconds``,
    ``cpu_s``). A failure anywhere fails the whole sample (all its cameras), so a sample's cameras
    always show the same inserted objects; with ``fail_fast`` the error is raised instead.
    """
    from .execute import tune_malloc

    tune_malloc()  # in every kind of worker (inline, local process, Dask), before the heavy allocations
    from ..assets.select import select_assets
    from ..pipeline import InsertOptions, insert_into_sample, item_seed, place_in_sample

    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        reader = _reader(config).with_tables(tables)
        sample = reader.sample(token)
        views = [sample.cameras[c] for c in cameras if c in sample.cameras]
        assets = {v.channel: select_assets(item_seed(config.seed, "asset", token, v.channel), config.n_objects,
                                           config.asset, config.assets_dir, config.asset_front, config.asset_length)
                  for v in views}
        options = InsertOptions(quality=config.quality, level=config.level, seed=config.seed,
                                yaw_sigma_deg=config.yaw_sigma_deg, ev=config.ev,
                                match_camera=config.match_camera)
        load_s = time.perf_counter() - t0
        if dry_run:
            rows = _plan_rows(token, cameras, place_in_sample(sample, views, assets, options))
        else:
            result = insert_into_sample(sample, views, assets, options)
            t_lidar = time.perf_counter()
            lidar = _write_lidar(Path(out_dir), reader, sample, result, config.version)
            shared_s = {"load": load_s, "lidar": time.perf_counter() - t_lidar}  # per sample: shared by its cameras
            rows = [_write_camera(Path(out_dir), sample, c, result, {k: v / max(len(views), 1) for k, v in
                                                                     shared_s.items()}, lidar) for c in cameras]
    except Exception as e:  # noqa: BLE001 - one failing sample is logged and the batch goes on
        if fail_fast:
            raise
        reason = f"{type(e).__name__}: {e}".splitlines()[0][:300]
        rows = [{"sample_token": token, "camera": c, "status": "failed", "reason": reason, "files": []}
                for c in cameras]
    n = max(len(rows), 1)
    seconds, cpu_s = (time.perf_counter() - t0) / n, (time.process_time() - cpu0) / n
    for row in rows:
        row.setdefault("timing_s", {"total": seconds})
        row.update(seconds=seconds, cpu_s=cpu_s, worker=worker_id(), peak_rss_mb=round(peak_rss_mb(), 1))
    return rows


def _box_global(placement) -> dict:
    box = placement.box
    return {"translation": [float(v) for v in box.center], "size": [float(v) for v in box.wlh],
            "rotation": [float(v) for v in box.rotation]}


def _write_lidar(out_dir: Path, reader: NuScenesReader, sample, result, version: str) -> dict | None:
    """Write the sample's LiDAR sweep (and lidarseg labels) with the placed objects in it.

    Returns the log entry shared by the sample's camera rows: the LiDAR ``sample_data_token``, the new
    ``file`` (and ``lidarseg_file``), ``num_lidar_pts`` per object and ``source_num_lidar_pts``
    (annotation token -> count, for the sample's boxes that lost points behind an inserted object);
    None when nothing was placed or the sample has no LiDAR.
    """
    from streetaug.datasets.lidarseg import read_lidar_points, read_lidarseg_labels

    from ..core import write_bytes_atomic
    from ..pipeline.lidar import insert_placements_into_sweep

    sd = reader.lidar_sample_data(sample.token)
    if sd is None or not result.placements:
        return None
    source = reader.dataroot / sd["filename"]
    points = read_lidar_points(source)
    seg_path = reader.lidarseg_path(sd["token"])
    labels = None if seg_path is None else read_lidarseg_labels(seg_path, num_points=len(points))
    class_index = {c["name"]: c["index"] for c in reader.table("category") if "index" in c}
    placed = insert_placements_into_sweep(points, labels, reader.T_global_from_ego(sd) @ reader.T_ego_from_sensor(sd),
                                          result.placements, result.assets, sample.boxes, class_index)
    before = {token: int(reader.get("sample_annotation", token).get("num_lidar_pts", n))
              for token, n in placed.lost_pts.items()}
    entry = {"sample_data_token": sd["token"], "file": f"samples/{Path(sd['filename']).parent.name}/{source.name}",
             "lidarseg_file": None, "num_lidar_pts": placed.num_lidar_pts,
             "source_num_lidar_pts": {t: max(before[t] - n, 0) for t, n in placed.lost_pts.items()}}
    write_bytes_atomic(out_dir / entry["file"], placed.sweep.points.astype("<f4").tobytes())
    if placed.sweep.labels is not None:
        entry["lidarseg_file"] = f"{LIDARSEG_FOLDER}/{version}/{seg_path.name}"
        write_bytes_atomic(out_dir / entry["lidarseg_file"], placed.sweep.labels.astype(np.uint8).tobytes())
    return entry


def _write_camera(out_dir: Path, sample, camera: str, result, shared_s: dict, lidar: dict | None = None) -> dict:
    """Write one camera's image + labels (when changed) and return its log row (with the sample's LiDAR entry)."""
    row = {"sample_token": sample.token, "camera": camera, "files": []}
    if lidar is not None:
        row["lidar"] = lidar
        row["files"] = [lidar["file"]] + ([lidar["lidarseg_file"]] if lidar["lidarseg_file"] else [])
    if camera not in result.views:
        row.update(status="skipped", reason=f"camera {camera} not in this sample")
        return row
    view = sample.cameras[camera]
    r = result.views[camera]
    # The objects placed in this camera's view: their annotation (once per object, over all cameras).
    row["objects"] = [
        {"object_index": i, "category": a.category, "attribute": p.attribute, "box_global": _box_global(p),
         "visible_px": float(result.visible_px[i]), "coverage_px": float(result.coverage_px[i]),
         "num_lidar_pts": lidar["num_lidar_pts"][i] if lidar is not None else 0}
        for i, (p, a, owner) in enumerate(zip(result.placements, result.assets, result.placed_for)) if owner == camera
    ]
    row["sample_data_token"] = view.sample_data_token
    timing = {**r.timing_s, **shared_s}
    if r.lighting is not None:
        row["lighting"] = {"level": r.lighting.level, "sun_source": r.lighting.sun_source,
                           "sun_visibility": round(float(r.lighting.sun_visibility), 3)}
    if np.array_equal(r.image, view.image):
        row.update(status="skipped", reason=r.skipped_reason or "image unchanged", timing_s=timing)
        return row
    from ..pipeline import labels_document

    t = time.perf_counter()
    name = Path(view.image_path).name
    image_rel = f"samples/{camera}/{name}"
    labels_rel = f"labels/{camera}/{Path(name).stem}.json"
    write_image_rgb(out_dir / image_rel, r.image)
    doc = labels_document(r, image_rel)
    doc.update(sample_token=sample.token, sample_data_token=view.sample_data_token, camera=camera)
    write_json_atomic(out_dir / labels_rel, doc)
    timing["write"] = time.perf_counter() - t
    row.update(status="ok", reason="", image=image_rel, files=[image_rel, labels_rel, *row["files"]], timing_s=timing,
               n_objects_visible=len(r.objects))
    return row


def _plan_rows(token: str, cameras: list[str], placed) -> list[dict]:
    rows = []
    for camera in cameras:
        res = placed.results.get(camera)
        objects = [
            {"object_index": i, "category": a.category, "attribute": p.attribute, "box_global": _box_global(p),
             "distance_m": round(float(p.distance_m), 2), "ground_source": p.ground_source,
             "drivable_source": p.drivable_source}
            for i, (p, a, owner) in enumerate(zip(placed.placements, placed.assets, placed.placed_for))
            if owner == camera
        ]
        rows.append({
            "sample_token": token, "camera": camera, "status": "planned" if objects else "no_placement",
            "reason": "" if objects else (res.reason if res is not None else f"camera {camera} not in this sample"),
            "objects": objects, "placement_report": None if res is None else res.report,
            "timing_s": {"placement": placed.seconds.get(camera, 0.0)},
        })
    return rows
