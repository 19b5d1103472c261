"""The pinhole camera: projection (points and 3D boxes), pixel rays, intrinsics.

Convention: pixel centres sit at integer coordinates, pixel (i, j) is the point u = i, v = j
(OpenCV / nuScenes intrinsics), so a point on the camera's +z axis projects to (cx, cy).
Camera frame: OpenCV, x right, y down, z forward, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConventionError, check_shape


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


# Box corners in units of the half size (x, y, z), the first four on the bottom face.
_UNIT_BOX_CORNERS = np.array([[1, 1, -1], [1, -1, -1], [-1, -1, -1], [-1, 1, -1],
                              [1, 1, 1], [1, -1, 1], [-1, -1, 1], [-1, 1, 1]], dtype=float)


def box_corners_cam(T_cam_from_box: np.ndarray, wlh: np.ndarray) -> np.ndarray:
    """(8, 3) corners of a centred box (nuScenes ``wlh``, x along its length) in the camera frame (metres);
    the first four on the bottom face."""
    half = 0.5 * np.array([wlh[1], wlh[0], wlh[2]], dtype=float)  # (length, width, height) along x, y, z
    T = np.asarray(T_cam_from_box, dtype=float)
    return (_UNIT_BOX_CORNERS * half) @ T[:3, :3].T + T[:3, 3]


def box_rect_px(K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray) -> np.ndarray:
    """(4,) x0, y0, x1, y1: the 2D bounding rectangle of the box's corners in front of the camera (NaN when
    none is; a box across the camera plane gets the rectangle of its front corners only)."""
    uv, _ = project_points(K, box_corners_cam(T_cam_from_box, wlh))
    if np.isnan(uv).all():
        return np.full(4, np.nan)
    return np.array([np.nanmin(uv[:, 0]), np.nanmin(uv[:, 1]), np.nanmax(uv[:, 0]), np.nanmax(uv[:, 1])])


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


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """An undistorted pinhole camera: intrinsics and image size.

    Attributes:
        K: (3, 3) float64 intrinsics (pixel centres at integer coordinates).
        width, height: image size in pixels.
    """

    K: np.ndarray
    width: int
    height: int

    def __post_init__(self) -> None:
        K = np.array(self.K, dtype=np.float64)
        check_shape(K, (3, 3), "K")
        if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
            raise ConventionError(f"K: focal lengths must be finite and positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        if int(self.width) < 1 or int(self.height) < 1:
            raise ConventionError(f"image size must be positive, got {self.width} x {self.height}")
        K.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @classmethod
    def from_fov(cls, width: int, height: int, fov_x_deg: float) -> "PinholeCamera":
        """A camera with the given horizontal field of view and the principal point at the image centre."""
        return cls(intrinsics_from_fov(width, height, fov_x_deg), width, height)

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width), the shape of an image of this camera."""
        return self.height, self.width

    def pixel_grid(self) -> np.ndarray:
        """(H, W, 2) float64 pixel coordinates (u, v) of every pixel centre."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return np.stack([u, v], axis=-1)

    def rays(self, uv: np.ndarray | None = None, unit: bool = True) -> np.ndarray:
        """Camera-frame ray directions through pixels.

        Args:
            uv: (N, 2) pixel coordinates, or None for every pixel centre.
            unit: unit-length directions if True, else scaled to z = 1 (so ``ray * depth_m`` is the point).

        Returns:
            (N, 3) float64, or (H, W, 3) when ``uv`` is None.
        """
        grid = uv is None
        uv = self.pixel_grid().reshape(-1, 2) if grid else np.asarray(uv, dtype=np.float64)
        check_shape(uv, ("N", 2), "uv")
        d = np.concatenate([uv, np.ones((len(uv), 1))], axis=1) @ np.linalg.inv(self.K).T
        if unit:
            d = d / np.linalg.norm(d, axis=1, keepdims=True)
        return d.reshape(self.height, self.width, 3) if grid else d

    def project(self, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project camera-frame points (N, 3): returns uv (N, 2) (nan behind the camera) and z (N,)."""
        return project_points(self.K, points_cam)

    def unproject(self, uv: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) from pixels uv (N, 2) and their z-depth (N,) in metres."""
        return unproject_depth(self.K, uv, depth_m)

    def scaled(self, sx: float, sy: float | None = None) -> "PinholeCamera":
        """The camera of this image resized by (sx, sy) = new size / old size (sy defaults to sx)."""
        sy = sx if sy is None else sy
        return PinholeCamera(scale_intrinsics(self.K, sx, sy), max(1, round(self.width * sx)),
                             max(1, round(self.height * sy)))

    def resized(self, width: int, height: int) -> "PinholeCamera":
        """The camera of this image resized to exactly ``width`` x ``height`` pixels."""
        return PinholeCamera(scale_intrinsics(self.K, width / self.width, height / self.height), width, height)
