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
    u, v, z, ok = _pixels_of(pts, K, width, height)
    return _zbuffer(u[ok], v[ok], z[ok], z[ok], width, height)


def _pixels_of(pts: np.ndarray, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, ...]:
    """Nearest pixel (u, v) (N,) int64 and depth z (N,) of finite points (N, 3) in front of the camera, and
    whether the pixel is in the image (N,) bool."""
    uv, z = project_points(K, pts) if len(pts) else (np.zeros((0, 2)), np.zeros(0))
    u = np.round(uv[:, 0]).astype(np.int64)
    v = np.round(uv[:, 1]).astype(np.int64)
    return u, v, z, (u >= 0) & (u < width) & (v >= 0) & (v < height)


def _zbuffer(u: np.ndarray, v: np.ndarray, z: np.ndarray, values: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H, W) float32 image of ``values`` (N,) of the nearest point (least ``z``) per in-image pixel (u, v), 0 where
    empty."""
    out = np.zeros((height, width), np.float32)
    order = np.argsort(-z, kind="stable")  # far first, so the nearest point is written last
    out[v[order], u[order]] = values[order]
    return out


def _plane_coefficients(K: np.ndarray, ground_normal_cam: np.ndarray) -> np.ndarray:
    """(3,) ``a`` with ``n . (Kinv [u, v, 1]) = a0 u + a1 v + a2``: the ray through pixel (u, v) has z = 1, so
    the plane ``n . p + d = 0`` lies at depth ``-d / (a0 u + a1 v + a2)`` along it."""
    return np.linalg.inv(K).T @ np.asarray(ground_normal_cam, dtype=np.float64)


def ground_plane_depth(K: np.ndarray, width: int, height: int, ground_normal_cam: np.ndarray,
                       ground_offset_m: float) -> np.ndarray:
    """Depth (H, W) float32 of the plane ``n . p + d = 0`` (n = ``ground_normal_cam``, d = ``ground_offset_m``).

    inf where the pixel ray does not hit the plane in front of the camera (above the horizon).
    Example: a camera 1.5 m above flat ground has n = (0, -1, 0), d = 1.5.
    """
    check_shape(K, (3, 3), "K")
    n = np.asarray(ground_normal_cam, dtype=np.float64)
    check_shape(n, (3,), "ground_normal_cam")
    u = np.arange(width, dtype=np.float64)
    v = np.arange(height, dtype=np.float64)
    a = _plane_coefficients(K, n)
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


def _zbuffer_inverse(u: np.ndarray, v: np.ndarray, z: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H, W) float32 ``1 / z`` of the nearest point per pixel (0 = empty) for in-image pixels (u, v) (N,) int."""
    return _zbuffer(u, v, z, 1.0 / np.maximum(z.astype(np.float32), np.float32(1e-6)), width, height)


