"""Inserted objects in the LiDAR sweep, so the LiDAR agrees with the augmented images and the boxes.

nuScenes stores only a sweep's returns. A beam whose return lies behind an inserted object (the road,
a wall, a car further away) would now have returned from the object: the point moves along its beam
onto the object's surface (first hit; 1 mm inside), keeps its ring index, takes the intensity typical of this
sweep's real cars and, with lidarseg, the object's class. Points in front of the object are unchanged.
Beams that returned nothing can hit an inserted object too. nuScenes keeps them in the sweep: the file
lists every firing of the spinning sensor (all rings, in ring order, firing after firing), and a beam
without a return is stored as a point at the sensor's own position (after ego-motion compensation, within
a metre or two of the origin). Its beam is rebuilt from its ring's elevation (median over the ring's real
returns) and its firing's azimuth (the direction of the firing's real returns); where it meets an object
within the sensor's range, the point becomes a return on the object. This matters at the horizon: the
beams 1-2 deg below it reach the road only beyond ~50-80 m and mostly return nothing, yet they cross the
upper half of a car 20-40 m away. A sweep not stored in firing order (e.g. one whose empty beams were
dropped) keeps its empty beams empty.

Frames: everything in the LiDAR sensor frame (nuScenes ``.pcd.bin``: x, y, z, intensity, ring).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import Box
from streetaug.datasets.nuscenes_format import LIDARSEG_CAR
from streetaug.placement.place import Placement
from streetaug.placement.rules import points_in_box, points_in_boxes

from ..assets.asset import Asset
from ..core import check_shape, invert_transform, transform_points
from ..core.raycast import RayScene

# Moved points sit this far beyond the surface along their beam: inside the object, so that float32
# storage cannot put a return on a tight box's face outside the box (LiDAR range noise is ~2 cm).
INSIDE_SURFACE_M = 1e-3
# Intensity of moved points when the sweep has no real car to learn it from (nuScenes 0-255 scale;
# painted car bodies mostly return 5-40).
DEFAULT_CAR_INTENSITY = 15.0
NO_RETURN_RANGE_M = 2.0  # a stored point this close to the sensor is a beam that returned nothing
MAX_RANGE_M = 80.0  # an empty beam returns from an object at most this far (HDL-32E: 70-100 m)
RING_FIT_MIN_RANGE_M = 5.0  # returns this far give the rings' elevations and the firings' azimuths
MIN_RING_RETURNS = 20  # a ring's elevation needs this many of them
EMPTY_BEAM_MIN_ELEVATION_DEG = -10.0  # steeper beams return from the road within 10 m (or the ego's roof)


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
                      intensity: float = DEFAULT_CAR_INTENSITY, use_empty_beams: bool = True) -> SweepInsertion:
    """Move the returns whose beam meets an object onto that object's surface.

    Args:
        points: (N, 5) sweep (x, y, z in the LiDAR frame, intensity, ring); beams start at the origin.
        meshes_lidar: per object, (V, 3) vertices in the LiDAR frame and (F, 3) faces.
        labels: (N,) lidarseg labels of the sweep, or None.
        object_labels: lidarseg class of each object (default: vehicle.car).
        intensity: intensity given to the moved points (:func:`car_intensity`).
        use_empty_beams: also let beams without a return hit the objects (:func:`empty_beams`).
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
    empty = empty_beams(points) if use_empty_beams else None
    if empty is not None:  # beams without a return: from the sensor's position, as far as the sensor reaches
        ok = ok | empty.mask
        origins[empty.mask] = xyz[empty.mask]
        directions[empty.mask] = empty.directions
        best_t[empty.mask] = MAX_RANGE_M
    for index, (vertices, faces) in enumerate(meshes_lidar):
        hits = RayScene(vertices, faces).intersect(origins[ok], directions[ok])
        closer = np.zeros(len(points), bool)
        closer[ok] = hits.hit & (hits.t < best_t[ok])
        best_t[closer] = hits.t[closer[ok]]
        moved[closer] = index
    hit = moved >= 0
    out[hit, :3] = (origins[hit] + directions[hit] * (best_t[hit, None] + INSIDE_SURFACE_M)).astype(np.float32)
    out[hit, 3] = intensity
    new_labels = None
    if labels is not None:
        new_labels = np.asarray(labels, np.uint8).copy()
        classes = np.asarray(object_labels if object_labels is not None else [LIDARSEG_CAR] * len(meshes_lidar),
                             np.uint8)
        new_labels[hit] = classes[moved[hit]]
    return SweepInsertion(out, new_labels, moved)


@dataclass(frozen=True)
class EmptyBeams:
    """The beams of a sweep that returned nothing.

    Attributes:
        mask: (N,) bool, the points that stand for a beam without a return (stored at the sensor's position
            at that firing: the beam's origin).
        directions: (mask.sum(), 3) unit directions of those beams (LiDAR frame).
    """

    mask: np.ndarray
    directions: np.ndarray


