"""placement.rules.box_transform / box_corners: the Box's own transform and corners, computed once per box pose."""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.core import yaw_to_quat
from streetaug.datasets.sample import Box
from streetaug.placement.rules import box_corners, box_footprints, box_transform


def _boxes():
    rng = np.random.default_rng(0)
    out = []
    for _ in range(50):
        q = rng.normal(size=4) if rng.random() < 0.3 else yaw_to_quat(rng.uniform(-np.pi, np.pi))
        out.append(Box(rng.uniform(-1e3, 1e3, 3), rng.uniform(0.3, 12, 3), np.asarray(q, float), "vehicle.car"))
    return out


def test_box_transform_and_corners_equal_the_box_methods_exactly():
    for b in _boxes():
        assert np.array_equal(box_transform(b), b.T_global_from_box)
        assert np.array_equal(box_corners(b), b.corners())
        assert box_transform(b) is box_transform(b)  # computed once
    boxes = _boxes()
    assert np.array_equal(box_footprints(boxes), np.stack([b.corners()[[0, 1, 5, 4], :2] for b in boxes]))


def test_cached_transform_is_read_only_and_keyed_by_pose():
    b = _boxes()[0]
    with pytest.raises(ValueError):
        box_transform(b)[0, 3] = 1.0
    moved = Box(b.center + [1.0, 0.0, 0.0], b.wlh, b.rotation, b.category)
    assert box_transform(moved)[0, 3] == pytest.approx(b.center[0] + 1.0)
