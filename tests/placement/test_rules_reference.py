"""points_in_boxes and the footprint point pairs (sorted-x strips, a tree over the nearby points only) against
reference copies of the previous implementations (a KD-tree over the whole sweep, 03 Dec 2026): the same results
on the bundled samples, on real scene-0916 sweeps (../shared/data/nuscenes-seq, skipped when absent) and on
random footprints."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import SHARED_DATA
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.placement.rules import _points_near_footprints, points_in_box, points_in_boxes

SEQ = SHARED_DATA / "nuscenes-seq"


# ---- reference: the previous implementations, unchanged but for the names ----
def reference_points_in_boxes(points_global, boxes, margin_m=0.0):
    points_global = np.asarray(points_global, dtype=np.float64)
    inside = np.zeros(len(points_global), dtype=bool)
    if len(boxes) == 0 or len(points_global) == 0:
        return inside
    centers = np.stack([b.center for b in boxes])
    half = np.stack([np.asarray(b.wlh)[[1, 0, 2]] / 2 + margin_m for b in boxes])
    lists = cKDTree(points_global[:, :2]).query_ball_point(centers[:, :2], np.linalg.norm(half, axis=1))
    for b, idx in zip(boxes, lists):
        if idx:
            idx = np.asarray(idx)
            inside[idx[points_in_box(points_global[idx], b, margin_m)]] = True
    return inside


def reference_points_near_footprints(corners_xy, points_xy, margin_m):
    N = len(corners_xy)
    if N == 0 or len(points_xy) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    center = corners_xy.mean(axis=1)
    ex = corners_xy[:, 0] - corners_xy[:, 3]
    ey = corners_xy[:, 0] - corners_xy[:, 1]
    half_l = np.linalg.norm(ex, axis=1) / 2
    half_w = np.linalg.norm(ey, axis=1) / 2
    ux = ex / np.maximum(2 * half_l, 1e-9)[:, None]
    uy = ey / np.maximum(2 * half_w, 1e-9)[:, None]
    radius = float(np.max(np.hypot(half_l, half_w))) + margin_m
    lists = cKDTree(points_xy).query_ball_point(center, radius)
    lens = np.fromiter((len(x) for x in lists), dtype=np.int64, count=N)
    cand = np.repeat(np.arange(N), lens)
    pt = np.fromiter((i for x in lists for i in x), dtype=np.int64, count=int(lens.sum()))
    d = points_xy[pt] - center[cand]
    keep = (np.abs(np.einsum("kd,kd->k", d, ux[cand])) <= half_l[cand] + margin_m) & (
        np.abs(np.einsum("kd,kd->k", d, uy[cand])) <= half_w[cand] + margin_m
    )
    return cand[keep], pt[keep]


# ---- comparisons ----
def _samples():
    bundled = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    out = [bundled.sample(bundled.sample_tokens(n)[0]) for n in ("sample-sunny", "sample-overcast", "sample-lowsun")]
    if (SEQ / "v1.0-mini" / "sample.json").is_file():
        real = NuScenesReader(SEQ, "v1.0-mini")
        out += [real.sample(t) for t in real.sample_tokens()[::10]]
    return out


def _footprints(rng, centre_xy, n, spread_m):
    xy = centre_xy + rng.uniform(-spread_m, spread_m, (n, 2))
    yaw = rng.uniform(-np.pi, np.pi, n)
    l, w = rng.uniform(0.3, 5.0, n), rng.uniform(0.3, 2.2, n)
    local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], float)[None] * np.stack([l, w], 1)[:, None] / 2
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return xy[:, None] + np.stack([c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]], -1)


def _same_pairs(a, b):
    return sorted(zip(a[0].tolist(), a[1].tolist())) == sorted(zip(b[0].tolist(), b[1].tolist()))


def test_points_in_boxes_same_as_reference_on_real_sweeps():
    samples = _samples()
    assert len(samples) >= 3
    for sample in samples:
        pts, boxes = sample.lidar.points_global, list(sample.boxes)
        for margin in (0.0, 0.1, 0.5):
            np.testing.assert_array_equal(points_in_boxes(pts, boxes, margin),
                                          reference_points_in_boxes(pts, boxes, margin))


def test_points_near_footprints_same_as_reference():
    rng = np.random.default_rng(7)
    for sample in _samples():
        xy = sample.lidar.points_global[:, :2]
        centre = xy.mean(axis=0)
        for n, spread, margin in ((48, 40.0, 0.5), (48, 5.0, 1.0), (1, 20.0, 0.0), (5, 200.0, 0.3)):
            fps = _footprints(rng, centre, n, spread)
            got = _points_near_footprints(fps, xy, margin)
            assert _same_pairs(got, reference_points_near_footprints(fps, xy, margin))
    # points on the grid of a footprint's edges and corners (boundaries included)
    fps = _footprints(rng, np.zeros(2), 3, 2.0)
    grid = np.stack(np.meshgrid(np.linspace(-6, 6, 241), np.linspace(-6, 6, 241)), -1).reshape(-1, 2)
    pts = np.concatenate([grid, fps.reshape(-1, 2)])
    for margin in (0.0, 0.25):
        assert _same_pairs(_points_near_footprints(fps, pts, margin), reference_points_near_footprints(fps, pts, margin))
    far = _points_near_footprints(fps, pts + 1000.0, 0.5)  # nothing near: empty, as before
    assert len(far[0]) == 0 and far[0].dtype == np.int64
