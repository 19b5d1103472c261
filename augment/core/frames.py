"""Frames and poses: quaternions ``[w, x, y, z]``, 4x4 rigid transforms ``T_a_from_b``, object poses.

Frames (all right-handed, metres)::

    camera (OpenCV)            ego / object (nuScenes)         global (map of log.location)
        z forward                  z up                            z up
       /                           |  x forward                    |  y north
      o---- x right                | /                             | /
      |                    y left--o                               o---- x east
      y down

* Transforms are 4x4 homogeneous matrices named ``T_a_from_b``; chains read right to left:
  ``p_cam = T_cam_from_ego @ T_ego_from_global @ p_global``.
* Quaternions are ``[w, x, y, z]`` (pyquaternion order).
* Object frame (assets after loading, nuScenes box frame): x = front, y = left, z = up,
  origin at the bottom centre of the box.  A nuScenes box ``wlh`` is (w along y, l along x, h along z).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from pyquaternion import Quaternion

from .errors import ConventionError, check_shape


def quat_to_rotation(q_wxyz: Sequence[float]) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` -> 3x3 rotation matrix (normalises the quaternion)."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    check_shape(q, (4,), "quaternion [w, x, y, z]")
    if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
        raise ConventionError(f"quaternion [w, x, y, z] must be finite and non-zero, got {q.tolist()}")
    return Quaternion(q / np.linalg.norm(q)).rotation_matrix


def rotation_to_quat(R: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix -> unit quaternion ``[w, x, y, z]`` with w >= 0."""
    check_shape(R, (3, 3), "rotation matrix")
    q = Quaternion(matrix=np.asarray(R, dtype=np.float64), atol=1e-6, rtol=1e-6)
    q = np.array([q.w, q.x, q.y, q.z])
    return q if q[0] >= 0 else -q


def yaw_to_quat(yaw_rad: float) -> np.ndarray:
    """Rotation by ``yaw_rad`` about +z (counter-clockwise seen from above) as ``[w, x, y, z]``."""
    return np.array([np.cos(yaw_rad / 2), 0.0, 0.0, np.sin(yaw_rad / 2)])


def quat_to_yaw(q_wxyz: Sequence[float]) -> float:
    """Heading (rad) of the rotated +x axis in the xy-plane, measured from +x towards +y."""
    x_axis = quat_to_rotation(q_wxyz)[:, 0]
    return float(np.arctan2(x_axis[1], x_axis[0]))


def make_transform(rotation: np.ndarray | Sequence[float], translation: Sequence[float]) -> np.ndarray:
    """4x4 transform from a 3x3 rotation matrix or a ``[w, x, y, z]`` quaternion, and a translation."""
    R = np.asarray(rotation, dtype=np.float64)
    if R.shape == (4,):
        R = quat_to_rotation(R)
    check_shape(R, (3, 3), "rotation")
    t = np.asarray(translation, dtype=np.float64)
    check_shape(t, (3,), "translation")
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert_transform(T_a_from_b: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform: returns ``T_b_from_a``."""
    check_shape(T_a_from_b, (4, 4), "transform")
    R = T_a_from_b[:3, :3]
    t = T_a_from_b[:3, 3]
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ t
    return T


def transform_points(T_a_from_b: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """Apply ``T_a_from_b`` (4, 4) to points (N, 3) in frame b; returns points (N, 3) in frame a."""
    check_shape(T_a_from_b, (4, 4), "transform")
    points_b = np.asarray(points_b, dtype=np.float64)
    check_shape(points_b, ("N", 3), "points")
    return points_b @ T_a_from_b[:3, :3].T + T_a_from_b[:3, 3]


def rotate_vectors(T_a_from_b: np.ndarray, vectors_b: np.ndarray) -> np.ndarray:
    """Rotate direction vectors (N, 3) from frame b to frame a (translation ignored)."""
    vectors_b = np.asarray(vectors_b, dtype=np.float64)
    check_shape(vectors_b, ("N", 3), "vectors")
    return vectors_b @ np.asarray(T_a_from_b)[:3, :3].T


def pose_camera_to_transform(x: float, y: float, z: float, yaw_deg: float) -> np.ndarray:
    """``--pose-camera X,Y,Z,YAW_DEG`` -> ``T_cam_from_object`` (4, 4).

    (X, Y, Z) is the bottom centre of the object's box in the camera frame; the object's up (+z)
    is the camera's -y; yaw 0 puts the object's front (+x) along camera +z, +90 deg along camera +x.
    """
    th = np.radians(yaw_deg)
    front = np.array([np.sin(th), 0.0, np.cos(th)])
    up = np.array([0.0, -1.0, 0.0])
    left = np.cross(up, front)
    return make_transform(np.stack([front, left, up], axis=1), [x, y, z])


def transform_to_pose_camera(T_cam_from_object: np.ndarray) -> tuple[np.ndarray, float]:
    """Inverse of :func:`pose_camera_to_transform` for the yaw: returns (origin (3,), yaw_deg).

    The yaw is that of the object's front projected onto the camera's x-z plane.
    """
    front = T_cam_from_object[:3, 0]
    return T_cam_from_object[:3, 3].copy(), float(np.degrees(np.arctan2(front[0], front[2])))
