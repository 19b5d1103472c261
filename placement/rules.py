"""Placement rules: small pure functions over candidate arrays, each returning (N,) bool "passes".

Footprints are the boxes' bottom rectangles in global x/y, corners (N, 4, 2) in the order
front-left, front-right, back-right, back-left (object x = front, y = left). Distances between
objects are footprint-to-footprint (polygon) distances, not centre distances.
"""

from __future__ import annotations

import functools
from typing import Sequence

import numpy as np
import shapely
from scipy.spatial import cKDTree

from streetaug.augment.core import PinholeCamera, check_shape, invert_transform, make_transform, transform_points
from streetaug.datasets.sample import Box

from .drivable import DrivableArea

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


def box_footprint_rect(T_global_from_object: np.ndarray, wlh: np.ndarray) -> np.ndarray:
    """Footprints (N, 4, 2) of 3D boxes standing on (possibly tilted) ground, as heading-aligned rectangles.

    The rectangle is aligned with each object's heading (its x axis projected on global x/y) and
    bounds the vertical projection of all 8 box corners, so it contains the box's whole shadow on
    the x/y plane (on flat ground it is exactly the box's bottom face). Corner order as
    :func:`footprint_corners`.

    Args:
        T_global_from_object: (N, 4, 4) object (x front, y left, z up, origin at the bottom centre) -> global.
        wlh: (3,) box size [w, l, h] in metres.
    """
    T = np.asarray(T_global_from_object, dtype=np.float64).reshape(-1, 4, 4)
    corners = np.einsum("nij,kj->nki", T[:, :3, :3], box_corners_object(wlh))[..., :2]  # (N, 8, 2) rel. origin
    u = T[:, :2, 0] / np.maximum(np.linalg.norm(T[:, :2, 0], axis=1, keepdims=True), 1e-12)
    v = np.c_[-u[:, 1], u[:, 0]]
    a = np.einsum("nkd,nd->nk", corners, u)
    b = np.einsum("nkd,nd->nk", corners, v)
    a0, a1, b0, b1 = a.min(1), a.max(1), b.min(1), b.max(1)
    ca = np.stack([a1, a1, a0, a0], axis=1)
    cb = np.stack([b1, b0, b0, b1], axis=1)
    return T[:, None, :2, 3] + ca[..., None] * u[:, None] + cb[..., None] * v[:, None]


@functools.lru_cache(maxsize=8192)
def _box_transform(rotation: bytes, center: bytes) -> np.ndarray:
    T = make_transform(np.frombuffer(rotation, np.float64), np.frombuffer(center, np.float64))
    T.setflags(write=False)
    return T


def box_transform(box: Box) -> np.ndarray:
    """``box.T_global_from_box`` (4, 4), read-only, computed once per rotation and centre: placement reads the
    sample's boxes again for every camera, object and rule (a quaternion to matrix each time was a tenth of it)."""
    return _box_transform(np.asarray(box.rotation, np.float64).tobytes(), np.asarray(box.center, np.float64).tobytes())


def box_corners(box: Box) -> np.ndarray:
    """``box.corners()`` (8, 3) (the same numbers) through :func:`box_transform`."""
    w, l, h = box.wlh
    x = np.array([1, 1, 1, 1, -1, -1, -1, -1]) * l / 2
    y = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * w / 2
    z = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * h / 2
    return transform_points(box_transform(box), np.stack([x, y, z], axis=1))


def box_footprints(boxes: Sequence[Box]) -> np.ndarray:
    """Footprints (B, 4, 2) of nuScenes :class:`Box` objects (global frame, bottom face corners in x/y)."""
    if len(boxes) == 0:
        return np.zeros((0, 4, 2))
    return np.stack([box_corners(b)[[0, 1, 5, 4], :2] for b in boxes])


def box_bottoms(boxes: Sequence[Box]) -> np.ndarray:
    """Bottom centres (B, 3) of nuScenes :class:`Box` objects (global frame): the centre less half the
    height along each box's own up axis (where the object stands on the ground)."""
    if len(boxes) == 0:
        return np.zeros((0, 3))
    return np.stack([np.asarray(b.center, np.float64) - 0.5 * float(b.wlh[2]) * box_transform(b)[:3, 2]
                     for b in boxes])


