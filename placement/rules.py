"""Placement rules: small pure functions over candidate arrays, each returning (N,) bool "passes".

Footprints are the boxes' bottom rectangles in global x/y, corners (N, 4, 2) in the order
front-left, front-right, back-right, back-left (object x = front, y = left). Distances between
objects are footprint-to-footprint (polygon) distances, not centre distances.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np
import shapely
from scipy.spatial import cKDTree

from streetaug.augment.conventions import check_shape, invert_transform, transform_points

# The 12 edges of a box whose corners are ordered as in box_corners_object.
_BOX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)


# ---------------------------------------------------------------------- geometry helpers


def footprint_corners(center_xy: np.ndarray, yaw_rad: np.ndarray, length_m: float, width_m: float) -> np.ndarray:
    """Footprint corners (N, 4, 2) of boxes with centres (N, 2) and headings (N,) (rad from +x towards +y)."""
    center_xy = np.asarray(center_xy, dtype=np.float64)
    check_shape(center_xy, ("N", 2), "center_xy")
    yaw = np.asarray(yaw_rad, dtype=np.float64).reshape(-1)
    lx = np.array([1, 1, -1, -1]) * length_m / 2
    ly = np.array([1, -1, -1, 1]) * width_m / 2
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return np.stack([center_xy[:, :1] + c * lx - s * ly, center_xy[:, 1:] + s * lx + c * ly], axis=2)


def box_corners_object(wlh: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of a box in its object frame (origin at the bottom centre, x front, z up).

    Order as :meth:`Box.corners`: the four front corners (+x) first, as (y, z) = (+w/2, h), (-w/2, h),
    (-w/2, 0), (+w/2, 0), then the same four at the back (-x).
    """
    w, l, h = np.asarray(wlh, dtype=np.float64)
    x = np.array([1, 1, 1, 1, -1, -1, -1, -1]) * l / 2
    y = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * w / 2
    z = np.array([1, 1, 0, 0, 1, 1, 0, 0]) * h
    return np.stack([x, y, z], axis=1)


def box_footprints(boxes: Sequence) -> np.ndarray:
    """Footprints (B, 4, 2) of nuScenes :class:`Box` objects (global frame, bottom face corners in x/y)."""
    if len(boxes) == 0:
        return np.zeros((0, 4, 2))
    return np.stack([b.corners()[[0, 1, 5, 4], :2] for b in boxes])


def points_in_boxes(points_global: np.ndarray, boxes: Sequence, margin_m: float = 0.0) -> np.ndarray:
    """(P,) bool: whether each point (P, 3) lies inside any box (grown by ``margin_m``)."""
    points_global = np.asarray(points_global, dtype=np.float64)
    check_shape(points_global, ("P", 3), "points_global")
    inside = np.zeros(len(points_global), dtype=bool)
    if len(boxes) == 0 or len(points_global) == 0:
        return inside
    centers = np.stack([b.center for b in boxes])
    half = np.stack([np.asarray(b.wlh)[[1, 0, 2]] / 2 + margin_m for b in boxes])  # (B, 3) along box x, y, z
    lists = cKDTree(points_global[:, :2]).query_ball_point(centers[:, :2], np.linalg.norm(half, axis=1))
    for b, idx, hb in zip(boxes, lists, half):  # one small vectorised check per box (tens of boxes)
        if idx:
            idx = np.asarray(idx)
            p = transform_points(invert_transform(b.T_global_from_box), points_global[idx])
            inside[idx[np.all(np.abs(p) <= hb, axis=1)]] = True
    return inside


def _points_near_footprints(corners_xy: np.ndarray, points_xy: np.ndarray, margin_m: float):
    """Pairs (candidate index (K,), point index (K,)) of points within the footprint grown by ``margin_m``.

    The grown footprint is the rectangle enlarged by ``margin_m`` on every side.
    """
    N = len(corners_xy)
    if N == 0 or len(points_xy) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    center = corners_xy.mean(axis=1)
    ex = corners_xy[:, 0] - corners_xy[:, 3]  # back-left -> front-left: length direction
    ey = corners_xy[:, 0] - corners_xy[:, 1]  # front-right -> front-left: width direction
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


