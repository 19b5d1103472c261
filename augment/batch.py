"""Batch augmentation over a dataset (first version: one process, images + labels, resumable).

Output layout under OUTDIR:
    samples/<CAMERA>/<source image name>     augmented images
    labels/<CAMERA>/<source image stem>.json labels (contract labels.json format)
    augment_log.jsonl                         one JSON line per attempted image
    summary.json                              counts by status/reason, stage-time percentiles

Resuming: an image whose log line says ``ok`` or ``skipped`` and whose files exist is not redone.
Every file is written atomically and the log line is appended (and fsync'ed) only after the image and
its labels are in place, so a crash at any point leaves a consistent output that a rerun completes.
"""

from __future__ import annotations

import json
import os
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .io import write_json_atomic


@dataclass(frozen=True)
class BatchConfig:
    cameras: tuple[str, ...] = ("CAM_FRONT",)
    limit: int | None = None
    seed: int = 0
    quality: str = "default"
    level: str = "L1"
    ev: float = 0.0
    asset: Path | None = None
    assets_dir: Path | None = None
    asset_front: str = "+z"
    asset_length: float | None = None
    fail_fast: bool = False


def read_log(log_path: Path) -> dict[tuple[str, str], dict]:
    """Last log entry per (sample_token, camera); a truncated last line (crash) is ignored."""
    entries: dict[tuple[str, str], dict] = {}
    if not log_path.is_file():
        return entries
    for line in log_path.read_text().splitlines():
        try:
            row = json.loads(line)
            entries[(row["sample_token"], row["camera"])] = row
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
    return entries


def _append_log(log_path: Path, row: dict) -> None:
    with open(log_path, "a") as f:
        f.write(json.dumps(row, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _is_done(row: dict | None, out_dir: Path) -> bool:
    if row is None or row.get("status") not in ("ok", "skipped"):
        return False
    return all((out_dir / rel).is_file() for rel in row.get("files", []))


def run_batch(reader, out_dir: str | Path, config: BatchConfig) -> dict:
    """Augment every (sample, camera) of ``reader``; returns the summary (also written to summary.json)."""
    from .assets.select import select_assets
    from .io import write_image_rgb
    from .pipeline import InsertOptions, insert_into_view, item_seed, labels_document

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log_path = out_dir / "augment_log.jsonl"
    done = read_log(log_path)
    tokens = reader.sample_tokens()
    if config.limit is not None:
        tokens = tokens[: config.limit]
    items = [(tok, cam) for tok in tokens for cam in config.cameras]
    options = InsertOptions(quality=config.quality, level=config.level, seed=config.seed, ev=config.ev)
    stage_times: dict[str, list[float]] = {}
    counts: Counter = Counter()
    reasons: Counter = Counter()
    sample = None
    for token, camera in tqdm(items, desc="augment", unit="img", dynamic_ncols=True):
        if _is_done(done.get((token, camera)), out_dir):
            counts["resumed"] += 1
            continue
        row = {"sample_token": token, "camera": camera}
        t0 = time.perf_counter()
        try:
            if sample is None or sample.token != token:  # items are ordered by sample: load each once
                sample = reader.sample(token)
            if camera not in sample.cameras:
                raise LookupError(f"camera {camera} not in sample")
            view = sample.cameras[camera]
            rng = item_seed(config.seed, "asset", token, camera)
            assets = select_assets(rng, 1, config.asset, config.assets_dir, config.asset_front, config.asset_length)
            result = insert_into_view(sample, view, assets, options)
            image_rel = Path("samples") / camera / Path(view.image_path).name
            labels_rel = Path("labels") / camera / (Path(view.image_path).stem + ".json")
            write_image_rgb(out_dir / image_rel, result.image)
            write_json_atomic(out_dir / labels_rel, labels_document(result, str(image_rel)))
            row.update(status="skipped" if result.skipped_reason else "ok", reason=result.skipped_reason or "",
                       files=[str(image_rel), str(labels_rel)], timing_s=result.timing_s,
                       n_objects=len(result.objects))
            for stage, seconds in result.timing_s.items():
                stage_times.setdefault(stage, []).append(seconds)
        except Exception as e:  # noqa: BLE001 - log, skip, go on
            if config.fail_fast:
                raise
            row.update(status="failed", reason=f"{type(e).__name__}: {e}")
        row["seconds"] = time.perf_counter() - t0
        _append_log(log_path, row)
        counts[row["status"]] += 1
        if row.get("reason"):
            reasons[row["reason"][:120]] += 1
    summary = {
        "counts": dict(counts),
        "reasons": dict(reasons),
        "items": len(items),
        "stage_seconds": {
            stage: {p: float(np.percentile(v, int(p[1:]))) for p in ("p50", "p90", "p99")}
            for stage, v in stage_times.items()
        },
    }
    write_json_atomic(out_dir / "summary.json", summary)
    return summary
