"""What a batch tells its user: ``summary.json``, the one-screen text summary, and a contact sheet."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from ..core import read_image_rgb, write_image_rgb
from .row import LogRow

SUMMARY_SCHEMA = "streetaug.batch_summary/1"
PERCENTILES = (50, 90, 99)
MAIN_STAGES = ("load", "placement", "lighting", "depth", "render", "write", "total", "cpu")


def reason_key(status: str, reason: str) -> str:
    """A reason with its numbers and per-camera details folded, so that like reasons count together."""
    text = re.sub(r"\b(CAM|LIDAR|RADAR)_[A-Z_]+: ", "", reason or "")
    text = re.sub(r"\d+(\.\d+)?", "N", text.split(" (")[0])
    return f"{status}: {text[:100]}"


def summarize(rows: list[LogRow], this_run: dict | None = None) -> dict:
    """Summary of a batch's final log rows (one per image) plus the numbers of this run."""
    counts = Counter(r.status for r in rows)
    reasons = Counter(reason_key(r.status, r.reason) for r in rows if r.reason)
    lighting = Counter(f"{r.lighting.level} sun={r.lighting.sun_source}" for r in rows
                       if r.status == "ok" and r.lighting)
    stages: dict[str, list[float]] = {}
    for r in rows:
        if r.status == "ok":
            for stage, seconds in r.timing_s.items():
                stages.setdefault(stage, []).append(float(seconds))
            if r.cpu_s is not None:  # the sample's CPU time per camera, for comparison with "total"
                stages.setdefault("cpu", []).append(float(r.cpu_s))
    workers: dict[str, dict] = {}
    for r in rows:
        if r.worker is not None:
            w = workers.setdefault(r.worker, {"images": 0, "peak_rss_mb": 0.0})
            w["images"] += 1
            w["peak_rss_mb"] = max(w["peak_rss_mb"], float(r.peak_rss_mb or 0.0))
    objects = [o for r in rows if r.done for o in r.objects or ()]
    return {
        **per_class(rows, objects),
        "schema": SUMMARY_SCHEMA,
        "counts": {k: counts[k] for k in sorted(counts)},
        "images": len(rows),
        "samples": len({r.sample_token for r in rows}),
        "objects_inserted": len(objects),
        "reasons": dict(reasons.most_common(20)),
        "lighting": dict(lighting.most_common()),
        "stage_seconds": {
            stage: {f"p{p}": round(float(np.percentile(v, p)), 4) for p in PERCENTILES}
            for stage, v in sorted(stages.items(), key=lambda kv: _stage_order(kv[0]))
        },
        "workers": workers,
        "this_run": this_run or {},
    }


def worker_timeline(rows: list[LogRow], dispatched_at: float, ended_at: float, workers: int | None = None) -> dict:
    """How busy the workers were between the first task's dispatch and the last result (Unix times).

    Busy time is the sum of the tasks' own wall spans (``task_span``), so another job sharing the cores
    stretches busy and total time alike; the CPU-based ``busy_workers`` drops instead. Each worker's idle
    time splits into ``startup`` (dispatch to its first task: spawning, imports), ``waiting`` (between its
    tasks: no task ready) and ``tail`` (its last task done, others still working; then the last result's
    delivery). ``workers``: the executor's worker count (a worker that got no task is idle throughout).
    """
    spans: dict[str, dict[str, tuple[float, float]]] = {}
    for r in rows:
        if r.task_span is not None and r.worker is not None:
            spans.setdefault(r.worker, {})[r.sample_token] = r.task_span
    wall = max(ended_at - dispatched_at, 1e-9)
    n = max(workers or 0, len(spans))
    idle = {"startup": 0.0, "waiting": 0.0, "tail": 0.0}
    busy = 0.0
    for by_sample in spans.values():
        ordered = sorted(by_sample.values())
        busy += sum(end - start for start, end in ordered)
        idle["startup"] += max(ordered[0][0] - dispatched_at, 0.0)
        idle["waiting"] += sum(max(b[0] - a[1], 0.0) for a, b in zip(ordered, ordered[1:]))
        idle["tail"] += max(ended_at - ordered[-1][1], 0.0)
    idle["startup"] += (n - len(spans)) * wall  # workers that never got a task
    return {"workers": n, "tasks": sum(map(len, spans.values())), "busy_s": round(busy, 2),
            "busy_fraction": round(busy / (n * wall), 3) if n else None, "busy_workers": round(busy / wall, 2),
            "idle_s": {k: round(v, 2) for k, v in idle.items()}}


def per_class(rows: list[LogRow], objects: list) -> dict:
    """``objects_per_category`` (nuScenes category -> objects inserted) and ``classes_not_placed`` (detection
    class -> the most common reasons an object of it found no place, with counts)."""
    per_category = Counter(o.category for o in objects)
    not_placed: dict[str, Counter] = {}
    for r in rows:
        for name, why in (r.class_reasons or {}).items():
            not_placed.setdefault(name, Counter())[reason_key("", why)] += 1
    return {"objects_per_category": dict(sorted(per_category.items())),
            "classes_not_placed": {k: dict(v.most_common(3)) for k, v in sorted(not_placed.items())}}


def _stage_order(stage: str) -> tuple[int, str]:
    return (MAIN_STAGES.index(stage) if stage in MAIN_STAGES else len(MAIN_STAGES) - 1, stage)


