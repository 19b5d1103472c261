"""Scene depth for occlusion and shadows: LiDAR densification and the ground-plane prior.

Depth maps are (H, W) float32 camera-frame z in metres, ``inf`` where unknown (sky).

Densification is classical morphological depth completion in the spirit of IP-Basic (Ku et al.,
CRV 2018): project the points with a z-buffer, then grow them with dilations of the *inverse*
depth (so the nearer surface wins at occlusion boundaries), a closing, and larger fills for the
remaining holes, never above the highest LiDAR return of a column (that is sky or unknown).
With a ground plane, the returns near it are the ground: between its scan lines (far rings are tens of
pixels apart) its inverse depth is interpolated down each column instead of grown from the nearer line,
which would hide the lower part of anything standing on the road farther away. Where there is no LiDAR
below the horizon the ground plane fills in.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import project_points
from .errors import check_shape

MIN_DEPTH_M = 0.5


def _diamond(size: int) -> np.ndarray:
    r = size // 2
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    return (np.abs(x) + np.abs(y) <= r).astype(np.uint8)


def sparse_depth(points_cam: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Z-buffered projection of camera-frame points (N, 3) -> (H, W) float32 depth, 0 where empty."""
    points_cam = np.asarray(points_cam, dtype=np.float64)
    check_shape(points_cam, ("N", 3), "points_cam")
    pts = points_cam[np.isfinite(points_cam).all(axis=1) & (points_cam[:, 2] > MIN_DEPTH_M)]
    depth = np.zeros((height, width), np.float32)
    if len(pts) == 0:
        return depth
    uv, z = project_points(K, pts)
    u = np.round(uv[:, 0]).astype(np.int64)
    v = np.round(uv[:, 1]).astype(np.int64)
    ok = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v, z = u[ok], v[ok], z[ok]
    order = np.argsort(-z, kind="stable")  # far first, so the nearest point is written last
    depth[v[order], u[order]] = z[order]
    return depth


def ground_plane_depth(K: np.ndarray, width: int, height: int, ground_normal_cam: np.ndarray,
                       ground_offset_m: float) -> np.ndarray:
    """Depth (H, W) float32 of the plane ``n . p + d = 0`` (n = ``ground_normal_cam``, d = ``ground_offset_m``).

    inf where the pixel ray does not hit the plane in front of the camera (above the horizon).
    Example: a camera 1.5 m above flat ground has n = (0, -1, 0), d = 1.5.
    """
    check_shape(K, (3, 3), "K")
    n = np.asarray(ground_normal_cam, dtype=np.float64)
    check_shape(n, (3,), "ground_normal_cam")
    Kinv = np.linalg.inv(K)
    u = np.arange(width, dtype=np.float64)
    v = np.arange(height, dtype=np.float64)
    # ray(u, v) = Kinv [u, v, 1] has z = 1, so the plane's t along it is the depth.
    a = Kinv.T @ n  # n . (Kinv [u, v, 1]) = a0 u + a1 v + a2
    denom = a[0] * u[None, :] + a[1] * v[:, None] + a[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -float(ground_offset_m) / denom
    return np.where(np.isfinite(z) & (z > 0), z, np.inf).astype(np.float32)


GROUND_BAND_M = 0.25  # with a ground plane: points below it or at most this above (+ GROUND_BAND_PER_M x depth)
#                        are ground
GROUND_BAND_PER_M = 0.015  # ... the band grows with depth (slopes, pitch)
GROUND_MAX_GAP_PX = 80  # ground samples of one column farther apart than this are not joined (an object between)
GROUND_PAST_OBSTACLE_PX = 31  # window in which a nearer obstacle hides a ground sample
GROUND_ROW_CLOSE_PX = 15  # horizontal closing of the ground (points along a scan line are ~4 px apart at 1600 px)


def _ground_inverse_depth(ground: np.ndarray, obstacle: np.ndarray) -> np.ndarray:
    """(H, W) float32 inverse depth of the ground: the sparse ground depth ``ground`` (0 = empty) joined down
    each column by linear interpolation of 1/z between consecutive samples at most ``GROUND_MAX_GAP_PX`` apart
    (1/z of a plane is affine in the pixel row) with no obstacle between them, after a 1 x 5 dilation that
    fills the columns between points. ``obstacle``: (H, W) float32 inverse depth of everything else (0 = none);
    a ground sample farther than an obstacle within ``GROUND_PAST_OBSTACLE_PX`` / 2 pixels is dropped (the
    LiDAR, above the camera, sees road over a car that projects inside the car's image)."""
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


def densify_lidar_depth(points_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                        ground_fill: tuple[np.ndarray, float] | None = None, max_depth_m: float = 200.0) -> np.ndarray:
    """Dense depth (H, W) float32 metres from LiDAR points in the camera frame, inf where unknown (sky).

    Args:
        points_cam: (N, 3) points, camera frame, metres.
        K: (3, 3) intrinsics; width, height: image size.
        ground_fill: optional ``(ground_normal_cam (3,), ground_offset_m)`` plane used where LiDAR
            leaves holes below the horizon (see :func:`ground_plane_depth`).
        max_depth_m: points farther than this are dropped.
    """
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
    ground = (_ground_inverse_depth(sparse_depth(pts[is_ground], K, width, height), inv) if is_ground.any()
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