def _ground_inverse_depth(ground: np.ndarray, obstacle: np.ndarray) -> tuple[int, np.ndarray]:
    """Inverse depth of the ground: the sparse ground inverse depth ``ground`` (H, W) float32 (0 = empty) joined
    down each column by linear interpolation of 1/z between consecutive samples at most ``GROUND_MAX_GAP_PX``
    apart (1/z of a plane is affine in the pixel row) with no obstacle between them, after a 1 x 5 dilation that
    fills the columns between points. ``obstacle``: (H, W) float32 inverse depth of everything else (0 = none);
    a ground sample farther than an obstacle within ``GROUND_PAST_OBSTACLE_PX`` / 2 pixels is dropped (the
    LiDAR, above the camera, sees road over a car that projects inside the car's image).

    Returns (g0, (h, W) float32): the rows g0 .. g0 + h - 1 that hold ground samples (0 elsewhere); h = 0 when
    there are none.
    """
    H, W = ground.shape
    sample_rows = np.flatnonzero(ground.any(axis=1))
    if len(sample_rows) == 0:
        return 0, np.zeros((0, W), np.float32)
    g0, g1 = int(sample_rows[0]), int(sample_rows[-1]) + 1  # the filters below are horizontal, the joins between samples
    inv = cv2.morphologyEx(cv2.dilate(ground[g0:g1], np.ones((1, 5), np.uint8)), cv2.MORPH_CLOSE,
                           np.ones((1, GROUND_ROW_CLOSE_PX), np.uint8))  # each scan line continuous along its row
    # ground the LiDAR (above the camera) saw past a nearer obstacle that is beside it in the image: hidden
    r = GROUND_PAST_OBSTACLE_PX // 2
    o0, o1 = max(g0 - r, 0), min(g1 + r, H)
    near = cv2.dilate(obstacle[o0:o1], np.ones((GROUND_PAST_OBSTACLE_PX, GROUND_PAST_OBSTACLE_PX), np.uint8))
    inv[inv < near[g0 - o0 : g1 - o0]] = 0.0
    # consecutive samples of a column (column-major order), close enough, with no obstacle pixel between them
    cols, rows = np.nonzero(inv.T > 0)
    pair = np.flatnonzero((cols[1:] == cols[:-1]) & (rows[1:] - rows[:-1] > 1)
                          & (rows[1:] - rows[:-1] <= GROUND_MAX_GAP_PX))
    xs, lo, hi = cols[pair], rows[pair], rows[pair + 1]
    # obstacle pixels in the rows strictly between each pair: S[r, c] of the integral image counts those in the
    # rows above r and the columns left of c, so one column's count above r is S[r, c + 1] - S[r, c]
    S = cv2.integral((obstacle[g0:g1] > 0).view(np.uint8))
    keep = (S[hi, xs + 1] - S[hi, xs]) == (S[lo + 1, xs + 1] - S[lo + 1, xs])
    xs, lo, hi = xs[keep], lo[keep], hi[keep]
    # the rows strictly between each pair, at np.interp's arithmetic (float64 slope times the offset from the
    # upper sample) so the values are the same
    f_lo = inv[lo, xs].astype(np.float64)
    slope = (inv[hi, xs].astype(np.float64) - f_lo) / (hi - lo).astype(np.float64)
    n = hi - lo - 1
    first = np.repeat(np.cumsum(n) - n, n)
    step = np.arange(first.size) - first + 1  # 1 .. n of each pair
    out = inv.copy()
    out[np.repeat(lo, n) + step, np.repeat(xs, n)] = (np.repeat(slope, n) * step + np.repeat(f_lo, n)).astype(
        np.float32)
    # a column whose join was refused between joined neighbours would stand out (streaks in a shadow): close it
    return g0, cv2.morphologyEx(out, cv2.MORPH_CLOSE, np.ones((1, GROUND_ROW_CLOSE_PX), np.uint8))