def points_in_box(points_global: np.ndarray, box: Box, margin_m: float = 0.0) -> np.ndarray:
    """(P,) bool: whether each point (P, 3) lies inside the box grown by ``margin_m``, boundary included
    (a nuScenes ``num_lidar_pts`` count with ``margin_m`` 0)."""
    p = transform_points(invert_transform(box_transform(box)), np.asarray(points_global, np.float64).reshape(-1, 3))
    return np.all(np.abs(p) <= np.asarray(box.wlh, np.float64)[[1, 0, 2]] / 2 + margin_m, axis=1)


def points_in_boxes(points_global: np.ndarray, boxes: Sequence[Box], margin_m: float = 0.0) -> np.ndarray:
    """(P,) bool: whether each point (P, 3) lies inside any box (grown by ``margin_m``)."""
    points_global = np.asarray(points_global, dtype=np.float64)
    check_shape(points_global, ("P", 3), "points_global")
    inside = np.zeros(len(points_global), dtype=bool)
    if len(boxes) == 0 or len(points_global) == 0:
        return inside
    centers = np.stack([b.center for b in boxes])
    half = np.stack([np.asarray(b.wlh)[[1, 0, 2]] / 2 + margin_m for b in boxes])  # (B, 3) along box x, y, z
    reach = np.linalg.norm(half, axis=1) * (1.0 + 1e-9) + 1e-9  # a square around each box's bounding circle
    order = np.argsort(points_global[:, 0], kind="stable")
    xs, ys = points_global[order, 0], points_global[order, 1]
    starts = np.searchsorted(xs, centers[:, 0] - reach, side="left")
    ends = np.searchsorted(xs, centers[:, 0] + reach, side="right")
    for b, c, r, i0, i1 in zip(boxes, centers, reach, starts, ends):  # one small check per box (tens of boxes)
        idx = order[i0:i1][np.abs(ys[i0:i1] - c[1]) <= r]
        if len(idx):
            inside[idx[points_in_box(points_global[idx], b, margin_m)]] = True
    return inside


def _points_near_footprints(corners_xy: np.ndarray, points_xy: np.ndarray,
                            margin_m: float) -> tuple[np.ndarray, np.ndarray]:
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
    # the tree only over the points in the candidates' bounding box grown by the radius (a little more: a
    # superset of every disc), not the whole sweep: the same points lie within the radius
    reach = radius * (1.0 + 1e-9) + 1e-9
    lo, hi = center.min(axis=0) - reach, center.max(axis=0) + reach
    near = np.flatnonzero((points_xy[:, 0] >= lo[0]) & (points_xy[:, 0] <= hi[0])
                          & (points_xy[:, 1] >= lo[1]) & (points_xy[:, 1] <= hi[1]))
    if len(near) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    lists = cKDTree(points_xy[near]).query_ball_point(center, radius)
    lens = np.fromiter((len(x) for x in lists), dtype=np.int64, count=N)
    cand = np.repeat(np.arange(N), lens)
    pt = near[np.fromiter((i for x in lists for i in x), dtype=np.int64, count=int(lens.sum()))]
    d = points_xy[pt] - center[cand]
    keep = (np.abs(np.einsum("kd,kd->k", d, ux[cand])) <= half_l[cand] + margin_m) & (
        np.abs(np.einsum("kd,kd->k", d, uy[cand])) <= half_w[cand] + margin_m
    )
    return cand[keep], pt[keep]


def projected_inside_fraction(corners_cam: np.ndarray, camera: PinholeCamera, near_m: float = 0.1) -> np.ndarray:
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
    uvw = pts @ camera.K.T
    uv = uvw[..., :2] / uvw[..., 2:3]
    hull = shapely.convex_hull(shapely.multipoints(uv))
    area = shapely.area(hull)
    image = shapely.box(-0.5, -0.5, camera.width - 0.5, camera.height - 0.5)
    inside = shapely.area(shapely.intersection(hull, image))
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(area > 1e-12, inside / area, 0.0)
    return np.where(any_valid, np.clip(frac, 0.0, 1.0), 0.0)


