"""Every geometric and radiometric convention of streetaug, in one place.

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
* Pixel centres sit at integer coordinates: pixel (i, j) is the point u = i, v = j
  (OpenCV / nuScenes intrinsics), so a point on the camera's +z axis projects to (cx, cy).
* Object frame (assets after loading, nuScenes box frame): x = front, y = left, z = up,
  origin at the bottom centre of the box.  A nuScenes box ``wlh`` is (w along y, l along x, h along z).
* Camera-frame equirectangular map (``envmap_camera.exr``): direction ``d`` has
  ``lon = atan2(dx, dz)`` (0 = ahead, +90 deg = right) and ``lat = asin(-dy)`` (+90 deg = image up).
  Continuous map coordinates (u, v), 0 at the left/top edge, give ``lon = (u/W - 0.5) 2 pi`` and
  ``lat = (0.5 - v/H) pi``; pixel (i, j) has its centre at u = i + 0.5, v = j + 0.5.
* World (z-up) equirectangular map, used for sky domes: ``lon = atan2(dy, dx)`` (0 = +x, +90 deg = +y),
  ``lat = asin(dz)``; same pixel mapping as above.
* Camera response (LDR <-> linear HDR): ``LDR = softclip(clamp(HDR * 2^EV, 0)^(1/2.2))`` with the
  paper's soft clip, tau = 0.95.  LDR values are floats in [0, 1] (divide uint8 by 255).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from pyquaternion import Quaternion

GAMMA = 2.2
SOFTCLIP_TAU = 0.95


class ConventionError(ValueError):
    """Raised when an array does not have the shape or values a convention requires."""


def check_shape(x: np.ndarray, shape: Sequence[int | str], name: str) -> None:
    """Raise a clear error unless ``x`` has ``shape``; strings in ``shape`` match any size.

    Example: ``check_shape(points, ("N", 3), "points_ego")``.
    """
    actual = tuple(np.shape(x))
    ok = len(actual) == len(shape) and all(
        isinstance(want, str) or want == got for want, got in zip(shape, actual)
    )
    if not ok:
        want = "(" + ", ".join(str(s) for s in shape) + ")"
        raise ConventionError(f"{name}: expected shape {want}, got {actual}")


# ----------------------------------------------------------------------------- transforms


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


# ----------------------------------------------------------------------------- pinhole camera


def project_points(K: np.ndarray, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project camera-frame points (N, 3) with intrinsics K (3, 3).

    Returns:
        uv: (N, 2) float64 pixel coordinates (pixel centres at integers).
        depth_m: (N,) camera-frame z; points with z <= 0 get uv = nan.
    """
    check_shape(K, (3, 3), "K")
    points_cam = np.asarray(points_cam, dtype=np.float64)
    check_shape(points_cam, ("N", 3), "points_cam")
    z = points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uvw = points_cam @ np.asarray(K, dtype=np.float64).T
        uv = uvw[:, :2] / uvw[:, 2:3]
    uv[z <= 1e-9] = np.nan
    return uv, z


