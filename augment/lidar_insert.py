"""Inserted objects in the LiDAR sweep, so the LiDAR agrees with the augmented images and the boxes.

nuScenes stores only a sweep's returns. A beam whose return lies behind an inserted object (the road,
a wall, a car further away) would now have returned from the object: the point moves along its beam
onto the object's surface (first hit; 1 mm inside), keeps its ring index, takes the intensity typical of this
sweep's real cars and, with lidarseg, the object's class. Points in front of the object are unchanged.
Beams that returned nothing (sky) stay without a return, so an object lit only by such beams is
under-sampled; at 10-40 m, where objects stand on the road, almost every beam through them returned
from the ground or a structure behind.

Frames: everything in the LiDAR sensor frame (nuScenes ``.pcd.bin``: x, y, z, intensity, ring).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from streetaug.datasets.lidarseg import LIDARSEG_CAR

from .conventions import check_shape, invert_transform, transform_points
from .raycast import RayScene

# Moved points sit this far beyond the surface along their beam: inside the object, so that float32
# storage cannot put a return on a tight box's face outside the box (LiDAR range noise is ~2 cm).
INSIDE_SURFACE_M = 1e-3
# Intensity of moved points when the sweep has no real car to learn it from (nuScenes 0-255 scale;
# painted car bodies mostly return 5-40).
DEFAULT_CAR_INTENSITY = 15.0


@dataclass(frozen=True)
class SweepInsertion:
    """A sweep with objects inserted.

    Attributes:
        points: (N, 5) float32 x, y, z, intensity, ring (same order and count as the input).
        labels: (N,) uint8 lidarseg labels with the moved points relabelled, or None without lidarseg.
        moved: (N,) int64 index of the object each point moved onto, -1 for unchanged points.
    """

    points: np.ndarray
    labels: np.ndarray | None
    moved: np.ndarray


def insert_into_sweep(points: np.ndarray, meshes_lidar: Sequence[tuple[np.ndarray, np.ndarray]],
                      labels: np.ndarray | None = None, object_labels: Sequence[int] | None = None,
                      intensity: float = DEFAULT_CAR_INTENSITY) -> SweepInsertion:
    """Move the returns whose beam meets an object onto that object's surface.

    Args:
        points: (N, 5) sweep (x, y, z in the LiDAR frame, intensity, ring); beams start at the origin.
        meshes_lidar: per object, (V, 3) vertices in the LiDAR frame and (F, 3) faces.
        labels: (N,) lidarseg labels of the sweep, or None.
        object_labels: lidarseg class of each object (default: vehicle.car).
        intensity: intensity given to the moved points (:func:`car_intensity`).
    """
    points = np.asarray(points, dtype=np.float32)
    check_shape(points, ("N", 5), "LiDAR points")
    out = points.copy()
    moved = np.full(len(points), -1, np.int64)
    if not meshes_lidar or len(points) == 0:
        return SweepInsertion(out, None if labels is None else np.asarray(labels, np.uint8).copy(), moved)
    xyz = points[:, :3].astype(np.float64)
    range_m = np.linalg.norm(xyz, axis=1)
    ok = range_m > 1e-6
    directions = np.zeros_like(xyz)
    directions[ok] = xyz[ok] / range_m[ok, None]
    best_t = np.where(ok, range_m, -np.inf)  # a hit must come before the return (or the other objects)
    origins = np.zeros_like(xyz)
    for index, (vertices, faces) in enumerate(meshes_lidar):
        hits = RayScene(vertices, faces).intersect(origins[ok], directions[ok])
        closer = np.zeros(len(points), bool)
        closer[ok] = hits.hit & (hits.t < best_t[ok])
        best_t[closer] = hits.t[closer[ok]]
        moved[closer] = index
    hit = moved >= 0
    out[hit, :3] = (directions[hit] * (best_t[hit, None] + INSIDE_SURFACE_M)).astype(np.float32)
    out[hit, 3] = intensity
    new_labels = None
    if labels is not None:
        new_labels = np.asarray(labels, np.uint8).copy()
        classes = np.asarray(object_labels if object_labels is not None else [LIDARSEG_CAR] * len(meshes_lidar),
                             np.uint8)
        new_labels[hit] = classes[moved[hit]]
    return SweepInsertion(out, new_labels, moved)


def car_intensity(points: np.ndarray, is_car: np.ndarray) -> float:
    """Median intensity of the sweep's real car returns (``is_car``: (N,) bool), or the default without any."""
    values = np.asarray(points)[np.asarray(is_car, bool), 3]
    return float(np.median(values)) if len(values) >= 20 else DEFAULT_CAR_INTENSITY


@dataclass(frozen=True)
class SampleSweep:
    """A sample's keyframe sweep with its placed objects in it.

    Attributes:
        sweep: the new points (and labels).
        num_lidar_pts: (n_objects,) points inside each placed object's box.
        lost_pts: source annotation token -> how many of its box's points now lie on a placed object.
    """

    sweep: SweepInsertion
    num_lidar_pts: list[int]
    lost_pts: dict[str, int]


def insert_placements_into_sweep(points: np.ndarray, labels: np.ndarray | None, T_global_from_lidar: np.ndarray,
                                 placements: Sequence, assets: Sequence, boxes: Sequence,
                                 class_index: dict[str, int]) -> SampleSweep:
    """Put placed assets (``Placement.T_global_from_object``, global frame) into a sweep; recount the boxes.

    Args:
        points: (N, 5) the sweep; labels: its lidarseg labels or None.
        placements, assets: the placed objects and their meshes.
        boxes: the sample's annotated boxes (global frame): cars among them give the moved points'
            intensity (without lidarseg), and they lose the points that now hit a placed object.
        class_index: nuScenes category name -> lidarseg class index (``category.index``).
    """
    from streetaug.placement.rules import points_in_box, points_in_boxes

    T_lidar_from_global = invert_transform(T_global_from_lidar)
    xyz_global = transform_points(T_global_from_lidar, np.asarray(points, np.float64)[:, :3])
    if labels is not None:
        is_car = np.asarray(labels) == LIDARSEG_CAR
    else:
        is_car = points_in_boxes(xyz_global, [b for b in boxes if b.category == "vehicle.car"])
    meshes = [(transform_points(T_lidar_from_global @ p.T_global_from_object, a.vertices), a.faces)
              for p, a in zip(placements, assets)]
    sweep = insert_into_sweep(points, meshes, labels, [class_index.get(a.category, LIDARSEG_CAR) for a in assets],
                              car_intensity(points, is_car))
    moved = xyz_global[sweep.moved >= 0]
    lost = {b.token: n for b in boxes if b.token and (n := int(np.count_nonzero(points_in_box(moved, b))))}
    new_global = transform_points(T_global_from_lidar, sweep.points[:, :3].astype(np.float64))
    counts = [int(np.count_nonzero(points_in_box(new_global, p.box))) for p in placements]
    return SampleSweep(sweep, counts, lost)
