"""A batch worker gives its freed heap back between samples (RSS), instead of carrying it into the next one."""

import sys

import numpy as np
import pytest

from streetaug.augment.batch import execute, worker

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc and /proc only")


def _rss_mb() -> float:
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def test_release_free_heap_returns_freed_arrays_to_the_os():
    if not execute.tune_malloc():
        pytest.skip("not glibc")
    arrays = [np.ones(2**20 // 2) for _ in range(60)]  # 60 x 4 MB, under the 64 MB mmap threshold: heap
    keep = np.ones(100)  # allocated after them: the heap's top stays in use, no automatic trim
    before = _rss_mb()
    del arrays
    freed = _rss_mb()
    assert freed > before - 100  # tuned malloc keeps them resident (trim threshold 256 MB)
    assert execute.release_free_heap()
    assert _rss_mb() < freed - 150
    assert keep.sum() == 100


def test_process_sample_releases_the_heap(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(worker, "release_free_heap", lambda: calls.append(1) or True)
    monkeypatch.setattr(worker, "dataset_reader", lambda config: (_ for _ in ()).throw(OSError("no dataset")))
    rows = worker.process_sample(None, str(tmp_path), "tok", ["CAM_FRONT"], {})
    assert [r.status for r in rows] == ["failed"] and calls == [1]
