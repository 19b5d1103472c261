"""Labels of inserted objects, per the ``labels.json`` contract (docs/interfaces.md).

Conventions chosen here:

* ``bbox_2d`` = [x0, y0, x1, y1] are the outer pixel *edges* of the visible object pixels (mask > 0.5):
  pixel (i, j) has its centre at (i, j) and spans [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5], so a single
  visible pixel (i, j) gives [i - 0.5, j - 0.5, i + 0.5, j + 0.5] and the full image [-0.5, -0.5, W - 0.5, H - 0.5].
  ``None`` when no pixel is visible.
* ``visible_fraction`` = sum(mask) / sum(coverage) (mask: visible coverage after occlusion; coverage:
  the object's coverage without occluders), clipped to [0, 1]; 0 when coverage is empty.
* ``visibility_token`` bins the visible fraction as nuScenes: "1" [0, 0.4), "2" [0.4, 0.6), "3" [0.6, 0.8),
  "4" [0.8, 1] (edges belong to the higher bin).
* ``truncation`` = fraction of the projected 3D box (convex hull of its corners, clipped at z = 0.1 m)
  outside the image.
* ``num_lidar_pts`` / ``num_radar_pts`` = 0: the inserted object was not seen by the real sensors (``streetaug
  batch`` then sets ``num_lidar_pts`` to the points of the sample's augmented LiDAR sweep on it, as its annotation).
* ``box_global`` follows ``sample_annotation``: ``translation`` = box centre (not the bottom), ``size`` =
  [w, l, h], ``rotation`` = [w, x, y, z] box -> global. On tilted ground the rotation carries the
  ground's roll/pitch (the box is exactly the rendered object's box), so it is not yaw-only.
* ``category`` comes from the asset (:mod:`streetaug.augment.assets.categories` maps file names).
* ``attribute`` = the caller's choice; :func:`streetaug.placement.place.place_objects` records it per class
  rule: vehicles ``vehicle.parked`` within ``kerb_distance_m`` of the drivable edge, else ``vehicle.moving``;
  cycles and pedestrians the asset's own (rider, pose); cones and barriers none (null).
"""

from __future__ import annotations

import numpy as np

from streetaug.augment.core import PinholeCamera, check_shape, rotation_to_quat, transform_to_pose_camera
from streetaug.datasets.nuscenes_format import VEHICLE_MOVING, visibility_token

from .place import Placement
from .rules import box_corners_object, projected_inside_fraction


def bbox_from_mask(mask: np.ndarray, threshold: float = 0.5) -> list[float] | None:
    """[x0, y0, x1, y1] pixel-edge box of pixels with mask > threshold (H, W); None when there are none."""
    mask = np.asarray(mask)
    check_shape(mask, ("H", "W"), "mask")
    on = mask > threshold
    cols = np.flatnonzero(on.any(axis=0))
    rows = np.flatnonzero(on.any(axis=1))
    if len(cols) == 0:
        return None
    return [float(cols[0]) - 0.5, float(rows[0]) - 0.5, float(cols[-1]) + 0.5, float(rows[-1]) + 0.5]


def object_label(
    T_cam_from_object: np.ndarray,
    wlh: np.ndarray,
    category: str,
    camera: PinholeCamera,
    mask: np.ndarray,
    coverage: np.ndarray,
    T_global_from_cam: np.ndarray | None = None,
    attribute: str | None = VEHICLE_MOVING,
) -> dict:
    """The contract's object dict for one inserted object.

    Args:
        T_cam_from_object: (4, 4) object frame (x front, y left, z up, origin at the bottom centre) -> camera.
        wlh: (3,) box size [w, l, h] in metres.
        category: nuScenes category, e.g. ``vehicle.car``.
        camera: the camera (intrinsics, image size).
        mask: (H, W) float visible coverage of the object in [0, 1] (after occlusion).
        coverage: (H, W) float coverage of the object without occluders.
        T_global_from_cam: (4, 4) camera -> global; when given, ``box_global`` is added.
        attribute: nuScenes attribute name, or None for a class without one (cones, barriers).

    Returns:
        dict with ``category``, ``box_camera`` {center, size_wlh, yaw_deg}, ``bbox_2d``,
        ``visible_fraction``, ``visibility_token``, ``truncation``, ``num_lidar_pts`` and ``num_radar_pts``
        (0), ``attribute``,
        and ``box_global`` {translation, size, rotation [w, x, y, z]} when ``T_global_from_cam`` is given.
    """
    T = np.asarray(T_cam_from_object, dtype=np.float64)
    check_shape(T, (4, 4), "T_cam_from_object")
    wlh = np.asarray(wlh, dtype=np.float64)
    check_shape(wlh, (3,), "wlh")
    mask = np.asarray(mask, dtype=np.float64)
    coverage = np.asarray(coverage, dtype=np.float64)
    check_shape(mask, camera.shape, "mask")
    check_shape(coverage, camera.shape, "coverage")

    up_cam = T[:3, 2]
    center_cam = T[:3, 3] + 0.5 * wlh[2] * up_cam
    _, yaw_deg = transform_to_pose_camera(T)
    total = float(coverage.sum())
    visible = float(np.clip(mask.sum() / total, 0.0, 1.0)) if total > 0 else 0.0
    corners_cam = box_corners_object(wlh) @ T[:3, :3].T + T[:3, 3]
    inside = float(projected_inside_fraction(corners_cam[None], camera, near_m=0.1)[0])
    label = {
        "category": category,
        "box_camera": {
            "center": [float(v) for v in center_cam],
            "size_wlh": [float(v) for v in wlh],
            "yaw_deg": float(yaw_deg),
        },
        "bbox_2d": bbox_from_mask(mask),
        "visible_fraction": visible,
        "visibility_token": visibility_token(visible),
        "truncation": float(1.0 - inside),
        "num_lidar_pts": 0,
        "num_radar_pts": 0,
        "attribute": attribute,
    }
    if T_global_from_cam is not None:
        T_gc = np.asarray(T_global_from_cam, dtype=np.float64)
        check_shape(T_gc, (4, 4), "T_global_from_cam")
        T_go = T_gc @ T
        label["box_global"] = {
            "translation": [float(v) for v in T_go[:3, 3] + 0.5 * wlh[2] * T_go[:3, 2]],
            "size": [float(v) for v in wlh],
            "rotation": [float(v) for v in rotation_to_quat(T_go[:3, :3])],
        }
    return label


def placement_label_fields(placement: Placement) -> dict:
    """Extra ``labels.json`` keys describing how a :class:`~streetaug.placement.place.Placement` was made.

    Returns ``{"placement": {drivable_source, drivable_confidence, ground_source, yaw_source, distance_m,
    edge_distance_m}}`` (sources as in ``Placement``; ``drivable_confidence`` is "high" for the map,
    "medium" for lidarseg, "low" for the LiDAR ground fallback).
    """
    return {"placement": {
        "drivable_source": placement.drivable_source,
        "drivable_confidence": placement.drivable_confidence,
        "ground_source": placement.ground_source,
        "yaw_source": placement.yaw_source,
        "distance_m": float(placement.distance_m),
        "edge_distance_m": float(placement.edge_distance_m),
    }}
