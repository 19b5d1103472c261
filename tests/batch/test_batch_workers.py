"""Batch workers (issue #19): what a worker keeps between samples, and the workers' timeline in the summary."""

from __future__ import annotations

import gc
import os
import time

from streetaug.augment.assets.asset import Asset
from streetaug.augment.batch import BatchConfig, LogRow, RunOptions, run_batch
from streetaug.augment.batch.execute import run_processes
from streetaug.augment.batch.report import worker_timeline
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot


def _live_assets() -> dict[int, Asset]:
    gc.collect()
    return {id(o): o for o in gc.get_objects() if isinstance(o, Asset)}


def test_a_worker_keeps_no_procedural_object_after_its_sample(tmp_path):
    """Objects per sample are drawn afresh for every sample: a worker holds none of them (nor their BVHs, ~3.5 MB
    each) once the sample is written; before, each worker kept up to 64 cars (~220 MB) that later samples
    almost never drew again."""
    before = set(_live_assets())
    config = BatchConfig(dataroot=str(bundled_dataroot().resolve()), version=BUNDLED_VERSION,
                         cameras=("CAM_FRONT", "CAM_BACK"), quality="draft", limit=2)
    summary = run_batch(config, tmp_path, RunOptions(workers=1, progress=False, contact_sheet=0))  # in this process
    assert summary["objects_inserted"] >= 2
    kept = [a.name for i, a in _live_assets().items() if i not in before]
    assert kept == [], f"assets kept after the batch: {kept}"


def _row(token: str, worker: str, span: tuple[float, float]) -> LogRow:
    return LogRow(token, "CAM_FRONT", "ok", worker=worker, task_span=span)


def test_timeline_splits_idle_time():
    rows = [_row("a", "w1", (1.0, 5.0)), _row("b", "w1", (6.0, 9.0)),  # w1: 1 s start-up, 1 s waiting, 1 s tail
            _row("c", "w2", (2.0, 10.0))]  # w2: 2 s start-up
    timeline = worker_timeline(rows + [_row("a", "w1", (1.0, 5.0))], 0.0, 10.0, workers=2)  # a's 2nd camera: once
    assert timeline["busy_s"] == 15.0 and timeline["busy_fraction"] == 0.75 and timeline["tasks"] == 3
    assert timeline["idle_s"] == {"startup": 3.0, "waiting": 1.0, "tail": 1.0}


def test_timeline_counts_a_worker_that_got_no_task_as_idle():
    timeline = worker_timeline([_row("a", "w1", (0.0, 10.0))], 0.0, 10.0, workers=2)
    assert timeline["busy_fraction"] == 0.5 and timeline["idle_s"]["startup"] == 10.0


def _nap(seconds: float) -> tuple[int, float, float]:
    start = time.time()
    time.sleep(seconds)
    return os.getpid(), start, time.time()


def test_local_workers_stay_fed_with_items_of_very_different_cost():
    """Long and short items mixed: a free worker takes the next item at once (no static split, no waiting for
    the slow one), so the two finish within one long item of each other and neither waits between items."""
    costs = [1.2] + [0.05] * 16 + [1.2, 0.05, 0.05, 0.6]
    spans = list(run_processes(_nap, [(c,) for c in costs], workers=2))
    assert len(spans) == len(costs)
    by_worker: dict[int, list[tuple[float, float]]] = {}
    for pid, start, end in spans:
        by_worker.setdefault(pid, []).append((start, end))
    assert len(by_worker) == 2
    for items in by_worker.values():
        items.sort()
        gaps = [b[0] - a[1] for a, b in zip(items, items[1:])]
        assert max(gaps, default=0.0) < 0.5, f"a worker waited {max(gaps):.2f} s for its next item"
    last = sorted(max(end for _, end in items) for items in by_worker.values())
    assert last[1] - last[0] < 1.2 + 0.5
    busy = sum(end - start for _, start, end in spans)
    assert busy > 0.95 * sum(costs)
