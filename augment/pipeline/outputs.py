"""The contract's files of one insertion: ``image.png|jpg``, ``labels.json`` (and with ``--debug`` the maps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core import write_exr, write_image_rgb, write_json_atomic
from .results import InsertResult

LABELS_SCHEMA = "streetaug.labels/1"


def labels_document(result: InsertResult, image_name: str) -> dict:
    """The contract's labels.json content."""
    doc = {"schema": LABELS_SCHEMA, "image": image_name, "objects": result.objects, "timing_s": result.timing_s}
    if result.skipped_reason:
        doc["skipped_reason"] = result.skipped_reason
    if result.placement_report is not None:
        doc["placement_report"] = result.placement_report
    if result.lighting is not None:
        doc["lighting"] = {"level": result.lighting.level, "sun_source": result.lighting.sun_source,
                           "sun_visibility": result.lighting.sun_visibility, "reason": result.lighting.reason}
    return doc


def write_insert_outputs(result: InsertResult, out_dir: str | Path, image_suffix: str = ".png", debug: bool = False) -> Path:
    """Write ``image.png|jpg`` and ``labels.json`` (and with ``debug`` the mask and shadow maps) atomically."""
    out_dir = Path(out_dir)
    image_name = "image" + (".jpg" if image_suffix.lower() in (".jpg", ".jpeg") else ".png")
    write_image_rgb(out_dir / image_name, result.image)
    if debug:
        write_image_rgb(out_dir / "mask.png", np.clip(np.round(result.mask * 255), 0, 255).astype(np.uint8))
        write_exr(out_dir / "shadow.exr", result.shadow_ratio.astype(np.float32))
    # labels.json last: its presence marks the output as complete.
    write_json_atomic(out_dir / "labels.json", labels_document(result, image_name))
    return out_dir / image_name
