"""Synthetic street scenes for the placement and label tests (no dataset needed).

Ego pose: yaw 30 deg at global (100, 200, 5); a straight road along ego x, |y_ego| <= 5 m, from
x_ego = -20 to 90 m; sidewalks beyond. CAM_FRONT looks along ego +x (nuScenes-like calibration).
"""

from __future__ import annotations

import numpy as np
import shapely

from streetaug.augment.core import PinholeCamera, make_transform, transform_points, yaw_to_quat
from streetaug.datasets.nuscenes_map import LaneCenterlines
from streetaug.datasets.sample import Box, CameraView, LidarSweep, Sample

EGO_YAW_RAD = np.radians(30.0)
T_GLOBAL_FROM_EGO = make_transform(yaw_to_quat(EGO_YAW_RAD), [100.0, 200.0, 5.0])
ROAD_HALF_WIDTH_M = 5.0
# camera axes in ego coordinates: x_cam = -y_ego, y_cam = -z_ego, z_cam = +x_ego
R_EGO_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
T_EGO_FROM_CAM = make_transform(R_EGO_FROM_CAM, [1.7, 0.0, 1.5])
T_EGO_FROM_LIDAR = make_transform(np.eye(3), [0.9, 0.0, 1.8])
K = np.array([[1266.0, 0.0, 800.0], [0.0, 1266.0, 450.0], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 1600, 900
CAMERA = PinholeCamera(K, WIDTH, HEIGHT)


def ego_to_global_xy(xy_ego: np.ndarray) -> np.ndarray:
    xy_ego = np.asarray(xy_ego, float).reshape(-1, 2)
    return transform_points(T_GLOBAL_FROM_EGO, np.c_[xy_ego, np.zeros(len(xy_ego))])[:, :2]


def road_polygon_global() -> shapely.Polygon:
    w = ROAD_HALF_WIDTH_M
    return shapely.Polygon(ego_to_global_xy([[-20, -w], [90, -w], [90, w], [-20, w]]))


def box_at_ego(x: float, y: float, category: str = "vehicle.car", wlh=(1.8, 4.5, 1.6), yaw_ego: float = 0.0) -> Box:
    """A box whose bottom centre is at ego (x, y, 0), heading yaw_ego relative to the ego."""
    c = transform_points(T_GLOBAL_FROM_EGO, np.array([[x, y, wlh[2] / 2]]))[0]
    return Box(c, np.array(wlh, float), yaw_to_quat(EGO_YAW_RAD + yaw_ego), category)


def camera_view() -> CameraView:
    return CameraView(
        channel="CAM_FRONT",
        sample_data_token="",
        image_path="",
        K=K.copy(),
        width=WIDTH,
        height=HEIGHT,
        T_ego_from_cam=T_EGO_FROM_CAM,
        T_global_from_ego=T_GLOBAL_FROM_EGO,
        timestamp_us=0,
    ).with_image(np.zeros((HEIGHT, WIDTH, 3), np.uint8))


def ground_grid_ego(spacing_m: float = 0.5, x_range=(-10.0, 60.0), y_half: float = 12.0) -> np.ndarray:
    """Flat ground points (N, 3) at z_ego = 0 on a regular grid."""
    x, y = np.meshgrid(np.arange(x_range[0], x_range[1], spacing_m), np.arange(-y_half, y_half, spacing_m))
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]


def lidar_rings_ego(n_rings: int = 32, n_azimuth: int = 1800) -> np.ndarray:
    """Ground hits (N, 3, ego) of a 32-beam LiDAR at 1.8 m: rings metres apart far away."""
    elev = np.radians(np.linspace(-30.0, -1.5, n_rings))
    rng_m = 1.8 / np.tan(-elev)
    az = np.linspace(-np.pi, np.pi, n_azimuth, endpoint=False)
    r, a = np.meshgrid(rng_m, az)
    pts = np.c_[0.9 + (r * np.cos(a)).ravel(), (r * np.sin(a)).ravel(), np.zeros(r.size)]
    return pts[np.hypot(pts[:, 0], pts[:, 1]) < 70]


def lidar_sweep(points_ego: np.ndarray, labels: np.ndarray | None = None) -> LidarSweep:
    T_lidar_from_ego = np.linalg.inv(T_EGO_FROM_LIDAR)
    return LidarSweep(
        points_sensor=transform_points(T_lidar_from_ego, points_ego),
        intensity=np.zeros(len(points_ego), np.float32),
        T_ego_from_lidar=T_EGO_FROM_LIDAR,
        T_global_from_ego=T_GLOBAL_FROM_EGO,
        timestamp_us=0,
        labels=None if labels is None else np.asarray(labels, np.uint8),
    )


def lane_ego(y: float, heading_ego: float = 0.0, x_range=(-20.0, 90.0), resolution_m: float = 0.5) -> np.ndarray:
    """Samples (N, 3) = (global x, global y, heading rad) of a straight lane centre line through ego
    (x, y) for x in ``x_range``, heading ``heading_ego`` relative to the ego (0 = along ego +x)."""
    x = np.arange(x_range[0], x_range[1], resolution_m)
    xy_ego = np.c_[x, np.full_like(x, y)]
    if heading_ego:
        c, s_ = np.cos(heading_ego), np.sin(heading_ego)
        xy_ego = np.c_[x * c, y + x * s_]
    return np.c_[ego_to_global_xy(xy_ego), np.full(len(x), EGO_YAW_RAD + heading_ego)]


def lanes_from(*centre_lines: np.ndarray) -> LaneCenterlines:
    """LaneCenterlines from centre-line samples (N_i, 3) (global x, y, heading)."""
    allp = np.concatenate(centre_lines)
    idx = np.concatenate([np.full(len(c), i) for i, c in enumerate(centre_lines)])
    heading = np.mod(allp[:, 2] + np.pi, 2 * np.pi) - np.pi
    return LaneCenterlines(allp[:, :2].copy(), heading, idx, tuple(f"lane-{i}" for i in range(len(centre_lines))))


def make_sample(boxes=(), polygons="road", lidar: LidarSweep | None = None, lanes=None) -> Sample:
    view = camera_view()
    polys = [road_polygon_global()] if polygons == "road" else polygons
    return Sample(
        token="synthetic",
        scene_name="synthetic",
        location="nowhere",
        timestamp_us=0,
        cameras={"CAM_FRONT": view},
        boxes=tuple(boxes),
        drivable_area_global=polys,
        lanes=lanes,
    ).with_lidar(lidar)
