"""Sweeps of a nuScenes dataset: the non-keyframe ``sample_data`` rows of a sample, and whether their files exist.

nuScenes captures cameras at 12 Hz and the LiDAR at 20 Hz; only the 2 Hz keyframes (``is_key_frame``
true, files under ``samples/``) are annotated; the frames in between are *sweeps* (``is_key_frame``
false, files under ``sweeps/<CHANNEL>/``). Every frame of a channel is chained by ``prev`` / ``next``
through keyframes and sweeps alike.

Convention: a sweep's ``sample_token`` is the sample at the END of its interval, i.e. the sweeps of sample
k are those captured after the previous keyframe and before sample k's keyframe. This is what the devkit's
``NuScenes.get_boxes`` assumes (it interpolates a sweep's boxes between ``sample.prev`` and ``sample``,
clamping the sweep's time into that interval). The first sample of a scene has no sweeps.

A dataset may list its sweeps without holding their files (nuScenes' metadata with only the keyframe blobs
downloaded; the bundled sequence scene without ``--sweeps``): :func:`sweeps_unavailable_reason` gives the
one-line reason a caller logs to skip them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from .errors import DatasetError
from .nuscenes import NuScenesReader

SWEEPS_HINT = ("the dataset holds keyframes only: download nuScenes' sweep blobs, or for the bundled sequence "
               "scene run `streetaug make-samples --sequence --sweeps --out DIR`")


def _channel(reader: NuScenesReader, sample_data: dict) -> str:
    return str(reader.sensor_of(sample_data).get("channel", ""))


def keyframe_of_sample(reader: NuScenesReader, sample_token: str, channel: str) -> dict | None:
    """The keyframe ``sample_data`` row of ``channel`` in a sample, or None when the sample has none."""
    for sd in reader.sample_data_rows(sample_token):
        if sd.get("is_key_frame", False) and _channel(reader, sd) == channel:
            return sd
    return None


def sweeps_of_sample(reader: NuScenesReader, sample_token: str, channel: str) -> list[dict]:
    """The sweeps (non-keyframe ``sample_data`` rows) of ``channel`` that belong to a sample, in time order.

    Args:
        reader: the dataset.
        sample_token: a sample (keyframe) token.
        channel: e.g. ``CAM_FRONT`` or ``LIDAR_TOP``.

    Returns:
        The rows whose ``sample_token`` is this sample and ``is_key_frame`` is false, sorted by ``timestamp``
        (the frames between the previous keyframe and this one; [] for a scene's first sample or a dataset
        without sweeps).
    """
    reader.get("sample", sample_token)  # an unknown sample is an error, not "no sweeps"
    rows = [sd for sd in reader.sample_data_rows(sample_token)
            if not sd.get("is_key_frame", False) and _channel(reader, sd) == channel]
    return sorted(rows, key=lambda r: int(r.get("timestamp", 0)))


def sweeps_by_links(reader: NuScenesReader, sample_token: str, channel: str) -> list[dict]:
    """The same sweeps as :func:`sweeps_of_sample`, found by walking ``prev`` from the sample's keyframe back to
    the previous keyframe (the channel's chain); returned in time order.

    Raises:
        DatasetError: the sample has no keyframe of ``channel``, the chain meets a frame of another channel,
            goes back in time the wrong way, or loops.
    """
    key = keyframe_of_sample(reader, sample_token, channel)
    if key is None:
        raise DatasetError(f"{reader.table_dir / 'sample_data.json'}: sample {sample_token!r} has no keyframe of "
                           f"channel {channel!r}")
    out: list[dict] = []
    row, seen = key, {key["token"]}
    while row.get("prev"):
        prev = reader.get("sample_data", row["prev"])
        where = reader.where("sample_data", prev, None)
        if prev["token"] in seen:
            raise DatasetError(f"{where}: the 'prev' links of channel {channel} loop")
        if _channel(reader, prev) != channel:
            raise DatasetError(f"{where}: reached by 'prev' from a {channel} frame but is a "
                               f"{_channel(reader, prev)} frame")
        if int(prev["timestamp"]) >= int(row["timestamp"]):
            raise DatasetError(f"{where}: 'prev' of a frame at {row['timestamp']} us but captured at "
                               f"{prev['timestamp']} us (expected earlier)")
        if prev.get("is_key_frame", False):
            break
        seen.add(prev["token"])
        out.append(prev)
        row = prev
    return out[::-1]


def interpolation_of(reader: NuScenesReader, sample_data: dict) -> tuple[str, str, float]:
    """Where a frame lies between two samples, as the devkit's ``NuScenes.get_boxes`` interpolates its boxes.

    Returns:
        (sample_before, sample_after, fraction): a sweep lies ``fraction`` (0..1, clamped) of the way from
        ``sample_before`` (its sample's ``prev``) to ``sample_after`` (its ``sample_token``); boxes at its time
        are ``before + fraction x (after - before)`` per instance. A keyframe, or a frame of a scene's first
        sample, gives (its sample, its sample, 1.0).
    """
    sample = reader.get("sample", sample_data.get("sample_token", ""))
    if sample_data.get("is_key_frame", False) or not sample.get("prev"):
        return sample["token"], sample["token"], 1.0
    before = reader.get("sample", sample["prev"])
    t0, t1, t = int(before["timestamp"]), int(sample["timestamp"]), int(sample_data["timestamp"])
    fraction = (min(max(t, t0), t1) - t0) / (t1 - t0) if t1 > t0 else 1.0
    return before["token"], sample["token"], float(fraction)


def sweep_path(reader: NuScenesReader, sample_data: dict) -> Path:
    """The file of a ``sample_data`` row (keyframe or sweep), resolved inside the dataroot."""
    return reader.path_field("sample_data", sample_data)


def missing_sweep_files(reader: NuScenesReader, rows: Iterable[dict]) -> list[Path]:
    """The files of ``rows`` (``sample_data``) that do not exist, in the rows' order."""
    return [p for p in (sweep_path(reader, r) for r in rows) if not p.is_file()]


def sweeps_unavailable_reason(reader: NuScenesReader, sample_tokens: Iterable[str],
                              channels: Iterable[str]) -> str | None:
    """Why the sweeps of these samples and channels cannot be used, as one line; None when they all can.

    They cannot when a sample after the scene's first lists no sweep of a channel (a keyframes-only
    dataset), or when sweep files are absent. A caller that renders into sweeps logs the reason once and
    skips the sweeps (keyframes stay usable).
    """
    listed: dict[str, int] = {}
    missing: dict[str, list[Path]] = {}
    empty: list[str] = []
    for token in sample_tokens:
        has_prev = bool(reader.get("sample", token).get("prev"))
        for channel in channels:
            rows = sweeps_of_sample(reader, token, channel)
            if has_prev and not rows:
                empty.append(channel)
            listed[channel] = listed.get(channel, 0) + len(rows)
            missing.setdefault(channel, []).extend(missing_sweep_files(reader, rows))
    if empty:
        chans = sorted(set(empty))
        return (f"{reader.table_dir / 'sample_data.json'} lists no sweeps of {', '.join(chans)} for "
                f"{len(empty)} sample/channel pair(s); {SWEEPS_HINT}")
    absent = {c: m for c, m in missing.items() if m}
    if absent:
        n_abs = sum(len(m) for m in absent.values())
        n_all = sum(listed[c] for c in absent)
        example = next(iter(absent.values()))[0]
        per = ", ".join(f"{c} {len(m)}/{listed[c]}" for c, m in sorted(absent.items()))
        return (f"{n_abs} of {n_all} sweep files are absent ({per}; e.g. {example}); {SWEEPS_HINT}")
    return None


__all__ = [
    "SWEEPS_HINT", "interpolation_of", "keyframe_of_sample", "missing_sweep_files", "sweep_path", "sweeps_by_links", "sweeps_of_sample",
    "sweeps_unavailable_reason",
]
