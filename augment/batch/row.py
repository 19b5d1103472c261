"""One line of ``augment_log.jsonl`` (and of ``plan.jsonl``): :class:`LogRow`, typed, with its JSON form.

The file contract (``interfaces.md``): one JSON object per attempted image with ``sample_token``,
``camera``, ``status`` (ok / skipped / failed; ``plan.jsonl``: planned / no_placement), ``reason`` and the
per-stage seconds ``timing_s``. The other keys are this tool's own (files to check on resume, the objects
placed in the camera's view, the sample's LiDAR sweep, the worker); keys this version does not know are
kept as they are, so that rewriting an older log (resume, merge) loses nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

DONE_STATUSES = ("ok", "skipped")


def _drop_none(doc: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in doc.items() if v is not None}


@dataclass(frozen=True)
class LoggedObject:
    """An object placed in a camera's view (logged once per object, on the row of that camera).

    Attributes:
        object_index: its index among the sample's placed objects (the annotation token derives from it).
        category, attribute: nuScenes category and attribute names.
        box_global: ``{"translation": [x, y, z], "size": [w, l, h], "rotation": [w, x, y, z]}`` (global frame,
            metres) exactly as a nuScenes ``sample_annotation``.
        visible_px, coverage_px: visible / unoccluded pixels summed over the sample's rendered cameras.
        num_lidar_pts: LiDAR points inside its box after insertion.
        distance_m, ground_source, drivable_source: placement details (``plan.jsonl`` only).
        track: ``--tracks``: ``"<scene token>/<track index>"``, the instance this annotation belongs to
            (``object_index`` is then the track index); None for objects of one sample.
        velocity: ``--tracks``: the trajectory's velocity [vx, vy, vz] (m/s, global) at this keyframe.
    """

    object_index: int
    category: str
    attribute: str | None
    box_global: dict[str, list[float]]
    visible_px: float | None = None
    coverage_px: float | None = None
    num_lidar_pts: int | None = None
    distance_m: float | None = None
    ground_source: str | None = None
    drivable_source: str | None = None
    track: str | None = None
    velocity: list[float] | None = None

    @property
    def visible_fraction(self) -> float:
        """Visible share of the object's pixels over the cameras (0 when no camera showed any)."""
        coverage = float(self.coverage_px or 0.0)
        return float(self.visible_px or 0.0) / coverage if coverage > 0 else 0.0

    def to_json(self) -> dict[str, Any]:
        doc = _drop_none({f.name: getattr(self, f.name) for f in fields(self)})
        return {**doc, "attribute": self.attribute}  # kept when null

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> "LoggedObject":
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in doc.items() if k in names})


