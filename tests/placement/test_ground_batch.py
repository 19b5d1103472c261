"""LocalGroundFitter.fit_many: the planes of fit() for many points at once (every branch: fit, widened radius,
scan line, tilt, canopy, ego fallback, lidarseg sets, the annotated boxes' word), and its group statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from placement_fixtures import T_GLOBAL_FROM_EGO, ego_to_global_xy, ground_grid_ego, lidar_rings_ego

from streetaug.augment.core import transform_points
from streetaug.placement.config import PlacementConfig
from streetaug.placement.ground import LocalGroundFitter, _group_median, _group_percentile

CFG = PlacementConfig()
SEQ = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "nuscenes-seq"


def _street(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A street of every case: a sloped noisy road near, sparse rings far, a canopy, a steep bank, a single scan
    line, clutter; with lidarseg-like labels (24 road, 26 sidewalk)."""
    road = ground_grid_ego(0.5, x_range=(5.0, 30.0), y_half=6.0)
    road[:, 2] = 0.02 * (road[:, 0] - 10) + rng.normal(0, 0.01, len(road))
    rings = lidar_rings_ego(n_azimuth=600)
    rings = rings[(rings[:, 0] > 30) & (np.abs(rings[:, 1]) < 10)]
    canopy = ground_grid_ego(0.5, x_range=(40.0, 48.0), y_half=3.0)
    canopy[:, 2] = 4.5
    bank = ground_grid_ego(0.3, x_range=(12.0, 20.0), y_half=3.0) + [0, 10.0, 0]
    bank[:, 2] = 0.5 * (bank[:, 1] - 7.0)  # 27 deg: too steep
    line = np.c_[np.linspace(52, 60, 40), np.full(40, 14.0), np.full(40, 0.3)]  # one scan line
    clutter = np.c_[rng.uniform(8, 25, (300, 2)) * [1, 0.3], rng.uniform(0.5, 1.8, 300)]
    pts = np.concatenate([road, rings, canopy, bank, line, clutter])
    labels = np.where(np.abs(pts[:, 1]) <= 5.0, 24, 26)
    return transform_points(T_GLOBAL_FROM_EGO, pts), labels


def _assert_same_planes(fitter: LocalGroundFitter, xy: np.ndarray, check_by_boxes: bool = True) -> list:
    loop = [fitter.fit(p, check_by_boxes) for p in xy]
    many = fitter.fit_many(xy, check_by_boxes)
    assert len(many) == len(loop)
    for a, b in zip(loop, many):
        assert (a.source, a.n_points) == (b.source, b.n_points)
        np.testing.assert_allclose(b.point_global, a.point_global, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.normal_global, a.normal_global, rtol=0, atol=1e-9)
    return loop


@pytest.mark.parametrize("labelled", [False, True])
@pytest.mark.parametrize("with_boxes", [False, True])
def test_fit_many_equals_fit_on_every_branch(labelled, with_boxes):
    rng = np.random.default_rng(3)
    pts, labels = _street(rng)
    bottoms = transform_points(T_GLOBAL_FROM_EGO, np.array([[44.0, 6.0, 0.1], [46.0, -6.0, 0.12], [15.0, 4.0, 0.6]]))
    fitter = LocalGroundFitter(pts, T_GLOBAL_FROM_EGO, labels if labelled else None, CFG,
                               bottoms if with_boxes else None)
    xy = ego_to_global_xy(np.c_[rng.uniform(0, 75, 300), rng.uniform(-16, 16, 300)])
    planes = _assert_same_planes(fitter, xy)
    sources = {p.source for p in planes}
    assert "ego-plane" in sources and ({"lidarseg"} if labelled else {"lidar-plane"}) <= sources
    if with_boxes:
        assert "boxes" in sources
    _assert_same_planes(fitter, xy, check_by_boxes=False)


def test_fit_many_without_points_and_empty_query():
    fitter = LocalGroundFitter(None, T_GLOBAL_FROM_EGO, None, CFG)
    xy = ego_to_global_xy([[20.0, 0.0], [30.0, 2.0]])
    assert [p.source for p in _assert_same_planes(fitter, xy)] == ["ego-plane"] * 2
    assert fitter.fit_many(np.zeros((0, 2))) == []


def test_group_statistics_equal_numpy_exactly():
    rng = np.random.default_rng(0)
    sizes = rng.integers(1, 60, 200)
    seg = np.repeat(np.arange(len(sizes)), sizes)
    values = rng.normal(0, 1, len(seg)) * 10 ** rng.uniform(-3, 3, len(seg))
    values[::7] = np.round(values[::7], 1)  # ties
    order = rng.permutation(len(seg))  # groups need not be contiguous
    seg, values = seg[order], values[order]
    for q in (5.0, 25.0, 50.0, 97.5):
        want = [np.percentile(values[seg == g], q) for g in range(len(sizes))]
        assert _group_percentile(values, seg, len(sizes), q).tolist() == want
    assert _group_median(values, seg, len(sizes)).tolist() == [np.median(values[seg == g]) for g in range(len(sizes))]
    assert np.isnan(_group_percentile(values, seg, len(sizes) + 1, 5.0)[-1])  # an empty group


@pytest.mark.skipif(not SEQ.is_dir(), reason="../shared/data/nuscenes-seq not present")
def test_fit_many_equals_fit_on_a_real_sweep():
    from streetaug.datasets.nuscenes import NuScenesReader
    from streetaug.placement.drivable import drivable_area_for_sample
    from streetaug.placement.scene import PlacementScene

    reader = NuScenesReader(SEQ, "v1.0-mini")
    sample = reader.sample(reader.sample_tokens()[20])
    view = sample.cameras["CAM_FRONT"]
    area, _ = drivable_area_for_sample(sample, view, CFG)
    scene = PlacementScene.of(sample, view, CFG, area, np.full((view.height, view.width), np.inf, np.float32))
    rng = np.random.default_rng(1)
    xy = view.T_global_from_cam[:2, 3] + rng.uniform(-40, 40, (200, 2))
    planes = _assert_same_planes(scene.ground, xy)
    assert len({p.source for p in planes}) >= 2