def projected_inside_fraction(
    corners_cam: np.ndarray, K: np.ndarray, width: int, height: int, near_m: float = 0.1
) -> np.ndarray:
    """(N,) fraction of each projected 3D box inside the image.

    The projected box is the convex hull of the projection of the box clipped at the plane z = near_m
    (corners (N, 8, 3) in the camera frame, ordered as :func:`box_corners_object`). The image covers
    [-0.5, W - 0.5] x [-0.5, H - 0.5] (pixel centres at integers). Boxes wholly behind the plane give 0.
    """
    corners_cam = np.asarray(corners_cam, dtype=np.float64)
    check_shape(corners_cam, ("N", 8, 3), "corners_cam")
    N = len(corners_cam)
    if N == 0:
        return np.zeros(0)
    z = corners_cam[..., 2]
    a, b = corners_cam[:, _BOX_EDGES[:, 0]], corners_cam[:, _BOX_EDGES[:, 1]]  # (N, 12, 3)
    za, zb = a[..., 2], b[..., 2]
    crosses = (za - near_m) * (zb - near_m) < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crosses, (near_m - za) / (zb - za), 0.0)
    cut = a + (b - a) * t[..., None]
    pts = np.concatenate([corners_cam, cut], axis=1)  # (N, 20, 3)
    valid = np.concatenate([z >= near_m, crosses], axis=1)
    any_valid = valid.any(axis=1)
    first = np.argmax(valid, axis=1)
    pts = np.where(valid[..., None], pts, pts[np.arange(N), first][:, None, :])
    pts[:, :, 2] = np.maximum(pts[:, :, 2], near_m * 0.999)
    uvw = pts @ np.asarray(K, dtype=np.float64).T
    uv = uvw[..., :2] / uvw[..., 2:3]
    hull = shapely.convex_hull(shapely.multipoints(uv))
    area = shapely.area(hull)
    image = shapely.box(-0.5, -0.5, width - 0.5, height - 0.5)
    inside = shapely.area(shapely.intersection(hull, image))
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(area > 1e-12, inside / area, 0.0)
    return np.where(any_valid, np.clip(frac, 0.0, 1.0), 0.0)


# ---------------------------------------------------------------------- rules


def rule_distance(center_xy: np.ndarray, camera_xy: np.ndarray, min_m: float, max_m: float) -> np.ndarray:
    """Horizontal (global x/y) distance from the camera centre to each box centre within [min_m, max_m]."""
    d = np.linalg.norm(np.asarray(center_xy, float) - np.asarray(camera_xy, float)[None, :2], axis=1)
    return (d >= min_m) & (d <= max_m)


def rule_drivable(drivable, corners_xy: np.ndarray) -> np.ndarray:
    """The whole footprint (N, 4, 2) lies in the drivable area (a :class:`DrivableArea`)."""
    return drivable.contains_footprints(corners_xy)


def rule_box_clearance(
    corners_xy: np.ndarray,
    box_corners_xy: np.ndarray,
    box_is_dynamic: np.ndarray,
    dynamic_m: float,
    static_m: float,
) -> np.ndarray:
    """Footprint distance to every annotated box >= dynamic_m (dynamic boxes) or static_m (others).

    Args:
        corners_xy: (N, 4, 2) candidate footprints, global x/y.
        box_corners_xy: (B, 4, 2) annotated boxes' footprints, global x/y.
        box_is_dynamic: (B,) bool, vehicle/human/animal boxes.
    """
    N = len(corners_xy)
    if N == 0 or len(box_corners_xy) == 0:
        return np.ones(N, dtype=bool)
    cand = shapely.polygons(np.asarray(corners_xy, float))
    boxes = shapely.polygons(np.asarray(box_corners_xy, float))
    d = shapely.distance(cand[:, None], boxes[None, :])  # (N, B)
    need = np.where(np.asarray(box_is_dynamic, bool), dynamic_m, static_m)
    return np.all(d >= need[None, :], axis=1)


def rule_obstacles(
    corners_xy: np.ndarray,
    ground_point: np.ndarray,
    ground_normal: np.ndarray,
    obstacle_points: np.ndarray,
    margin_m: float,
    min_height_m: float,
    max_height_m: float,
    max_points: int,
) -> np.ndarray:
    """At most ``max_points`` unannotated LiDAR points near each footprint stand out of the ground.

    Args:
        corners_xy: (N, 4, 2) footprints, global x/y.
        ground_point, ground_normal: (N, 3) each candidate's local ground plane (global frame).
        obstacle_points: (P, 3) LiDAR points in the global frame that lie in no annotated box.
        margin_m: the footprint is grown by this on every side.
        min_height_m, max_height_m: height band above the local ground (along its normal) counting as obstacle.
    """
    N = len(corners_xy)
    obstacle_points = np.asarray(obstacle_points, dtype=np.float64).reshape(-1, 3)
    cand, pt = _points_near_footprints(np.asarray(corners_xy, float), obstacle_points[:, :2], margin_m)
    h = np.einsum("kd,kd->k", obstacle_points[pt] - ground_point[cand], ground_normal[cand])
    hits = (h >= min_height_m) & (h <= max_height_m)
    count = np.bincount(cand[hits], minlength=N)
    return count <= max_points