@dataclass(frozen=True)
class LidarEntry:
    """The sample's LiDAR sweep with its placed objects in it (the same entry on each camera row).

    Attributes:
        sample_data_token: the sweep's ``sample_data`` token.
        file: the new sweep, relative to the output folder.
        lidarseg_file: its lidarseg labels (None without lidarseg).
        num_lidar_pts: (n_objects,) points inside each placed object's box.
        source_num_lidar_pts: annotation token -> its new count, for the sample's boxes that lost points
            behind an inserted object.
    """

    sample_data_token: str
    file: str
    lidarseg_file: str | None
    num_lidar_pts: list[int]
    source_num_lidar_pts: dict[str, int]

    @property
    def files(self) -> list[str]:
        """The files this entry stands for."""
        return [self.file] + ([self.lidarseg_file] if self.lidarseg_file else [])

    def to_json(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> "LidarEntry":
        return cls(doc["sample_data_token"], doc["file"], doc.get("lidarseg_file"),
                   list(doc.get("num_lidar_pts", [])), dict(doc.get("source_num_lidar_pts", {})))


@dataclass(frozen=True)
class LoggedLighting:
    """The lighting an image was rendered with: level, sun source and visibility (rounded to 0.001)."""

    level: str
    sun_source: str
    sun_visibility: float

    def to_json(self) -> dict[str, Any]:
        return {"level": self.level, "sun_source": self.sun_source, "sun_visibility": self.sun_visibility}

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> "LoggedLighting":
        return cls(doc["level"], doc["sun_source"], doc["sun_visibility"])


@dataclass(frozen=True)
class LogRow:
    """One attempted image (one camera of one sample).

    Attributes:
        sample_token, camera: the image.
        status: ``ok`` | ``skipped`` | ``failed`` (``plan.jsonl``: ``planned`` | ``no_placement``).
        reason: why it was skipped or failed ("" for ok).
        timing_s: seconds per stage (``load``, ``placement``, ``lighting``, ``depth``, ``render``, ``write``,
            ``total``, ...), the sample's shared stages divided among its cameras.
        files: the files it wrote, relative to the output folder (all must exist for a resume to skip it).
        file_checks: file -> ``{"size": bytes, "sha256": hex}`` of each of ``files`` as written; a resume
            redoes the image when a file's size or checksum differs (truncated, overwritten).
        image: the augmented image (ok rows).
        sample_data_token: the camera's ``sample_data`` token.
        objects: the objects placed in this camera's view (None when the camera is not in the sample).
        lidar: the sample's sweep with the objects in it (None when nothing was placed or no LiDAR).
        lighting: the lighting of the image.
        n_objects_visible: objects with a label in this image (ok rows).
        placement_report: rule name -> candidates rejected (``plan.jsonl``).
        seconds, cpu_s: the sample's wall and CPU seconds divided among its cameras.
        task_span: (start, end) Unix time (seconds) of the sample's task in its worker (the same on each of its
            rows): the batch's worker timeline (:func:`~.report.worker_timeline`).
        worker, peak_rss_mb: the worker (``host:pid``) and its peak resident memory.
        sweep_files: ``--sweeps``: sweep ``sample_data`` token -> its new file, for the sweeps before this
            sample of this camera (the LiDAR sweeps on every camera row of the sample); also in ``files``.
        sweeps_note: ``--sweeps``: why this sample's sweeps were not rendered (e.g. their files are absent).
        class_reasons: detection class -> why an object of it drawn for this camera's view was not placed.
        extra: keys this version does not know (kept on rewriting).
    """

    sample_token: str
    camera: str
    status: str
    reason: str = ""
    timing_s: dict[str, float] = field(default_factory=dict)
    files: tuple[str, ...] = ()
    image: str | None = None
    sample_data_token: str | None = None
    objects: tuple[LoggedObject, ...] | None = None
    lidar: LidarEntry | None = None
    lighting: LoggedLighting | None = None
    n_objects_visible: int | None = None
    placement_report: dict[str, int] | None = None
    seconds: float | None = None
    cpu_s: float | None = None
    worker: str | None = None
    peak_rss_mb: float | None = None
    file_checks: dict[str, dict[str, Any]] | None = None
    sweep_files: dict[str, str] | None = None
    sweeps_note: str | None = None
    class_reasons: dict[str, str] | None = None
    task_span: tuple[float, float] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def key(self) -> tuple[str, str]:
        """(sample_token, camera): one image."""
        return self.sample_token, self.camera

    @property
    def done(self) -> bool:
        """Finished (ok or skipped), so a resume does not redo it if its files exist."""
        return self.status in DONE_STATUSES

    def to_json(self) -> dict[str, Any]:
        """The JSON object of the log line (None fields left out)."""
        doc = {
            **self.extra,
            "sample_token": self.sample_token, "camera": self.camera, "status": self.status, "reason": self.reason,
            "timing_s": dict(self.timing_s), "files": list(self.files), "image": self.image,
            "sample_data_token": self.sample_data_token,
            "objects": None if self.objects is None else [o.to_json() for o in self.objects],
            "lidar": None if self.lidar is None else self.lidar.to_json(),
            "lighting": None if self.lighting is None else self.lighting.to_json(),
            "n_objects_visible": self.n_objects_visible, "seconds": self.seconds, "cpu_s": self.cpu_s,
            "worker": self.worker, "peak_rss_mb": self.peak_rss_mb,
            "file_checks": None if self.file_checks is None else {k: dict(v) for k, v in self.file_checks.items()},
            "sweep_files": None if self.sweep_files is None else dict(self.sweep_files), "sweeps_note": self.sweeps_note,
            "class_reasons": dict(self.class_reasons) if self.class_reasons else None,
            "task_span": None if self.task_span is None else list(self.task_span),
        }
        doc = _drop_none(doc)
        if self.status in ("planned", "no_placement"):
            doc["placement_report"] = self.placement_report  # kept when null, as before
        return doc

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> "LogRow":
        """The row of a log line's JSON object (``sample_token`` and ``camera`` are required)."""
        known = {f.name for f in fields(cls)} - {"extra"}
        objects, lidar, lighting = doc.get("objects"), doc.get("lidar"), doc.get("lighting")
        return cls(
            sample_token=doc["sample_token"], camera=doc["camera"], status=doc.get("status", ""),
            reason=doc.get("reason") or "", timing_s=dict(doc.get("timing_s") or {}),
            files=tuple(doc.get("files") or ()), image=doc.get("image"), sample_data_token=doc.get("sample_data_token"),
            objects=None if objects is None else tuple(LoggedObject.from_json(o) for o in objects),
            lidar=None if lidar is None else LidarEntry.from_json(lidar),
            lighting=None if lighting is None else LoggedLighting.from_json(lighting),
            n_objects_visible=doc.get("n_objects_visible"), placement_report=doc.get("placement_report"),
            seconds=doc.get("seconds"), cpu_s=doc.get("cpu_s"), worker=doc.get("worker"),
            peak_rss_mb=doc.get("peak_rss_mb"), file_checks=doc.get("file_checks"),
            sweep_files=doc.get("sweep_files"), sweeps_note=doc.get("sweeps_note"),
            class_reasons=doc.get("class_reasons"),
            task_span=None if doc.get("task_span") is None else tuple(doc["task_span"]),
            extra={k: v for k, v in doc.items() if k not in known},
        )
