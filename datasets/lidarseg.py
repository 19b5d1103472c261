"""Pure readers for nuScenes LiDAR point files and nuScenes-lidarseg label files.

File formats (no header in either):

* ``*.pcd.bin``: float32 little-endian, 5 values per point: x, y, z (metres, LiDAR sensor frame),
  intensity, ring index.  The file size is therefore a multiple of 20 bytes.
* ``*_lidarseg.bin``: one uint8 class index per point, same order as the point file.  Class
  indices follow the nuScenes ``category.index`` (e.g. 17 = vehicle.car, 24 = flat.driveable_surface,
  31 = vehicle.ego, 0 = noise; :mod:`streetaug.datasets.nuscenes_format`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import DatasetError

LIDAR_VALUES_PER_POINT = 5
LIDAR_BYTES_PER_POINT = LIDAR_VALUES_PER_POINT * 4


def read_lidar_points(path: str | Path) -> np.ndarray:
    """Read a nuScenes ``.pcd.bin`` sweep.

    Returns:
        (N, 5) float32: x, y, z (LiDAR sensor frame, metres), intensity, ring index.

    Raises:
        DatasetError: the file is missing, its size is not a multiple of 20 bytes (truncated), or a point
            holds NaN or Inf.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: LiDAR file not found (expected a nuScenes .pcd.bin sweep)")
    size = path.stat().st_size
    if size % LIDAR_BYTES_PER_POINT != 0:
        raise DatasetError(
            f"{path}: LiDAR file has {size} bytes, not a multiple of {LIDAR_BYTES_PER_POINT} "
            f"(float32 x {LIDAR_VALUES_PER_POINT} per point); the file is truncated or not a .pcd.bin"
        )
    points = np.fromfile(path, dtype="<f4").reshape(-1, LIDAR_VALUES_PER_POINT)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise DatasetError(
            f"{path}: {int(bad.sum())} of {len(points)} points are non-finite (NaN or Inf in x, y, z, intensity "
            "or ring); the sweep is corrupt"
        )
    return points.astype(np.float32, copy=False)


def read_lidarseg_labels(path: str | Path, num_points: int | None = None) -> np.ndarray:
    """Read a nuScenes-lidarseg ``_lidarseg.bin`` file.

    Args:
        path: the label file.
        num_points: if given, the number of points of the matching sweep; a different label count
            raises.

    Returns:
        (N,) uint8 class indices (nuScenes ``category.index``), one per LiDAR point.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: lidarseg label file not found")
    labels = np.fromfile(path, dtype=np.uint8)
    if num_points is not None and labels.shape[0] != num_points:
        raise DatasetError(
            f"{path}: lidarseg file has {labels.shape[0]} labels but the LiDAR sweep has {num_points} "
            "points; the label file does not belong to this sweep or is truncated"
        )
    return labels