def pixel_rays(K: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Unit camera-frame ray directions (N, 3) through pixel coordinates uv (N, 2)."""
    check_shape(K, (3, 3), "K")
    uv = np.asarray(uv, dtype=np.float64)
    check_shape(uv, ("N", 2), "uv")
    Kinv = np.linalg.inv(K)
    d = np.concatenate([uv, np.ones((len(uv), 1))], axis=1) @ Kinv.T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def unproject_depth(K: np.ndarray, uv: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """Camera-frame points (N, 3) from pixels uv (N, 2) and their z-depth (N,) in metres."""
    uv = np.asarray(uv, dtype=np.float64)
    check_shape(uv, ("N", 2), "uv")
    Kinv = np.linalg.inv(np.asarray(K, dtype=np.float64))
    rays = np.concatenate([uv, np.ones((len(uv), 1))], axis=1) @ Kinv.T  # z = 1
    return rays * np.asarray(depth_m, dtype=np.float64)[:, None]


def scale_intrinsics(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Intrinsics (3, 3) of an image resized by (sx, sy) = new size / old size.

    Pixel centres sit at integers, so a pixel coordinate maps as u' = (u + 0.5) sx - 0.5.
    """
    K = np.asarray(K, dtype=np.float64)
    check_shape(K, (3, 3), "K")
    Ks = K.copy()
    Ks[0] *= sx
    Ks[1] *= sy
    Ks[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    Ks[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return Ks


def intrinsics_from_fov(width: int, height: int, fov_x_deg: float) -> np.ndarray:
    """Pinhole K with the given horizontal field of view and the principal point at the centre."""
    if not 1.0 < fov_x_deg < 179.0:
        raise ConventionError(f"horizontal field of view must be in (1, 179) degrees, got {fov_x_deg}")
    fx = (width / 2.0) / np.tan(np.radians(fov_x_deg) / 2.0)
    return np.array([[fx, 0.0, (width - 1) / 2.0], [0.0, fx, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------- equirectangular maps


def equirect_pixel_lonlat(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (rad) of every pixel centre of an H x W map, each (H, W)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    lon = (u - 0.5) * 2.0 * np.pi
    lat = (0.5 - v) * np.pi
    return np.meshgrid(lon, lat)


def lonlat_to_uv(lon: np.ndarray, lat: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous map coordinates (u in [0, W), v in [0, H]) of longitudes/latitudes (rad)."""
    u = np.mod(np.asarray(lon) / (2.0 * np.pi) + 0.5, 1.0) * width
    v = (0.5 - np.asarray(lat) / np.pi) * height
    return u, v


def camera_dir_to_lonlat(d_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame directions (..., 3) -> (lon, lat) in rad (camera equirect convention)."""
    d = np.asarray(d_cam, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.arctan2(d[..., 0], d[..., 2]), np.arcsin(np.clip(-d[..., 1], -1.0, 1.0))


def lonlat_to_camera_dir(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(lon, lat) in rad -> unit camera-frame directions (..., 3) (camera equirect convention)."""
    c = np.cos(lat)
    return np.stack([c * np.sin(lon), -np.sin(lat), c * np.cos(lon)], axis=-1)


def world_dir_to_lonlat(d_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """z-up directions (..., 3) -> (lon, lat) in rad (world equirect convention)."""
    d = np.asarray(d_world, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.arctan2(d[..., 1], d[..., 0]), np.arcsin(np.clip(d[..., 2], -1.0, 1.0))


def lonlat_to_world_dir(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(lon, lat) in rad -> unit z-up directions (..., 3) (world equirect convention)."""
    c = np.cos(lat)
    return np.stack([c * np.cos(lon), c * np.sin(lon), np.sin(lat)], axis=-1)


def camera_envmap_directions(height: int, width: int) -> np.ndarray:
    """Unit camera-frame direction of every pixel centre of a camera-frame equirect map, (H, W, 3)."""
    lon, lat = equirect_pixel_lonlat(height, width)
    return lonlat_to_camera_dir(lon, lat)


def equirect_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle (sr) of each pixel of an H x W equirect map, (H, W); sums to 4 pi."""
    lat_edges = (0.5 - np.arange(height + 1) / height) * np.pi
    band = np.sin(lat_edges[:-1]) - np.sin(lat_edges[1:])  # (H,)
    return np.repeat((band * 2.0 * np.pi / width)[:, None], width, axis=1)


def sample_equirect(envmap: np.ndarray, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W, C) equirect map at (lon, lat) (rad); wraps in longitude.

    Returns an array of shape ``lon.shape + (C,)``.
    """
    H, W = envmap.shape[:2]
    u, v = lonlat_to_uv(lon, lat, H, W)
    x = u - 0.5
    y = np.clip(v - 0.5, 0.0, H - 1.0)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    y1 = np.minimum(y0 + 1, H - 1)
    x0w = np.mod(x0, W)
    x1w = np.mod(x0 + 1, W)
    top = envmap[y0, x0w] * (1 - fx) + envmap[y0, x1w] * fx
    bottom = envmap[y1, x0w] * (1 - fx) + envmap[y1, x1w] * fx
    return top * (1 - fy) + bottom * fy


# ----------------------------------------------------------------------------- camera response


def softclip(x: np.ndarray, tau: float = SOFTCLIP_TAU) -> np.ndarray:
    """The paper's soft clip: identity up to tau, then an exponential shoulder towards 1."""
    x = np.asarray(x, dtype=np.float64)
    shoulder = 1.0 - (1.0 - tau) * np.exp(-(np.maximum(x, tau) - tau) / (1.0 - tau))
    return np.where(x <= tau, x, shoulder)


def inverse_softclip(y: np.ndarray, tau: float = SOFTCLIP_TAU) -> np.ndarray:
    """Inverse of :func:`softclip` on [0, 1); values >= 1 map to a large finite number."""
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0 - 1e-6)
    inv = tau - (1.0 - tau) * np.log(np.maximum((1.0 - y) / (1.0 - tau), 1e-12))
    return np.where(y <= tau, y, inv)


def hdr_to_ldr(hdr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Linear HDR radiance -> LDR floats in [0, 1] with the camera response of the contract."""
    x = np.clip(np.asarray(hdr, dtype=np.float64) * 2.0**ev, 0.0, None)
    return softclip(x ** (1.0 / GAMMA))


def ldr_to_hdr(ldr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """LDR floats in [0, 1] -> linear HDR radiance (inverse camera response of the contract)."""
    return inverse_softclip(ldr) ** GAMMA / 2.0**ev


def ldr_uint8_to_hdr(image: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """uint8 (H, W, 3) image -> float32 linear HDR (H, W, 3)."""
    return ldr_to_hdr(np.asarray(image, dtype=np.float64) / 255.0, ev).astype(np.float32)


def hdr_to_ldr_uint8(hdr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Linear HDR (H, W, 3) -> uint8 image with the contract's camera response (rounded)."""
    return np.clip(np.round(hdr_to_ldr(hdr, ev) * 255.0), 0, 255).astype(np.uint8)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (..., 3) -> (...)."""
    rgb = np.asarray(rgb)
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


# ----------------------------------------------------------------------------- object poses in the camera


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
