"""The contract's second ``insert`` form: any image with a metric depth map, a camera-frame env map and a pose."""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from streetaug.datasets.nuscenes_format import VEHICLE_MOVING
from streetaug.placement.labels import object_label

from ..assets.asset import Asset
from ..core import InputError, PinholeCamera, pose_camera_to_transform, transform_points
from ..lighting.light import DistantLight
from .objects import render_objects
from .options import InsertOptions, item_seed
from .results import InsertResult

GROUND_MAX_TILT_DEG = 15.0  # a ground plane fitted from the depth map is trusted up to this tilt


def insert_into_image(
    image: np.ndarray, K: np.ndarray, depth_m: np.ndarray, envmap_cam: np.ndarray, asset: Asset,
    pose_camera: Sequence[float], options: InsertOptions,
) -> InsertResult:
    """Insert ``asset`` into any image.

    Args:
        image: (H, W, 3) uint8 RGB.
        K: (3, 3) intrinsics.
        depth_m: (H, W) camera-z depth in metres (inf / 0 / nan = unknown, treated as far).
        envmap_cam: (h, w, 3) linear HDR equirect map in the camera-frame convention (distant light).
        pose_camera: (X, Y, Z, YAW_DEG): bottom centre of the box on the ground, camera frame.
    """
    H, W = image.shape[:2]
    if depth_m.shape != (H, W):
        raise InputError(f"depth map: expected shape ({H}, {W}) like the image, got {depth_m.shape}")
    depth_m = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, np.inf).astype(np.float32)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    light = DistantLight.from_envmap(envmap_cam)
    timing["lighting"] = time.perf_counter() - t0
    T_cam_from_object = pose_camera_to_transform(*pose_camera)
    camera = PinholeCamera(K, W, H)
    ground_normal = ground_normal_from_depth(camera, depth_m, T_cam_from_object, asset.wlh)
    rendered = render_objects(image, K, depth_m, [light], [asset], [T_cam_from_object], [ground_normal], options,
                              item_seed(options.seed, "image"), timing)
    (obj,) = rendered.objects
    attribute = asset.attribute if asset.attribute is not None else (
        VEHICLE_MOVING if asset.category.startswith("vehicle.") else None)  # the pose says nothing more
    objects = [object_label(T_cam_from_object, asset.wlh, asset.category, camera, obj.full_mask(),
                            obj.full_coverage(), attribute=attribute)]
    timing["total"] = time.perf_counter() - t0
    return InsertResult.of(rendered.image, objects, rendered.mask, rendered.shadow_ratio, timing)


def ground_normal_from_depth(camera: PinholeCamera, depth_m: np.ndarray, T_cam_from_object: np.ndarray,
                             wlh: np.ndarray) -> np.ndarray:
    """Ground normal (3,) under the object, camera frame: a least-squares plane through the depth map's
    points under its footprint (grown to twice its size), or camera up (-y) when the depth has too few
    points there or the plane is tilted more than ``GROUND_MAX_TILT_DEG``."""
    up = np.array([0.0, -1.0, 0.0])
    l, w = wlh[1], wlh[0]
    gx, gy = np.meshgrid(np.linspace(-l, l, 9), np.linspace(-w, w, 9))
    pts_obj = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    uv, z = camera.project(transform_points(T_cam_from_object, pts_obj))
    ok = np.isfinite(uv).all(axis=1) & (z > 0)
    ij = np.round(uv[ok]).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < camera.width) & (ij[:, 1] >= 0) & (ij[:, 1] < camera.height)
    ij = ij[inside]
    if len(ij) < 6:
        return up
    d = depth_m[ij[:, 1], ij[:, 0]]
    good = np.isfinite(d)
    if good.sum() < 6:
        return up
    p = camera.unproject(ij[good].astype(float), d[good])
    centred = p - p.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    normal = normal if normal @ up > 0 else -normal
    # Only trust a plane that is close to horizontal; depth noise must not tilt the car.
    return normal if normal @ up > np.cos(np.radians(GROUND_MAX_TILT_DEG)) else up
