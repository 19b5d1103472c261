"""The shadow's coarse-to-fine sky grid interpolates between its nodes in blocks of grid rows: the same
values as over the whole grid at once, without its (hl, wl, 3) float64 temporaries (~69 MB for a
whole-frame box)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from streetaug.augment.render import shadow
from streetaug.augment.render.shadow import _coarse_to_fine_cells


def _field(hl: int, wl: int) -> np.ndarray:
    """(hl * wl, 3) a smooth deficit with a sharp step (some node squares refine, most interpolate)."""
    y, x = np.mgrid[0:hl, 0:wl].astype(np.float64)
    base = 0.3 * np.exp(-((x - wl / 3) ** 2 + (y - hl / 2) ** 2) / (0.1 * wl * wl)) + 0.2 * (x > 0.7 * wl)
    return np.stack([base, 0.8 * base, 0.5 * base], axis=-1).reshape(-1, 3)


def _run(hl: int, wl: int, valid: np.ndarray):
    truth = _field(hl, wl)
    D0, C = np.zeros((hl * wl, 3)), np.zeros((hl * wl, 3))
    evaluated: list[np.ndarray] = []

    def evaluate(cells):
        evaluated.append(np.asarray(cells).copy())
        D0[cells], C[cells] = truth[cells], 0.5 * truth[cells]

    stats: dict = {}
    _coarse_to_fine_cells(hl, wl, valid, evaluate, D0, C, np.ones(3), stats)
    return D0, C, evaluated, stats


@pytest.mark.parametrize("grid", [(37, 53), (64, 9)])
def test_blocked_interpolation_is_the_whole_grid_one(grid, monkeypatch):
    hl, wl = grid
    valid = np.ones(hl * wl, bool)
    valid[: wl // 2] = False  # a corner without ground points
    whole = _run(hl, wl, valid)
    monkeypatch.setattr(shadow, "SKY_INTERP_CHUNK_CELLS", 2 * wl + 3)  # blocks of two rows, not on a node row
    blocked = _run(hl, wl, valid)
    assert whole[3]["sky_cells_evaluated"] < hl * wl  # some cells were interpolated
    assert np.array_equal(whole[0], blocked[0]) and np.array_equal(whole[1], blocked[1])
    assert all(np.array_equal(a, b) for a, b in zip(whole[2], blocked[2]))
    assert not whole[0][~valid].any()


def test_interpolation_does_not_allocate_grid_sized_temporaries():
    hl, wl = 450, 800  # a whole 1600 x 900 frame at shadow_factor 2
    valid = np.ones(hl * wl, bool)
    D0, C = np.zeros((hl * wl, 3)), np.zeros((hl * wl, 3))
    tracemalloc.start()
    try:
        _coarse_to_fine_cells(hl, wl, valid, lambda cells: None, D0, C, np.ones(3), {})
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 2.5 * D0.nbytes  # one grid-sized float64 array (8.6 MB) was ~8 of them at once