def _plane_depth_at(K: np.ndarray, ys: np.ndarray, xs: np.ndarray, ground_normal_cam: np.ndarray,
                    ground_offset_m: float) -> np.ndarray:
    """:func:`ground_plane_depth` at the pixels (ys, xs) (N,) only, (N,) float32 (same arithmetic, same values)."""
    a = _plane_coefficients(K, ground_normal_cam)
    denom = a[0] * xs.astype(np.float64) + a[1] * ys.astype(np.float64) + a[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -float(ground_offset_m) / denom
    return np.where(np.isfinite(z) & (z > 0), z, np.inf).astype(np.float32)


def _first_plane_row(K: np.ndarray, width: int, height: int, ground_normal_cam: np.ndarray,
                     ground_offset_m: float) -> int:
    """The first image row in which the plane ``n . p + d = 0`` can have a finite depth (``height``: none).

    Along a row the ray's ``n . Kinv [u, v, 1]`` is affine in u, so it has the sign a hit needs (opposite to d)
    somewhere in the row only if it has it in the first or the last column."""
    a = _plane_coefficients(K, ground_normal_cam)
    v = np.arange(height, dtype=np.float64)
    ends = a[0] * np.array([0.0, width - 1.0])[None, :] + a[1] * v[:, None] + a[2]
    rows = np.flatnonzero((np.sign(ends) == -np.sign(float(ground_offset_m))).any(axis=1))
    return int(rows[0]) if len(rows) else height


CROP_MARGIN_PX = 48  # rows kept above the highest return: > the summed vertical reach of the filters (~33 px)


def densify_lidar_depth(points_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                        ground_fill: tuple[np.ndarray, float] | None = None, max_depth_m: float = 200.0) -> np.ndarray:
    """Dense depth (H, W) float32 metres from LiDAR points in the camera frame, inf where unknown (sky).

    Args:
        points_cam: (N, 3) points, camera frame, metres.
        K: (3, 3) intrinsics; width, height: image size.
        ground_fill: optional ``(ground_normal_cam (3,), ground_offset_m)`` plane used where LiDAR
            leaves holes below the horizon (see :func:`ground_plane_depth`).
        max_depth_m: points farther than this are dropped.

    The filters run on the rows from ``CROP_MARGIN_PX`` above the highest return down: above it every row
    is unknown (inf, or the plane), and no filter reaches from there into the rows kept.
    """
    pts = np.asarray(points_cam, dtype=np.float64)
    check_shape(pts, ("N", 3), "points_cam")
    pts = pts[(pts[:, 2] < max_depth_m) & np.isfinite(pts).all(axis=1) & (pts[:, 2] > MIN_DEPTH_M)]
    depth = np.full((height, width), np.inf, np.float32)
    u, v, z, ok = _pixels_of(pts, K, width, height)
    if ok.any():
        is_ground = np.zeros(len(pts), dtype=bool)
        if ground_fill is not None:
            normal, offset = ground_fill
            height_m = pts @ np.asarray(normal, dtype=np.float64) + float(offset)
            # below the ego's plane is the road too (it falls away downhill); above it, a band growing with depth
            is_ground = height_m < GROUND_BAND_M + GROUND_BAND_PER_M * pts[:, 2]
        is_ground, u, v, z = is_ground[ok], u[ok], v[ok], z[ok]
        # 0. Only the rows from a margin above the highest return (rows above it have no returns).
        top = np.full(width, height, np.int64)
        np.minimum.at(top, u, v)  # first row with a return, per column
        r0 = max(int(top.min()) - CROP_MARGIN_PX, 0)
        h = height - r0
        v = v - r0
        obstacle = ~is_ground
        inv = _zbuffer_inverse(u[obstacle], v[obstacle], z[obstacle], width, h)
        # 1. Small diamond dilation: nearest point wins (max of inverse depth).
        inv = cv2.dilate(inv, _diamond(5))
        # 2. Closing to join neighbouring scan lines.
        inv = cv2.morphologyEx(inv, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
        # 2b. The ground between scan lines: its inverse depth interpolated down each column (exact for a
        #     plane), not the nearer line grown upwards (which would hide the bottom of anything standing
        #     farther away).
        g0, ground = _ground_inverse_depth(_zbuffer_inverse(u[is_ground], v[is_ground], z[is_ground], width, h),
                                           inv)
        g1 = g0 + len(ground)
        # 3. Fill remaining small holes with a wider dilation, then large holes with a wider one (the obstacles
        #    only, into what the ground does not cover: the ground is never grown, the plane fills its holes).
        for size in (7, 15, 31):
            empty = inv <= 0
            empty[g0:g1] &= ground <= 0
            if not empty.any():
                break
            grown = cv2.dilate(inv, np.ones((size, size), np.uint8))
            np.copyto(inv, grown, where=empty)
        np.maximum(inv[g0:g1], ground, out=inv[g0:g1])  # the nearer surface wins
        # 4. Light median to remove dilation blockiness, keeping empties empty.
        med = cv2.medianBlur(inv, 5)
        np.copyto(inv, med, where=(inv > 0) & (med > 0))
        # 5. Nothing above the highest LiDAR return of each column (sky / beyond range), spread over neighbours.
        top = cv2.erode(top.astype(np.float32)[None, :], np.ones((1, 31), np.uint8))[0] - r0
        known = (inv > 0) & (np.arange(h)[:, None] >= top[None, :])
        sub = depth[r0:]
        sub[known] = 1.0 / np.maximum(inv[known], np.float32(1e-9))
    if ground_fill is not None:
        p0 = _first_plane_row(K, width, height, *ground_fill)
        ys, xs = np.nonzero(np.isinf(depth[p0:]))
        ys += p0
        depth[ys, xs] = _plane_depth_at(K, ys, xs, *ground_fill)
    return depth
