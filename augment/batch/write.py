"""What a worker writes for one sample -- the LiDAR sweep with the objects in it, each camera's image and
labels -- and the log rows that describe them."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from streetaug.datasets.lidarseg import read_lidar_points, read_lidarseg_labels
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import Sample
from streetaug.placement.place import Placement

from ..core import write_bytes_atomic, write_image_rgb, write_json_atomic
from ..pipeline import SampleInsertResult, SamplePlacement, insert_placements_into_sweep, labels_document
from .layout import LIDARSEG_FOLDER, labels_file, output_file
from .log import file_check
from .row import LidarEntry, LoggedLighting, LoggedObject, LogRow


def box_global(placement: Placement) -> dict[str, list[float]]:
    """The placed box as a nuScenes ``sample_annotation``: translation, size (w, l, h), rotation [w, x, y, z]."""
    box = placement.box
    return {"translation": [float(v) for v in box.center], "size": [float(v) for v in box.wlh],
            "rotation": [float(v) for v in box.rotation]}


def write_lidar(out_dir: Path, reader: NuScenesReader, sample: Sample, result: SampleInsertResult,
                version: str) -> LidarEntry | None:
    """Write the sample's LiDAR sweep (and lidarseg labels) with the placed objects in it.

    Returns the entry shared by the sample's camera rows; None when nothing was placed or the sample has
    no LiDAR.
    """
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
    file = output_file(sd["filename"], reader.sensor_of(sd).get("channel", "LIDAR_TOP"), sd["token"])
    lidarseg_file = None if placed.sweep.labels is None else f"{LIDARSEG_FOLDER}/{version}/{seg_path.name}"
    write_bytes_atomic(out_dir / file, placed.sweep.points.astype("<f4").tobytes())
    if lidarseg_file is not None:
        write_bytes_atomic(out_dir / lidarseg_file, placed.sweep.labels.astype(np.uint8).tobytes())
    return LidarEntry(sd["token"], file, lidarseg_file, placed.num_lidar_pts,
                      {t: max(before[t] - n, 0) for t, n in placed.lost_pts.items()})


def logged_objects(result: SampleInsertResult, camera: str, lidar: LidarEntry | None) -> tuple[LoggedObject, ...]:
    """The objects placed in ``camera``'s view: their annotation (once per object, over all cameras)."""
    return tuple(
        LoggedObject(object_index=i, category=a.category, attribute=p.attribute, box_global=box_global(p),
                     visible_px=float(result.visible_px[i]), coverage_px=float(result.coverage_px[i]),
                     num_lidar_pts=lidar.num_lidar_pts[i] if lidar is not None else 0)
        for i, (p, a, owner) in enumerate(zip(result.placements, result.assets, result.placed_for)) if owner == camera
    )


def write_camera(out_dir: Path, sample: Sample, camera: str, result: SampleInsertResult, shared_s: dict[str, float],
                 lidar: LidarEntry | None = None, image_rel: str | None = None) -> LogRow:
    """Write one camera's image + labels (when changed) and return its log row (with the sample's LiDAR entry).

    Args:
        shared_s: the sample's shared stages (``load``, ``lidar``), seconds per camera.
        image_rel: the image's output path (:func:`~.layout.output_file` of its source filename).
    """
    files = tuple(lidar.files) if lidar is not None else ()
    if camera not in result.views:
        return LogRow(sample.token, camera, "skipped", f"camera {camera} not in this sample", files=files, lidar=lidar)
    view = sample.cameras[camera]
    r = result.views[camera]
    timing = {**r.timing_s, **shared_s}
    lighting = None if r.lighting is None else LoggedLighting(
        r.lighting.level, r.lighting.sun_source, round(float(r.lighting.sun_visibility), 3))
    placed = result.placement_results.get(camera)
    class_reasons = dict(placed.class_reasons) if placed is not None and placed.class_reasons else None
    row = LogRow(sample.token, camera, "skipped", r.skipped_reason or "image unchanged", timing_s=timing, files=files,
                 sample_data_token=view.sample_data_token, objects=logged_objects(result, camera, lidar), lidar=lidar,
                 lighting=lighting, class_reasons=class_reasons)
    if np.array_equal(r.image, view.image):
        return row
    t = time.perf_counter()
    image_rel = image_rel or f"samples/{camera}/{Path(view.image_path).name}"
    labels_rel = labels_file(image_rel)
    write_image_rgb(out_dir / image_rel, r.image)
    doc = labels_document(r, image_rel)
    doc.update(sample_token=sample.token, sample_data_token=view.sample_data_token, camera=camera)
    if lidar is not None:  # the points of the sample's LiDAR sweep on each object, as its annotation has them
        for obj in doc.get("objects", []):
            obj["num_lidar_pts"] = int(lidar.num_lidar_pts[obj["object_index"]])
    write_json_atomic(out_dir / labels_rel, doc)
    timing["write"] = time.perf_counter() - t
    return LogRow(sample.token, camera, "ok", "", timing_s=timing, files=(image_rel, labels_rel, *files),
                  image=image_rel, sample_data_token=view.sample_data_token, objects=row.objects, lidar=lidar,
                  lighting=lighting, n_objects_visible=len(r.objects), class_reasons=class_reasons)


def with_file_checks(out_dir: Path, rows: list[LogRow]) -> list[LogRow]:
    """The rows with the size and sha256 of each file they wrote (each file hashed once)."""
    checks: dict[str, dict] = {}
    for row in rows:
        for f in row.files:
            if f not in checks:
                checks[f] = file_check(out_dir / f)
    return [replace(r, file_checks={f: checks[f] for f in r.files}) if r.files else r for r in rows]


def plan_rows(token: str, cameras: list[str], placed: SamplePlacement) -> list[LogRow]:
    """``--dry-run``: one row per camera with the objects planned in its view (nothing rendered)."""
    rows = []
    for camera in cameras:
        res = placed.results.get(camera)
        objects = tuple(
            LoggedObject(object_index=i, category=a.category, attribute=p.attribute, box_global=box_global(p),
                         distance_m=round(float(p.distance_m), 2), ground_source=p.ground_source,
                         drivable_source=p.drivable_source)
            for i, (p, a, owner) in enumerate(zip(placed.placements, placed.assets, placed.placed_for))
            if owner == camera
        )
        reason = "" if objects else (res.reason if res is not None else f"camera {camera} not in this sample")
        rows.append(LogRow(token, camera, "planned" if objects else "no_placement", reason,
                           timing_s={"placement": placed.seconds.get(camera, 0.0)}, objects=objects,
                           placement_report=None if res is None else res.report,
                           class_reasons=dict(res.class_reasons) if res is not None and res.class_reasons else None))
    return rows
