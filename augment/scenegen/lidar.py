"""LiDAR + lidarseg simulation for the generated streets (a nuScenes-like 32-beam LIDAR_TOP).

The sensor frame follows nuScenes' LIDAR_TOP: x = right, y = forward, z = up (a -90 deg yaw from
the ego frame), mounted ~1.84 m above the ground.  Points are written as float32 x 5
(x, y, z, intensity, ring) in the sensor frame; labels are nuScenes-lidarseg uint8 class indices.
Like a nuScenes sweep, every beam is stored, firing after firing (all rings of one azimuth, then the
next azimuth); a beam without a return sits at the sensor's position (the origin: the simulated sensor
does not move during the sweep) with intensity 0 and lidarseg class 0 (noise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from streetaug.augment.core import check_shape, invert_transform, make_transform, transform_points, yaw_to_quat
from streetaug.augment.core.raycast import RayScene
from streetaug.datasets.sample import Box

from .street import StreetScene

LIDAR_TRANSLATION_EGO = (0.943713, 0.0, 1.84023)
LIDAR_ROTATION_EGO = tuple(yaw_to_quat(-np.pi / 2))  # sensor x = ego -y (right), sensor y = ego x
N_RINGS = 32
ELEVATION_RANGE_DEG = (-30.67, 10.67)
N_AZIMUTH = 1000
MAX_RANGE_M = 70.0
MIN_RANGE_M = 1.0
RANGE_NOISE_M = 0.01


@dataclass(frozen=True)
class LidarScan:
    """One simulated sweep.

    Attributes:
        points_sensor: (N, 3) float64 points in the LIDAR_TOP frame, metres.
        intensity: (N,) float32 0..255 (0: no return).
        ring: (N,) int64 beam index 0 (lowest) .. 31.
        labels: (N,) uint8 nuScenes-lidarseg class index (0, noise: no return).
        face: (N,) int64 index of the scene triangle hit, -1 for no return.
        object_index: (N,) int64 index into ``scene.objects`` of the hit object, -1 for background or no return.
    N = N_RINGS x N_AZIMUTH, firing after firing (see the module doc).
    """

    points_sensor: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray
    labels: np.ndarray
    face: np.ndarray
    object_index: np.ndarray

    def to_pcd_bin(self) -> bytes:
        """nuScenes ``.pcd.bin`` bytes: float32 (x, y, z, intensity, ring) per point."""
        data = np.c_[self.points_sensor, self.intensity, self.ring].astype(np.float32)
        return data.tobytes()


def T_ego_from_lidar() -> np.ndarray:
    """(4, 4) LIDAR_TOP sensor -> ego transform used by the generated scenes."""
    return make_transform(np.asarray(LIDAR_ROTATION_EGO), LIDAR_TRANSLATION_EGO)


def beam_directions_sensor() -> tuple[np.ndarray, np.ndarray]:
    """Unit ray directions (N_RINGS * N_AZIMUTH, 3) in the sensor frame and their ring index (N,)."""
    el = np.radians(np.linspace(*ELEVATION_RANGE_DEG, N_RINGS))
    az = 2 * np.pi * np.arange(N_AZIMUTH) / N_AZIMUTH
    EL, AZ = np.meshgrid(el, az, indexing="ij")
    # azimuth measured from sensor +y (forward) clockwise towards +x (right), like a spinning head
    d = np.stack([np.cos(EL) * np.sin(AZ), np.cos(EL) * np.cos(AZ), np.sin(EL)], axis=-1).reshape(-1, 3)
    ring = np.repeat(np.arange(N_RINGS), N_AZIMUTH)
    return d, ring


def simulate_lidar(scene: StreetScene, T_global_from_lidar: np.ndarray, seed: int = 0,
                   rays: RayScene | None = None) -> LidarScan:
    """Cast every beam of the sensor posed by ``T_global_from_lidar`` (4, 4) into the scene."""
    check_shape(T_global_from_lidar, (4, 4), "T_global_from_lidar")
    rays = rays or RayScene(scene.vertices_global, scene.faces)
    d_sensor, ring = beam_directions_sensor()
    d_global = d_sensor @ T_global_from_lidar[:3, :3].T
    origin = np.tile(T_global_from_lidar[:3, 3], (len(d_global), 1))
    hits = rays.intersect(origin, d_global)
    keep = hits.hit & (hits.t < MAX_RANGE_M) & (hits.t > MIN_RANGE_M)
    rng = np.random.default_rng(seed)
    r = hits.t[keep] + rng.normal(0.0, RANGE_NOISE_M, keep.sum())
    face_kept = hits.face[keep]
    n = scene.face_normals_global[face_kept]
    cos = np.abs(np.einsum("ij,ij->i", n, d_global[keep]))
    refl = np.array([m.lidar_reflectivity for m in scene.materials])[scene.face_material[face_kept]]
    # every beam, returned or not (empty: at the sensor, intensity 0, class 0, no face, no object)
    points_sensor = np.zeros((len(d_sensor), 3))
    points_sensor[keep] = d_sensor[keep] * r[:, None]
    intensity = np.zeros(len(d_sensor), np.float32)
    intensity[keep] = np.clip(np.round(255.0 * refl * (0.3 + 0.7 * cos) * np.exp(-r / 150.0)), 1, 255)
    face = np.full(len(d_sensor), -1, np.int64)
    face[keep] = face_kept
    labels = np.zeros(len(d_sensor), np.uint8)
    labels[keep] = scene.face_label[face_kept]
    object_index = np.full(len(d_sensor), -1, np.int64)
    object_index[keep] = scene.face_object[face_kept]
    firing_order = np.arange(len(d_sensor)).reshape(N_RINGS, N_AZIMUTH).T.ravel()  # ring-major -> firing-major
    return LidarScan(
        points_sensor=points_sensor[firing_order],
        intensity=intensity[firing_order],
        ring=ring[firing_order],
        labels=labels[firing_order],
        face=face[firing_order],
        object_index=object_index[firing_order],
    )


def points_in_box(box: Box, points_global: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
    """(N,) bool: which global points (N, 3) lie inside the box (grown by ``margin_m`` on every side)."""
    p_box = transform_points(invert_transform(box.T_global_from_box), points_global)
    half = np.array([box.wlh[1], box.wlh[0], box.wlh[2]]) / 2 + margin_m
    return np.all(np.abs(p_box) <= half, axis=1)
