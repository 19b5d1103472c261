"""HeightMap.blocked marches blocks of points: the same answer as one march over all points, bounded memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from streetaug.augment.lighting import levels
from streetaug.augment.lighting.levels import HeightMap


def _street_map(seed: int = 0) -> HeightMap:
    """Random blocks of buildings (up to 20 m) on a 1 m grid of 300 m."""
    rng = np.random.default_rng(seed)
    h = np.zeros((300, 300), np.float32)
    for _ in range(40):
        i, j = rng.integers(0, 290, 2)
        h[i:i + rng.integers(2, 10), j:j + rng.integers(2, 10)] = rng.uniform(2, 20)
    return HeightMap(h, 1.0, 150.0)


def _dirs(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) * 0.5
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("block_elements", [1, 7_000, 123_457])
def test_blocks_give_the_one_march_answer(monkeypatch, block_elements):
    hmap = _street_map()
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-60, 60, (37, 2)), rng.uniform(0.0, 3.0, 37)])
    dirs = _dirs(11)
    lo, hi = np.array([-40.0, -40.0]), np.array([40.0, 40.0])
    monkeypatch.setattr(levels, "BLOCKED_MARCH_ELEMENTS", 10 ** 12)
    whole, whole_box = hmap.blocked(pts, dirs), hmap.blocked(pts, dirs, lo, hi)
    monkeypatch.setattr(levels, "BLOCKED_MARCH_ELEMENTS", block_elements)
    assert np.array_equal(hmap.blocked(pts, dirs), whole)
    assert np.array_equal(hmap.blocked(pts, dirs, lo, hi), whole_box)
    assert whole.any() and not whole.all()  # the scene has both: the comparison can tell
    assert (whole_box <= whole).all() and (whole_box != whole).any()


def _peak_mb(fn) -> float:
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return peak


def test_march_memory_does_not_grow_with_the_points(monkeypatch):
    hmap = _street_map()
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-30, 30, (400, 2)), np.full(400, 0.5)])
    dirs = _dirs(49)
    monkeypatch.setattr(levels, "BLOCKED_MARCH_ELEMENTS", 10 ** 12)
    one_march_mb = _peak_mb(lambda: hmap.blocked(pts[:100], dirs))  # a quarter of the points in one march
    monkeypatch.setattr(levels, "BLOCKED_MARCH_ELEMENTS", 500_000)  # ~17 points a block
    blocked_mb = _peak_mb(lambda: hmap.blocked(pts, dirs))
    assert blocked_mb < 0.5 * one_march_mb, (blocked_mb, one_march_mb)