# ---------------------------------------------------------------------- rules


def rule_distance(center_xy: np.ndarray, camera_xy: np.ndarray, min_m: float, max_m: float) -> np.ndarray:
    """Horizontal (global x/y) distance from the camera centre to each box centre within [min_m, max_m]."""
    d = np.linalg.norm(np.asarray(center_xy, float) - np.asarray(camera_xy, float)[None, :2], axis=1)
    return (d >= min_m) & (d <= max_m)


def rule_drivable(drivable: DrivableArea, corners_xy: np.ndarray) -> np.ndarray:
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
    corners_xy = np.asarray(corners_xy, float)
    box_corners_xy = np.asarray(box_corners_xy, float)
    need = np.where(np.asarray(box_is_dynamic, bool), dynamic_m, static_m)
    # only pairs whose bounding circles come closer than the clearance need the polygon distance
    c_cand, c_box = corners_xy.mean(axis=1), box_corners_xy.mean(axis=1)
    r_cand = np.linalg.norm(corners_xy - c_cand[:, None], axis=2).max(axis=1)
    r_box = np.linalg.norm(box_corners_xy - c_box[:, None], axis=2).max(axis=1)
    gap_bound = np.linalg.norm(c_cand[:, None] - c_box[None], axis=2) - r_cand[:, None] - r_box[None]
    ci, bi = np.nonzero(gap_bound < need[None, :])
    ok = np.ones(N, dtype=bool)
    if len(ci):
        d = shapely.distance(shapely.polygons(corners_xy[ci]), shapely.polygons(box_corners_xy[bi]))
        ok[ci[d < need[bi]]] = False
    return ok


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


def visible_fraction_estimate(
    T_cam_from_object: np.ndarray,
    wlh: np.ndarray,
    camera: PinholeCamera,
    depth_m: np.ndarray,
    tolerance_m: float,
    grid: int = 16,
) -> np.ndarray:
    """(N,) estimated fraction of each box's image that is inside the image and not hidden by the scene.

    A ``grid`` x ``grid`` lattice of rays spans the bounding rectangle of each projected box; the rays
    that hit the box (slab test in the object frame) are its samples, with the box surface's camera
    z. A sample counts as visible when its pixel is in the image and the scene depth there (``depth_m``,
    (H, W) camera z in metres, inf = unknown: the renderer's, :func:`streetaug.placement.scene.scene_depth`)
    is not nearer than the box surface by more than ``tolerance_m``. Boxes not wholly in front of the
    camera (z > 0.1 m) give 0.

    Args:
        T_cam_from_object: (N, 4, 4) object (x front, y left, z up, origin at the bottom centre) -> camera.
        wlh: (3,) box size [w, l, h] in metres.
    """
    T = np.asarray(T_cam_from_object, dtype=np.float64).reshape(-1, 4, 4)
    N = len(T)
    corners = np.einsum("nij,kj->nki", T[:, :3, :3], box_corners_object(wlh)) + T[:, None, :3, 3]
    front = np.all(corners[..., 2] > 0.1, axis=1)
    out = np.zeros(N)
    if not front.any():
        return out
    T, corners = T[front], corners[front]
    uv = corners @ camera.K.T
    uv = uv[..., :2] / uv[..., 2:3]
    lo, hi = uv.min(axis=1), uv.max(axis=1)  # (M, 2)
    t = (np.arange(grid) + 0.5) / grid
    gu = lo[:, None, 0] + (hi - lo)[:, None, 0] * np.repeat(t, grid)[None]  # (M, S)
    gv = lo[:, None, 1] + (hi - lo)[:, None, 1] * np.tile(t, grid)[None]
    d_cam = camera.rays(np.stack([gu, gv], axis=2).reshape(-1, 2), unit=False).reshape(*gu.shape, 3)  # z = 1
    R, o = T[:, :3, :3], T[:, :3, 3]
    d_obj = np.einsum("mji,msj->msi", R, d_cam)  # R^T d
    o_obj = -np.einsum("mji,mj->mi", R, o)[:, None, :]  # camera centre in the object frame
    w, l, h = np.asarray(wlh, dtype=np.float64)
    box_lo, box_hi = np.array([-l / 2, -w / 2, 0.0]), np.array([l / 2, w / 2, h])
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (box_lo - o_obj) / d_obj
        t1 = (box_hi - o_obj) / d_obj
    t_near = np.nanmax(np.minimum(t0, t1), axis=2)
    t_far = np.nanmin(np.maximum(t0, t1), axis=2)
    hit = (t_near < t_far) & (t_far > 0)
    z_surface = np.maximum(t_near, 0.0)  # d_cam has z = 1: the ray parameter is the camera z
    ui, vi = np.round(gu).astype(np.int64), np.round(gv).astype(np.int64)
    in_image = (ui >= 0) & (ui < camera.width) & (vi >= 0) & (vi < camera.height)
    scene = np.full(gu.shape, np.inf)
    scene[in_image] = depth_m[vi[in_image], ui[in_image]]
    visible = hit & in_image & ~(scene < z_surface - tolerance_m)
    n_hit = hit.sum(axis=1)
    out[front] = np.where(n_hit > 0, visible.sum(axis=1) / np.maximum(n_hit, 1), 0.0)
    return out


