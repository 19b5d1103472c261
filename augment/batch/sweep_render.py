"""``--tracks --sweeps``: render a sample's tracks into the sweeps before it (camera 12 Hz, LiDAR 20 Hz).

The sweeps of sample k are the frames captured after keyframe k-1 and before keyframe k (nuScenes: a sweep's
``sample_token`` is the sample at the end of its interval; :mod:`streetaug.datasets.sweeps`). A track present
at both keyframes is drawn at its pose interpolated at each sweep's timestamp
(:meth:`~streetaug.placement.track.Track.pose_at`): position linear, rotation slerp. A track annotated at only
one of the two keyframes is not drawn between them (it does not exist there for the labels either).

Each camera sweep is lit by its keyframe's lighting (the sample's shared estimate, turned into the sweep
camera's frame: 0.04-0.5 s apart the light is the same) and occluded by the LiDAR frame closest in time.
Outputs keep the source layout: ``sweeps/<CHANNEL>/<name>`` (+ ``labels/...`` for camera sweeps), written
atomically; the tables then point the sweeps' ``sample_data`` rows at them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from streetaug.datasets.lidarseg import read_lidar_points
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import CameraView, Sample
from streetaug.datasets.sweeps import sweeps_of_sample, sweeps_unavailable_reason

from ..core import write_bytes_atomic, write_image_rgb, write_json_atomic
from ..pipeline import InsertOptions, insert_placed_into_sample, insert_placements_into_sweep, labels_document
from .layout import labels_file, output_file


@dataclass(frozen=True)
class SweepOutputs:
    """What rendering a sample's sweeps wrote.

    Attributes:
        files: sweep ``sample_data`` token -> its new file (relative to the output folder).
        labels: camera sweep token -> its labels file.
        by_channel: channel -> the files written for it (images and labels; LiDAR sweeps under LIDAR_TOP).
        note: why the sample's sweeps were not rendered (None when they were or it has none).
        seconds: wall time.
    """

    files: dict[str, str] = field(default_factory=dict)
    labels: dict[str, str] = field(default_factory=dict)
    by_channel: dict[str, list[str]] = field(default_factory=dict)
    note: str | None = None
    seconds: float = 0.0


def _nearest_lidar(reader: NuScenesReader, sample: Sample, lidar_rows: list[dict], t_us: int):
    """The LiDAR frame (keyframe or sweep of this sample) closest in time to ``t_us``: the scene depth there."""
    candidates = list(lidar_rows)
    key = reader.lidar_sample_data(sample.token)
    if key is not None:
        candidates.append(key)
    if not candidates:
        return None
    best = min(candidates, key=lambda r: abs(int(r["timestamp"]) - t_us))
    return reader.lidar_sweep(best["token"])


def render_sweeps(out_dir: Path, reader: NuScenesReader, sample: Sample, views: list[CameraView], tracks: list,
                  assets: list, label_fields: list[dict], shared_lighting, options: InsertOptions) -> SweepOutputs:
    """Render ``tracks`` (with their ``assets``) into the camera sweeps of ``views``' channels and the LiDAR
    sweeps of ``sample``; the sweeps' files must exist (else nothing is rendered and ``note`` says why)."""
    t0 = time.perf_counter()
    prev = reader.get("sample", sample.token).get("prev", "")
    if not prev:
        return SweepOutputs(seconds=time.perf_counter() - t0)  # a scene's first sample has no sweeps
    lidar_key = reader.lidar_sample_data(sample.token)
    lidar_channel = reader.sensor_of(lidar_key).get("channel", "LIDAR_TOP") if lidar_key is not None else None
    channels = [v.channel for v in views] + ([lidar_channel] if lidar_channel else [])
    note = sweeps_unavailable_reason(reader, [sample.token], channels)
    if note is not None:
        return SweepOutputs(note=note, seconds=time.perf_counter() - t0)
    alive = [i for i, t in enumerate(tracks) if t.index_of(prev) is not None and t.index_of(sample.token) is not None]
    files, labels, by_channel = {}, {}, {}
    lidar_rows = sweeps_of_sample(reader, sample.token, lidar_channel) if lidar_channel else []
    if alive:
        for view in views:
            for sd in sweeps_of_sample(reader, sample.token, view.channel):
                t = int(sd["timestamp"])
                placements = [tracks[i].placement_at_time(t, j) for j, i in enumerate(alive)]
                sweep_view = reader.camera_view(sd["token"])
                sweep_sample = sample.with_lidar(_nearest_lidar(reader, sample, lidar_rows, t),
                                                 cameras={view.channel: sweep_view}, timestamp_us=t)
                result = insert_placed_into_sample(sweep_sample, [sweep_view], placements, [assets[i] for i in alive],
                                                   options, [label_fields[i] for i in alive], shared_lighting)
                r = result.views[view.channel]
                if np.array_equal(r.image, sweep_view.image):
                    continue
                image_rel = output_file(sd["filename"], view.channel, sd["token"])
                write_image_rgb(out_dir / image_rel, r.image)
                doc = labels_document(r, image_rel)
                doc.update(sample_token=sample.token, sample_data_token=sd["token"], camera=view.channel,
                           is_key_frame=False)
                write_json_atomic(out_dir / labels_file(image_rel), doc)
                files[sd["token"]], labels[sd["token"]] = image_rel, labels_file(image_rel)
                by_channel.setdefault(view.channel, []).extend([image_rel, labels_file(image_rel)])
        class_index = {c["name"]: c["index"] for c in reader.table("category") if "index" in c}
        for sd in lidar_rows:
            t = int(sd["timestamp"])
            placements = [tracks[i].placement_at_time(t, j) for j, i in enumerate(alive)]
            points = read_lidar_points(reader.dataroot / sd["filename"])
            placed = insert_placements_into_sweep(points, None, reader.T_global_from_ego(sd) @ reader.T_ego_from_sensor(sd),
                                                  placements, [assets[i] for i in alive], sample.boxes, class_index)
            file = output_file(sd["filename"], lidar_channel, sd["token"])
            write_bytes_atomic(out_dir / file, placed.sweep.points.astype("<f4").tobytes())
            files[sd["token"]] = file
            by_channel.setdefault(lidar_channel, []).append(file)
    return SweepOutputs(files, labels, by_channel, None, time.perf_counter() - t0)


__all__ = ["SweepOutputs", "render_sweeps"]