def format_summary(summary: dict) -> str:
    """The one-screen text the CLI prints at the end."""
    run = summary.get("this_run", {})
    counts = summary.get("counts", {})
    lines = [
        f"{summary['images']} images of {summary['samples']} samples, {summary['objects_inserted']} objects inserted",
        "  status:   " + " | ".join(f"{k} {counts.get(k, 0)}" for k in ("ok", "skipped", "failed")),
    ]
    if run:
        rate = run.get("images_per_s")
        lines.append(f"  this run: {run.get('images', 0)} images ({run.get('samples', 0)} samples) in "
                     f"{run.get('wall_s', 0):.1f} s" + (f" = {rate:.2f} img/s" if rate else "")
                     + f" on {run.get('executor', '?')} ({_busy(run)})"
                     + f"; {run.get('resumed_samples', 0)} samples already done")
    for i, (key, n) in enumerate(list(summary.get("reasons", {}).items())[:6]):
        lines.append(("  reasons:  " if i == 0 else "            ") + f"{n:4d}  {key}")
    per_category = summary.get("objects_per_category") or {}
    if len(per_category) > 1 or summary.get("classes_not_placed"):
        lines.append("  per class: " + ", ".join(f"{k} {n}" for k, n in per_category.items()))
        for name, reasons in summary.get("classes_not_placed", {}).items():
            key, n = next(iter(reasons.items()))
            lines.append(f"  not placed: {name} in {sum(reasons.values())} view(s), e.g. {key}")
    if summary.get("lighting"):
        lines.append("  lighting: " + ", ".join(f"{k} ({n})" for k, n in summary["lighting"].items()))
    stages = summary.get("stage_seconds", {})
    shown = [s for s in MAIN_STAGES if s in stages]
    if shown:
        lines.append("  seconds per ok image:  " + "  ".join(f"{s:>9}" for s in shown))
        for p in PERCENTILES:
            lines.append(f"                   p{p:<2}  " + "  ".join(f"{stages[s][f'p{p}']:9.3f}" for s in shown))
    tracks = summary.get("tracks")
    if tracks:
        lines.append(f"  tracks:   {tracks['tracks']} in {tracks['scenes']} scene(s) ({tracks['parked']} parked, "
                     f"{tracks['moving']} moving), median {tracks['keyframes_per_track_median']} keyframes each"
                     + (f"; {tracks['scenes_failed']} scene(s) failed" if tracks["scenes_failed"] else ""))
    sweeps = summary.get("sweeps")
    if sweeps:
        lines.append(f"  sweeps:   {sweeps['files']} sweep files rendered"
                     + (f"; not rendered for {sweeps['samples_not_rendered']} sample(s): {sweeps['reason']}"
                        if sweeps["samples_not_rendered"] else ""))
    workers = summary.get("workers", {})
    if workers:
        rss = [w["peak_rss_mb"] for w in workers.values()]
        lines.append(f"  workers:  {len(workers)}, peak RSS {min(rss):.0f}-{max(rss):.0f} MiB")
    return "\n".join(lines)


def _busy(run: dict) -> str:
    """How busy the workers were: by their tasks' wall time (and CPU, which other jobs on the cores lower)."""
    timeline = run.get("timeline") or {}
    if timeline.get("busy_fraction") is None:
        return f"{run.get('busy_workers')} busy"
    idle = timeline["idle_s"]
    return (f"{timeline['busy_workers']} of {timeline['workers']} busy, {run.get('busy_workers')} by CPU; idle s: "
            + ", ".join(f"{k} {v:.1f}" for k, v in idle.items()))


def contact_sheet(out_dir: Path, rows: list[LogRow], n: int, seed: int, thumb_width: int = 400) -> Path | None:
    """``out_dir/contact_sheet.png``: up to ``n`` random augmented images (seeded), inserted objects boxed in green."""
    ok = sorted((r for r in rows if r.status == "ok" and r.image), key=lambda r: r.key)
    if n <= 0 or not ok:
        return None
    rng = np.random.default_rng(seed)
    picks = sorted(rng.choice(len(ok), size=min(n, len(ok)), replace=False))
    thumbs = []
    for i in picks:
        row = ok[int(i)]
        image = read_image_rgb(out_dir / row.image).copy()
        labels_path = out_dir / row.files[1] if len(row.files) > 1 else None
        if labels_path is not None and labels_path.is_file():
            for obj in json.loads(labels_path.read_text()).get("objects", []):
                if obj.get("bbox_2d"):
                    x0, y0, x1, y1 = (int(round(v)) for v in obj["bbox_2d"])
                    cv2.rectangle(image, (x0, y0), (x1, y1), (0, 255, 0), max(2, image.shape[1] // 400))
        scale = thumb_width / image.shape[1]
        thumb = cv2.resize(image, (thumb_width, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        caption = f"{row.camera} {row.sample_token[:8]}"
        (tw, th), _ = cv2.getTextSize(caption, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        thumb[: th + 12, : tw + 12] //= 3
        cv2.putText(thumb, caption, (6, th + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        thumbs.append(thumb)
    h = max(t.shape[0] for t in thumbs)
    cols = min(4, len(thumbs))
    n_rows = -(-len(thumbs) // cols)
    sheet = np.zeros((n_rows * h, cols * thumb_width, 3), np.uint8)
    for k, t in enumerate(thumbs):
        r, c = divmod(k, cols)
        sheet[r * h: r * h + t.shape[0], c * thumb_width: (c + 1) * thumb_width] = t
    path = out_dir / "contact_sheet.png"
    write_image_rgb(path, sheet)
    return path