def empty_beams(points: np.ndarray) -> EmptyBeams | None:
    """The beams without a return of a sweep stored in firing order, or None when it is not.

    Firing order: point ``i`` is ring ``i % n_rings`` of firing ``i // n_rings`` (nuScenes LIDAR_TOP: 32
    rings x ~1084 firings). Directions are taken from the sensor's position at each firing (its empty beams'
    stored position, interpolated between firings). A beam's elevation is its ring's (median of the ring's
    returns beyond ``RING_FIT_MIN_RANGE_M``; a ring with too few: the line through the others' elevations over the ring index),
    its azimuth its firing's (mean direction of the firing's real returns; a firing without any takes its
    neighbours').
    """
    points = np.asarray(points)
    check_shape(points, ("N", 5), "LiDAR points")
    n = len(points)
    ring = np.round(points[:, 4]).astype(np.int64)
    n_rings = int(ring.max()) + 1 if n else 0
    if n_rings < 2 or n % n_rings or not np.array_equal(ring, np.arange(n) % n_rings):
        return None
    xyz = points[:, :3].astype(np.float64)
    range_m = np.linalg.norm(xyz, axis=1)
    far = range_m > RING_FIT_MIN_RANGE_M
    elevation = np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))
    ring_elevation = np.full(n_rings, np.nan)
    for r in range(n_rings):
        sel = far & (ring == r)
        if sel.sum() >= MIN_RING_RETURNS:
            ring_elevation[r] = np.median(elevation[sel])
    known_ring = np.isfinite(ring_elevation)
    if known_ring.sum() < 2:
        return None
    if not known_ring.all():  # rings that (almost) never returned: the rings' fan is linear in the ring index
        slope, offset = np.polyfit(np.flatnonzero(known_ring), ring_elevation[known_ring], 1)
        ring_elevation[~known_ring] = offset + slope * np.flatnonzero(~known_ring)
    # near points of steep rings are returns from the ego car's roof, not empty beams
    shallow = ring_elevation > np.radians(EMPTY_BEAM_MIN_ELEVATION_DEG)
    empty = (range_m < NO_RETURN_RANGE_M) & shallow[ring]
    if not empty.any():
        return None
    # the sensor's position at each firing: where its empty beams are stored (ego motion over the sweep)
    firing = np.arange(n) // n_rings
    n_firings = n // n_rings
    known, sensor_known = _group_medians(firing[empty], xyz[empty])
    sensor = np.stack([np.interp(np.arange(n_firings), known, sensor_known[:, c]) for c in range(3)], axis=1)
    rel = xyz - sensor[firing]
    # firing azimuth: mean horizontal direction of its real returns (unit vectors: no wrap-around at +-180 deg)
    horiz = rel[:, :2] / np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1e-9)[:, None]
    per_firing = np.where(far[:, None], horiz, 0.0).reshape(n_firings, n_rings, 2).sum(axis=1)
    have = np.linalg.norm(per_firing, axis=1) > 1e-9
    if have.sum() < 2:
        return None
    angle = np.unwrap(np.arctan2(per_firing[have, 1], per_firing[have, 0]))
    firing_angle = np.interp(np.arange(n_firings), np.flatnonzero(have), angle)
    az = firing_angle[firing[empty]]
    el = ring_elevation[ring[empty]]
    directions = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    return EmptyBeams(empty, directions)


def _group_medians(groups: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``groups`` (sorted) and each one's per-column (lower) median of ``values`` (N, C)."""
    keys, counts = np.unique(groups, return_counts=True)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = np.empty((len(keys), values.shape[1]))
    for c in range(values.shape[1]):
        ordered = values[np.lexsort((values[:, c], groups)), c]
        out[:, c] = ordered[starts + (counts - 1) // 2]
    return keys, out


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
                                 placements: Sequence[Placement], assets: Sequence[Asset], boxes: Sequence[Box],
                                 class_index: dict[str, int], use_empty_beams: bool = True) -> SampleSweep:
    """Put placed assets (``Placement.T_global_from_object``, global frame) into a sweep; recount the boxes.

    Args:
        points: (N, 5) the sweep; labels: its lidarseg labels or None.
        placements, assets: the placed objects and their meshes.
        boxes: the sample's annotated boxes (global frame): cars among them give the moved points'
            intensity (without lidarseg), and they lose the points that now hit a placed object.
        class_index: nuScenes category name -> lidarseg class index (``category.index``).
        use_empty_beams: see :func:`insert_into_sweep`.
    """
    T_lidar_from_global = invert_transform(T_global_from_lidar)
    xyz_global = transform_points(T_global_from_lidar, np.asarray(points, np.float64)[:, :3])
    if labels is not None:
        is_car = np.asarray(labels) == LIDARSEG_CAR
    else:
        is_car = points_in_boxes(xyz_global, [b for b in boxes if b.category == "vehicle.car"])
    meshes = [(transform_points(T_lidar_from_global @ p.T_global_from_object, a.vertices), a.faces)
              for p, a in zip(placements, assets)]
    sweep = insert_into_sweep(points, meshes, labels, [class_index.get(a.category, LIDARSEG_CAR) for a in assets],
                              car_intensity(points, is_car), use_empty_beams)
    hit = sweep.moved >= 0
    moved = xyz_global[hit]  # where the moved points were
    lost = {b.token: n for b in boxes if b.token and (n := int(np.count_nonzero(points_in_box(moved, b))))}
    new_global = xyz_global.copy()  # only the moved points changed
    new_global[hit] = transform_points(T_global_from_lidar, sweep.points[hit, :3].astype(np.float64))
    counts = [int(np.count_nonzero(points_in_box(new_global, p.box))) for p in placements]
    return SampleSweep(sweep, counts, lost)
