"""What a batch produces (:class:`BatchConfig`, saved beside the outputs) and how it runs (:class:`RunOptions`)."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from ..core import InputError, write_json_atomic

CONFIG_FILE = "batch_config.json"
CONFIG_SCHEMA = "streetaug.batch/1"
# Fields added after the schema's first release: a batch_config.json without them means their default.
OPTIONAL_FIELDS = {"limit", "match_camera", "tracks", "sweeps", "classes", "class_weights", "class_rules",
                   "class_sizes"}
# Fields that may change between runs into the same output folder (everything else must match to resume).
_MAY_CHANGE = ("limit",)


@dataclass(frozen=True)
class BatchConfig:
    """What to produce. Saved as ``OUTDIR/batch_config.json``; a rerun must ask for the same to resume.

    Attributes:
        dataroot: source nuScenes dataroot (absolute path).
        version: table folder, e.g. ``v1.0-mini``.
        cameras: channels to augment, in placement order; empty = every camera of each sample.
        limit: at most this many samples (the first ones, in scene order).
        seed: base seed; per-item seeds derive from (seed, sample token, camera).
        quality: render preset, ``draft`` | ``default`` | ``high``.
        level: lighting level, ``L0`` | ``L1`` | ``L2`` | ``L3`` | ``auto``.
        match_camera: blur and add noise to the objects like the image (:attr:`InsertOptions.match_camera`).
        ev: exposure of the camera response.
        n_objects: objects placed in each camera's view (each then rendered into every camera that sees it).
        yaw_sigma_deg: yaw noise around the ego heading (15 for augmentation, as the paper).
        asset, assets_dir, asset_front, asset_length: asset choice (see ``streetaug insert``); none = procedural cars.
        tracks: 0 = objects per sample (independent in each keyframe); N > 0 = N tracks per scene, each an
            instance through the scene's keyframes (parked or moving; :mod:`streetaug.placement.track`),
            rendered into every camera of every keyframe that sees it (``n_objects`` is then not used).
        sweeps: with ``tracks``, also render them into the camera and LiDAR sweeps between keyframes (poses
            interpolated at each sweep's time); a dataset without sweep files skips them with one reason.
        classes, class_weights: the class mix (``--classes``, ``--class-weights``; :class:`ClassMix`), None = cars.
        class_rules: absolute path of a class-rules file overriding the built-in placement rules, or None.
        class_sizes: absolute path of a class-sizes table for procedural objects, or None (the shipped one).
    """

    dataroot: str
    version: str
    cameras: tuple[str, ...] = ()
    limit: int | None = None
    seed: int = 0
    quality: str = "default"
    level: str = "auto"
    ev: float = 0.0
    match_camera: bool = True
    n_objects: int = 1
    yaw_sigma_deg: float = 15.0
    asset: str | None = None
    assets_dir: str | None = None
    asset_front: str = "+z"
    asset_length: float | None = None
    tracks: int = 0
    sweeps: bool = False
    classes: str | None = None
    class_weights: str | None = None
    class_rules: str | None = None
    class_sizes: str | None = None

    @property
    def class_mix(self):
        """The :class:`~streetaug.augment.assets.classes.ClassMix` of ``classes`` / ``class_weights`` (None = cars)."""
        from ..assets.classes import ClassMix  # deferred: the procedural generators

        return ClassMix.parse(self.classes, self.class_weights)

    def __post_init__(self) -> None:
        if self.tracks < 0:
            raise InputError(f"--tracks must be >= 0 (tracks per scene; 0 = objects per sample), got {self.tracks}")
        if self.sweeps and not self.tracks:
            raise InputError("--sweeps renders tracks into the sweeps between keyframes: give --tracks N too")

    def to_json(self) -> dict:
        return {"schema": CONFIG_SCHEMA, **asdict(self), "cameras": list(self.cameras)}

    @classmethod
    def from_json(cls, doc: dict, path: Path) -> "BatchConfig":
        if doc.get("schema") != CONFIG_SCHEMA:
            raise InputError(f"{path}: expected schema {CONFIG_SCHEMA!r}, got {doc.get('schema')!r}")
        names = {f.name for f in fields(cls)}
        missing = names - set(doc) - OPTIONAL_FIELDS
        if missing:
            raise InputError(f"{path}: missing fields {sorted(missing)}")
        values = {k: v for k, v in doc.items() if k in names}
        values["cameras"] = tuple(values.get("cameras") or ())
        return cls(**values)


@dataclass(frozen=True)
class RunOptions:
    """How to run (free to change between runs).

    Attributes:
        workers: local worker processes (1 = in this process).
        scheduler: address of a Dask scheduler (``tcp://HOST:PORT``); workers must see the same paths.
        dask_local: start a Dask LocalCluster with this many single-threaded worker processes.
        shard: (index, count): process only samples ``i`` with ``i % count == index``; ``streetaug merge`` joins.
        fail_fast: stop at the first failing sample (raise its error).
        dry_run: only plan placements (write ``plan.jsonl``), render nothing.
        contact_sheet: thumbnails in ``contact_sheet.png`` (0 = none).
        progress: show a tqdm progress bar.
    """

    workers: int = 1
    scheduler: str | None = None
    dask_local: int | None = None
    shard: tuple[int, int] | None = None
    fail_fast: bool = False
    dry_run: bool = False
    contact_sheet: int = 12
    progress: bool = True


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` -> (I, N) with 0 <= I < N (I is 0-based, as SLURM_ARRAY_TASK_ID / JOB_COMPLETION_INDEX)."""
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise InputError(f"--shard: expected I/N (e.g. 0/8), got {text!r}") from None
    if n < 1 or not 0 <= i < n:
        raise InputError(f"--shard: expected 0 <= I < N, got {text!r}")
    return i, n


def load_config(out_dir: Path) -> BatchConfig | None:
    path = out_dir / CONFIG_FILE
    if not path.is_file():
        return None
    try:
        return BatchConfig.from_json(json.loads(path.read_text()), path)
    except (json.JSONDecodeError, TypeError) as e:
        raise InputError(f"{path}: not a valid batch config ({e}); remove it or use a new --out") from None


def check_and_save_config(out_dir: Path, config: BatchConfig) -> None:
    """Refuse to resume an output folder made with different options; then save ``config``."""
    old = load_config(out_dir)
    if old is not None:
        diff = [f.name for f in fields(BatchConfig)
                if f.name not in _MAY_CHANGE and getattr(old, f.name) != getattr(config, f.name)]
        if diff:
            shown = ", ".join(f"{k}: {getattr(old, k)!r} -> {getattr(config, k)!r}" for k in diff)
            raise InputError(f"{out_dir / CONFIG_FILE}: this folder was made with other options ({shown}); "
                             "rerun with the same options to resume, or choose a new --out")
        if old == config:
            return
    write_json_atomic(out_dir / CONFIG_FILE, config.to_json())
