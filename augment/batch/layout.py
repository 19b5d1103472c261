"""The output folder of a batch: where the log, the summary, the plan, the augmented files go.

Output names keep the source's path relative to its dataroot (``samples/CAM_FRONT/sub0/x.jpg`` ->
``OUT/samples/CAM_FRONT/sub0/x.jpg``), so no two source files map to one output; a file outside
``samples/`` goes under ``samples/<CHANNEL>/`` with its whole relative path. See :mod:`.run` for the tree.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from ..core import InputError

LOG_FILE = "augment_log.jsonl"
SUMMARY_FILE = "summary.json"
PLAN_FILE = "plan.jsonl"
# Output folder of lidarseg labels that inserted objects changed (``lidarseg/`` links to the source's).
LIDARSEG_FOLDER = "lidarseg_augmented"
SAMPLES = "samples"
SWEEPS = "sweeps"  # nuScenes keeps non-keyframe files under sweeps/<CHANNEL>/
LABELS = "labels"


def shard_dir(out_dir: Path, shard: tuple[int, int]) -> Path:
    """The folder of shard ``(i, n)``'s log and summary."""
    return out_dir / "shards" / f"{shard[0]}-of-{shard[1]}"


def output_file(filename: str, channel: str, token: str = "") -> str:
    """The output path (relative to ``OUT``) of the augmented copy of a source file.

    Args:
        filename: the source ``sample_data.filename`` (relative to the dataroot).
        channel: its sensor channel (e.g. ``CAM_FRONT``, ``LIDAR_TOP``).
        token: its ``sample_data`` token (for the message).

    Convention: ``samples/...`` and ``sweeps/...`` keep their path; any other path ``p`` becomes
    ``samples/<channel>/p``.

    Raises:
        InputError: the filename is absolute or climbs out with ``..``.
    """
    parts = PurePosixPath(str(filename).replace("\\", "/")).parts
    if not parts or PurePosixPath(filename).is_absolute() or any(p in ("..", "") for p in parts):
        raise InputError(f"sample_data {token}: filename {filename!r} must be a relative path inside the dataroot")
    parts = tuple(p for p in parts if p != ".")
    if parts[0] not in (SAMPLES, SWEEPS) or len(parts) < 3:
        parts = (SAMPLES, channel, *parts)
    return str(PurePosixPath(*parts))


def labels_file(image_file: str) -> str:
    """The labels of an augmented image: ``samples/CAM/x/y.jpg`` -> ``labels/CAM/x/y.json``; a sweep's
    ``sweeps/CAM/y.jpg`` -> ``labels/sweeps/CAM/y.json``."""
    path = PurePosixPath(image_file)
    parts = path.parts[1:] if path.parts[0] != SWEEPS else path.parts
    return str(PurePosixPath(LABELS, *parts).with_suffix(".json"))


def check_unique_outputs(outputs: dict[str, list[str]]) -> None:
    """Refuse a plan in which two source ``sample_data`` map to one output file.

    Args:
        outputs: sample_data token -> its output files.

    Raises:
        InputError: naming both tokens and the file.
    """
    owner: dict[str, str] = {}
    for token, files in outputs.items():
        for f in files:
            key = f.casefold()  # case-insensitive file systems would merge these too
            if key in owner and owner[key] != token:
                raise InputError(f"sample_data {owner[key]} and {token} would both be written to OUT/{f}; "
                                 "rename one of the source files (their paths must differ)")
            owner[key] = token
