"""nuScenes data in and out: the reader (tables, cameras, LiDAR, lidarseg, boxes, map), the writer of augmented
datasets, and the plain data objects between them (``Sample``, ``CameraView``, ``LidarSweep``, ``Box``).

The fixed content of the format (category names = lidarseg class ids, attributes, visibility bins, tokens)
lives once in :mod:`.nuscenes_format`. Imports only the core; needs no devkit.
"""

from .bundled import BUNDLED_VERSION, bundled_dataroot
from .errors import DatasetError
from .lidarseg import read_lidar_points, read_lidarseg_labels
from .nuscenes import NuScenesReader
from .nuscenes_map import LaneCenterlines, read_drivable_area, read_lanes
from .nuscenes_writer import InsertedObject, link_source, write_augmented_tables
from .sample import Box, CameraView, LidarSweep, Sample

__all__ = [
    "BUNDLED_VERSION", "Box", "CameraView", "DatasetError", "InsertedObject", "LaneCenterlines", "LidarSweep",
    "NuScenesReader", "Sample", "bundled_dataroot", "link_source", "read_drivable_area", "read_lanes",
    "read_lidar_points", "read_lidarseg_labels", "write_augmented_tables",
]