def rule_lidarseg(corners_xy: np.ndarray, non_drivable_xy: np.ndarray, margin_m: float, max_points: int) -> np.ndarray:
    """At most ``max_points`` non-drivable lidarseg points (P, 2) within the footprint grown by ``margin_m``."""
    N = len(corners_xy)
    non_drivable_xy = np.asarray(non_drivable_xy, dtype=np.float64).reshape(-1, 2)
    cand, _ = _points_near_footprints(np.asarray(corners_xy, float), non_drivable_xy, margin_m)
    return np.bincount(cand, minlength=N) <= max_points


def rule_in_view(
    corners_cam: np.ndarray, K: np.ndarray, width: int, height: int, min_fraction: float, near_m: float
) -> np.ndarray:
    """Every box corner (N, 8, 3) at camera z >= near_m and >= min_fraction of the projected box in the image."""
    corners_cam = np.asarray(corners_cam, dtype=np.float64)
    front = np.all(corners_cam[..., 2] >= near_m, axis=1)
    frac = projected_inside_fraction(corners_cam, K, width, height, near_m)
    return front & (frac >= min_fraction)


def rule_mutual(corners_xy: np.ndarray, placed_corners_xy: np.ndarray, clearance_m: float) -> np.ndarray:
    """Footprints (N, 4, 2) at least ``clearance_m`` from every already placed footprint (Q, 4, 2)."""
    return rule_box_clearance(
        corners_xy, placed_corners_xy, np.ones(len(placed_corners_xy), bool), clearance_m, clearance_m
    )


def lidar_depth_image(points_cam: np.ndarray, K: np.ndarray, width: int, height: int, spread_px: int = 3) -> np.ndarray:
    """Sparse scene depth (H, W) float32 from camera-frame LiDAR points (P, 3): nearest z per pixel,
    spread to a (2 spread_px + 1)^2 neighbourhood by a min filter; inf where no point."""
    points_cam = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    depth = np.full((height, width), np.inf, np.float32)
    front = points_cam[:, 2] > 0.1
    uvw = points_cam[front] @ np.asarray(K, dtype=np.float64).T
    u = np.round(uvw[:, 0] / uvw[:, 2]).astype(np.int64)
    v = np.round(uvw[:, 1] / uvw[:, 2]).astype(np.int64)
    ok = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    np.minimum.at(depth, (v[ok], u[ok]), points_cam[front][ok, 2].astype(np.float32))
    if spread_px > 0:
        finite = np.where(np.isfinite(depth), depth, np.float32(1e9))
        finite = cv2.erode(finite, np.ones((2 * spread_px + 1, 2 * spread_px + 1), np.uint8))
        depth = np.where(finite < 1e9, finite, np.inf).astype(np.float32)
    return depth


def rule_corners_unoccluded(
    corners_cam: np.ndarray, K: np.ndarray, depth_m: np.ndarray, tolerance_m: float = 1.0
) -> np.ndarray:
    """The paper's occlusion rule: no top corner of the box (N, 8, 3) is hidden by the scene.

    A top corner projecting inside the image is occluded when the scene depth at its pixel (H, W),
    camera z in metres, inf = unknown) is nearer than the corner by more than ``tolerance_m``. Only the
    four top corners are tested: the bottom ones touch the ground, whose own depth would hide them.
    """
    corners_cam = np.asarray(corners_cam, dtype=np.float64)
    check_shape(corners_cam, ("N", 8, 3), "corners_cam")
    H, W = depth_m.shape
    top = corners_cam[:, [0, 1, 4, 5]]  # (N, 4, 3)
    z = top[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uvw = top @ np.asarray(K, dtype=np.float64).T
        u = np.round(uvw[..., 0] / uvw[..., 2])
        v = np.round(uvw[..., 1] / uvw[..., 2])
    inside = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    ui = np.where(inside, u, 0).astype(np.int64)
    vi = np.where(inside, v, 0).astype(np.int64)
    occluded = inside & (depth_m[vi, ui] < z - tolerance_m)
    return ~occluded.any(axis=1)
