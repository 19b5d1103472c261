"""densify_lidar_depth (vectorised, rows above the returns skipped) against a reference copy of the previous
implementation (a per-column Python loop for the ground joins, 03 Dec 2026): bit-identical depth maps on the bundled
samples, on real scene-0916 views (../shared/data/nuscenes-seq, skipped when absent) and on synthetic edge cases.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import SHARED_DATA
from streetaug.augment.core import intrinsics_from_fov
from streetaug.augment.core.errors import check_shape
from streetaug.augment.core.depth import (GROUND_BAND_M, GROUND_BAND_PER_M, GROUND_MAX_GAP_PX, GROUND_PAST_OBSTACLE_PX,
                                          GROUND_ROW_CLOSE_PX, _diamond, densify_lidar_depth, ground_plane_depth,
                                          sparse_depth)
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

SEQ = SHARED_DATA / "nuscenes-seq"


# ---- reference: the previous implementation, unchanged but for the names and docstrings ----
def _ref_ground_inverse_depth(ground: np.ndarray, obstacle: np.ndarray) -> np.ndarray:
    inv = np.where(ground > 0, 1.0 / np.maximum(ground, 1e-6), 0.0).astype(np.float32)
    inv = cv2.morphologyEx(cv2.dilate(inv, np.ones((1, 5), np.uint8)), cv2.MORPH_CLOSE,
                           np.ones((1, GROUND_ROW_CLOSE_PX), np.uint8))  # each scan line continuous along its row
    # ground the LiDAR (above the camera) saw past a nearer obstacle that is beside it in the image: hidden
    inv[inv < cv2.dilate(obstacle, np.ones((GROUND_PAST_OBSTACLE_PX, GROUND_PAST_OBSTACLE_PX), np.uint8))] = 0.0
    out = inv.copy()
    H, W = inv.shape
    rows = np.arange(H, dtype=np.float64)
    blocked = np.cumsum(obstacle > 0, axis=0)  # obstacle pixels at or above each row, per column
    for col in np.flatnonzero((inv > 0).sum(axis=0) >= 2):
        r = np.flatnonzero(inv[:, col] > 0)
        gap = np.diff(r)
        join = (gap > 1) & (gap <= GROUND_MAX_GAP_PX) & (blocked[r[1:] - 1, col] == blocked[r[:-1], col])
        if not join.any():
            continue
        lo, hi = r[:-1][join], r[1:][join]
        starts = np.zeros(H + 1, dtype=np.int64)
        np.add.at(starts, lo + 1, 1)
        np.add.at(starts, hi, -1)
        span = np.cumsum(starts[:H]) > 0
        out[span, col] = np.interp(rows[span], r, inv[r, col]).astype(np.float32)
    # a column whose join was refused between joined neighbours would stand out (streaks in a shadow): close it
    return cv2.morphologyEx(out, cv2.MORPH_CLOSE, np.ones((1, GROUND_ROW_CLOSE_PX), np.uint8))


def reference_densify_lidar_depth(points_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                        ground_fill: tuple[np.ndarray, float] | None = None, max_depth_m: float = 200.0) -> np.ndarray:
    pts = np.asarray(points_cam, dtype=np.float64)
    check_shape(pts, ("N", 3), "points_cam")
    pts = pts[pts[:, 2] < max_depth_m]
    sparse = sparse_depth(pts, K, width, height)
    is_ground = np.zeros(len(pts), dtype=bool)
    if ground_fill is not None and len(pts):
        normal, offset = ground_fill
        height_m = pts @ np.asarray(normal, dtype=np.float64) + float(offset)
        # below the ego's plane is the road too (it falls away downhill); above it, a band that grows with depth
        is_ground = height_m < GROUND_BAND_M + GROUND_BAND_PER_M * pts[:, 2]
    obstacles = sparse_depth(pts[~is_ground], K, width, height) if is_ground.any() else sparse
    inv = np.where(obstacles > 0, 1.0 / np.maximum(obstacles, 1e-6), 0.0).astype(np.float32)
    valid_rows = np.flatnonzero(sparse.any(axis=1))
    # 1. Small diamond dilation: nearest point wins (max of inverse depth).
    inv = cv2.dilate(inv, _diamond(5))
    # 2. Closing to join neighbouring scan lines.
    inv = cv2.morphologyEx(inv, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    # 2b. The ground between scan lines: its inverse depth interpolated down each column (exact for a plane),
    #     not the nearer line grown upwards (which would hide the bottom of anything standing farther away).
    ground = (_ref_ground_inverse_depth(sparse_depth(pts[is_ground], K, width, height), inv) if is_ground.any()
              else None)
    # 3. Fill remaining small holes with a wider dilation, then large holes with a wider one (the obstacles
    #    only, into what the ground does not cover: the ground is never grown, the plane fills its holes).
    for size in (7, 15, 31):
        empty = inv <= 0 if ground is None else (inv <= 0) & (ground <= 0)
        if not empty.any():
            break
        grown = cv2.dilate(inv, np.ones((size, size), np.uint8))
        inv = np.where(empty, grown, inv)
    if ground is not None:
        inv = np.maximum(inv, ground)  # the nearer surface wins
    # 4. Light median to remove dilation blockiness, keeping empties empty.
    med = cv2.medianBlur(inv, 5)
    inv = np.where((inv > 0) & (med > 0), med, inv)
    depth = np.where(inv > 0, 1.0 / np.maximum(inv, 1e-9), np.inf).astype(np.float32)
    # 5. Nothing above the highest LiDAR return of each column (sky / beyond range).
    has = sparse > 0
    if has.any():
        top = np.where(has.any(axis=0), has.argmax(axis=0), height)  # first row with a return
        top = cv2.erode(top.astype(np.float32)[None, :], np.ones((1, 31), np.uint8))[0]  # spread over neighbours
        rows = np.arange(height)[:, None]
        depth[rows < top[None, :]] = np.inf
    elif len(valid_rows) == 0:
        depth[:] = np.inf
    if ground_fill is not None:
        normal, offset = ground_fill
        plane = ground_plane_depth(K, width, height, normal, offset)
        depth = np.where(np.isfinite(depth), depth, plane)
    return depth


# ---- comparisons ----
def _check_same(points_cam, K, width, height, ground_fill):
    new = densify_lidar_depth(points_cam, K, width, height, ground_fill=ground_fill)
    ref = reference_densify_lidar_depth(points_cam, K, width, height, ground_fill=ground_fill)
    assert new.dtype == ref.dtype and new.shape == ref.shape
    np.testing.assert_array_equal(new, ref)  # bit-identical, inf where inf


def _views(reader, tokens, cams):
    for token in tokens:
        sample = reader.sample(token)
        for cam in cams:
            view = sample.cameras[cam]
            yield sample.lidar.points_in(view.T_cam_from_global), view


@pytest.mark.parametrize("scene", ["sample-sunny", "sample-overcast", "sample-lowsun"])
def test_same_depth_as_reference_on_the_bundled_samples(scene):
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    for pts, view in _views(reader, reader.sample_tokens(scene)[:1], ["CAM_FRONT"]):
        _check_same(pts, view.K, view.width, view.height, view.ego_ground_plane_cam)
        _check_same(pts, view.K, view.width, view.height, None)


@pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file(), reason=f"real nuScenes dev scene not at {SEQ}")
@pytest.mark.parametrize("keyframe, cam", [(4, "CAM_FRONT"), (16, "CAM_FRONT"), (8, "CAM_BACK"),
                                           (20, "CAM_FRONT_LEFT"), (36, "CAM_BACK_RIGHT")])
def test_same_depth_as_reference_on_real_views(keyframe, cam):
    reader = NuScenesReader(SEQ, "v1.0-mini")
    for pts, view in _views(reader, [reader.sample_tokens()[keyframe]], [cam]):
        _check_same(pts, view.K, view.width, view.height, view.ego_ground_plane_cam)


def test_same_depth_as_reference_on_edge_cases():
    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 70.0)
    plane = (np.array([0.0, -1.0, 0.0]), 1.6)
    rng = np.random.default_rng(3)
    cloud = rng.uniform([-20, -6, -2], [20, 1.6, 60], (4000, 3))
    cases = {
        "empty": np.zeros((0, 3)),
        "behind": np.array([[0.0, 0.0, -5.0], [1.0, 0.0, 0.2]]),
        "outside": np.array([[100.0, 0.0, 5.0]]),
        "one point": np.array([[0.0, 0.0, 10.0]]),
        "ground only": np.c_[rng.uniform(-10, 10, 3000), np.full(3000, 1.6), rng.uniform(2, 40, 3000)],
        "near the top": np.c_[rng.uniform(-5, 5, 500), np.full(500, -30.0), np.full(500, 20.0)],
        "cloud": cloud,
        "with nan": np.r_[cloud, [[np.nan, 0.0, 5.0]]],
    }
    tilted = np.array([0.3, -0.9, 0.4]) / np.linalg.norm([0.3, -0.9, 0.4])
    fills = [plane, None, (np.array([0.0, 1.0, 0.0]), 1.6), (tilted, 1.2), (-tilted, -1.2), (plane[0], 0.0),
             (np.array([0.0, 0.0, 1.0]), -30.0)]  # a ceiling, tilted both ways, through the camera, a wall ahead
    for name, pts in cases.items():
        for fill in fills:
            _check_same(pts, K, W, H, fill)