def occlusion_tolerance_for(wlh: np.ndarray, tolerance_m: float) -> float:
    """The occlusion tolerance (m) for a box of size ``wlh``: ``tolerance_m``, but no more than half its smaller
    horizontal side (at least 0.3 m): a hedge 0.9 m in front of a pedestrian hides it, though not a car's
    far half."""
    return float(min(tolerance_m, max(0.3, 0.5 * min(float(wlh[0]), float(wlh[1])))))


def rule_in_view(
    corners_cam: np.ndarray,
    camera: PinholeCamera,
    min_fraction: float,
    near_m: float,
    visible_fraction: np.ndarray | None = None,
) -> np.ndarray:
    """In front of the camera and visible enough.

    Every box corner (N, 8, 3) at camera z >= near_m, >= min_fraction of the projected box inside the
    image, and, when given, the occlusion-aware ``visible_fraction`` (N,) (see
    :func:`visible_fraction_estimate`) >= min_fraction too.
    """
    corners_cam = np.asarray(corners_cam, dtype=np.float64)
    front = np.all(corners_cam[..., 2] >= near_m, axis=1)
    frac = projected_inside_fraction(corners_cam, camera, near_m)
    ok = front & (frac >= min_fraction)
    if visible_fraction is not None:
        ok &= np.asarray(visible_fraction) >= min_fraction
    return ok


def rule_mutual(corners_xy: np.ndarray, placed_corners_xy: np.ndarray, clearance_m: float) -> np.ndarray:
    """Footprints (N, 4, 2) at least ``clearance_m`` from every already placed footprint (Q, 4, 2)."""
    return rule_box_clearance(
        corners_xy, placed_corners_xy, np.ones(len(placed_corners_xy), bool), clearance_m, clearance_m
    )


def rule_corners_unoccluded(
    corners_cam: np.ndarray, camera: PinholeCamera, depth_m: np.ndarray, tolerance_m: float = 1.0
) -> np.ndarray:
    """The paper's occlusion rule: no top corner of the box (N, 8, 3) is hidden by the scene.

    A top corner projecting inside the image is occluded when the scene depth at its pixel (H, W),
    camera z in metres, inf = unknown) is nearer than the corner by more than ``tolerance_m``. Only the
    four top corners are tested: the bottom ones touch the ground, whose own depth would hide them.
    """
    corners_cam = np.asarray(corners_cam, dtype=np.float64)
    check_shape(corners_cam, ("N", 8, 3), "corners_cam")
    check_shape(depth_m, camera.shape, "depth_m")
    H, W = camera.shape
    top = corners_cam[:, [0, 1, 4, 5]]  # (N, 4, 3)
    z = top[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uvw = top @ camera.K.T
        u = np.round(uvw[..., 0] / uvw[..., 2])
        v = np.round(uvw[..., 1] / uvw[..., 2])
    inside = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    ui = np.where(inside, u, 0).astype(np.int64)
    vi = np.where(inside, v, 0).astype(np.int64)
    occluded = inside & (depth_m[vi, ui] < z - tolerance_m)
    return ~occluded.any(axis=1)
