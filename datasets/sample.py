"""Plain data objects for one dataset sample: cameras, LiDAR, boxes, drivable area.

Conventions (see :mod:`streetaug.augment.core`): transforms ``T_a_from_b`` are 4x4 float64;
quaternions ``[w, x, y, z]``; ego frame x forward / y left / z up; global frame = the map of the log's
location (x east, y north, z up); metres; timestamps in microseconds.

Objects are frozen; heavy fields (images, LiDAR) are loaded lazily through loader callables so that
building a ``Sample`` parses no image it does not need.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
import shapely

from streetaug.augment.core import (
    invert_transform,
    make_transform,
    quat_to_rotation,
    read_image_rgb,
    rotate_vectors,
    rotation_to_quat,
    transform_points,
)

from .nuscenes_map import LaneCenterlines

# nuScenes categories whose boxes count as dynamic for placement clearance.
DYNAMIC_CATEGORY_PREFIXES = ("vehicle.", "human.", "animal")


@dataclass(frozen=True)
class Box:
    """A 3D box as in a nuScenes ``sample_annotation``, in the global frame.

    Attributes:
        center: (3,) float64 box centre (gravity centre, not bottom), global frame, metres.
        wlh: (3,) float64 width (along box y), length (along box x = heading), height (along z), metres.
        rotation: (4,) float64 ``[w, x, y, z]`` rotation from the box frame to the global frame.
        category: nuScenes category name, e.g. ``vehicle.car``.
        token: the ``sample_annotation`` token ('' for boxes we create).
        attributes: the annotation's attribute names.
        instance_token: the object's ``instance`` token (the same in every keyframe; '' for boxes we create).
    """

    center: np.ndarray
    wlh: np.ndarray
    rotation: np.ndarray
    category: str
    token: str = ""
    attributes: tuple[str, ...] = ()
    instance_token: str = ""

    @property
    def is_dynamic(self) -> bool:
        return self.category.startswith(DYNAMIC_CATEGORY_PREFIXES)

    @property
    def T_global_from_box(self) -> np.ndarray:
        """Box frame (origin at the centre, x = heading, z up) -> global."""
        return make_transform(self.rotation, self.center)

    def corners(self) -> np.ndarray:
        """The 8 corners (8, 3) in the global frame; first four at the front (+x), then the back."""
        w, l, h = self.wlh
        x = np.array([1, 1, 1, 1, -1, -1, -1, -1]) * l / 2
        y = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * w / 2
        z = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * h / 2
        return transform_points(self.T_global_from_box, np.stack([x, y, z], axis=1))

    def transformed(self, T_new_from_global: np.ndarray) -> "Box":
        """The same box expressed in another frame (returns a new Box; never mutates)."""
        center = transform_points(T_new_from_global, self.center[None])[0]
        R = T_new_from_global[:3, :3] @ quat_to_rotation(self.rotation)
        return Box(center, self.wlh.copy(), rotation_to_quat(R), self.category, self.token, self.attributes,
                   self.instance_token)


@dataclass(frozen=True)
class CameraView:
    """One camera image of a sample with its calibration and pose.

    Attributes:
        channel: sensor channel, e.g. ``CAM_FRONT``.
        sample_data_token: token of the camera ``sample_data`` row ('' for non-nuScenes inputs).
        image_path: path of the image file.
        K: (3, 3) float64 intrinsics (pixel centres at integer coordinates).
        width, height: image size in pixels.
        T_ego_from_cam: (4, 4) camera (OpenCV) -> ego frame at this camera's timestamp.
        T_global_from_ego: (4, 4) ego -> global at this camera's timestamp.
        timestamp_us: capture time, microseconds since the Unix epoch (UTC).
        ego_poses_around: the ego's poses just before and just after this capture, as
            ``((dt_s, T_global_from_ego), (dt_s, T_global_from_ego))`` with ``dt_s`` relative to
            ``timestamp_us`` (before <= 0 <= after; one of them may be this capture's own pose), from
            the camera's neighbouring ``sample_data`` rows, else its keyframe neighbours; None when the
            dataset has neither (a single frame). It gives the camera's motion (motion blur).
    """

    channel: str
    sample_data_token: str
    image_path: str
    K: np.ndarray
    width: int
    height: int
    T_ego_from_cam: np.ndarray
    T_global_from_ego: np.ndarray
    timestamp_us: int
    _load_image: Callable[[], np.ndarray] = field(repr=False, compare=False, default=None)
    ego_poses_around: tuple[tuple[float, np.ndarray], tuple[float, np.ndarray]] | None = field(
        repr=False, compare=False, default=None)

    @functools.cached_property
    def image(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB, decoded on first access."""
        if self._load_image is None:
            return read_image_rgb(self.image_path)
        return self._load_image()

    def with_image(self, image: np.ndarray) -> "CameraView":
        """This view (same calibration and pose) showing ``image`` (H, W, 3) uint8 instead, e.g. a perturbed copy."""
        return replace(self, _load_image=lambda: image)

    @property
    def T_global_from_cam(self) -> np.ndarray:
        return self.T_global_from_ego @ self.T_ego_from_cam

    @property
    def T_cam_from_global(self) -> np.ndarray:
        return invert_transform(self.T_global_from_cam)

    @property
    def T_cam_from_ego(self) -> np.ndarray:
        return invert_transform(self.T_ego_from_cam)

    @property
    def ego_ground_plane_cam(self) -> tuple[np.ndarray, float]:
        """The ego's ground plane (ego z = 0) in this camera's frame as (normal (3,), offset d): n . p + d = 0."""
        T_cam_from_ego = self.T_cam_from_ego
        normal = rotate_vectors(T_cam_from_ego, np.array([[0.0, 0.0, 1.0]]))[0]
        point = transform_points(T_cam_from_ego, np.zeros((1, 3)))[0]
        return normal, float(-normal @ point)


@dataclass(frozen=True)
class LidarSweep:
    """A LiDAR sweep.

    Attributes:
        points_sensor: (N, 3) float64 points in the LiDAR sensor frame, metres.
        intensity: (N,) float32.
        T_ego_from_lidar: (4, 4) sensor -> ego at the sweep's timestamp.
        T_global_from_ego: (4, 4) ego -> global at the sweep's timestamp.
        labels: (N,) uint8 lidarseg class indices, or None when the dataset has no lidarseg.
    """

    points_sensor: np.ndarray
    intensity: np.ndarray
    T_ego_from_lidar: np.ndarray
    T_global_from_ego: np.ndarray
    timestamp_us: int
    labels: np.ndarray | None = None

    @property
    def T_global_from_lidar(self) -> np.ndarray:
        return self.T_global_from_ego @ self.T_ego_from_lidar

    def points_in(self, T_frame_from_global: np.ndarray) -> np.ndarray:
        """Points (N, 3) in any frame given by its ``T_frame_from_global``."""
        return transform_points(T_frame_from_global @ self.T_global_from_lidar, self.points_sensor)

    @property
    def points_global(self) -> np.ndarray:
        return transform_points(self.T_global_from_lidar, self.points_sensor)


@dataclass(frozen=True)
class Sample:
    """One keyframe: its cameras, LiDAR, annotated boxes and map context.

    Attributes:
        token: the nuScenes ``sample`` token.
        scene_name: e.g. ``scene-0061``.
        location: ``log.location``, e.g. ``singapore-onenorth`` (the global frame's map).
        timestamp_us: keyframe time, microseconds since the Unix epoch (UTC).
        cameras: channel -> CameraView (images load lazily).
        boxes: annotated boxes in the global frame.
        drivable_area_global: list of shapely (Multi)Polygons in global x/y, or None when no map.
        load_lidar: callable returning the LiDAR sweep (or None when the sample has none).
        lanes: lane centre lines of the map, or None when the map has no lanes.
        map_source: which map gave ``drivable_area_global``: ``"expansion"`` (the map expansion JSON),
            ``"semantic-prior raster"`` (the base release's ``map.json`` PNG, vectorised; no lanes), or None.
        walkways_global, ped_crossings_global: the map expansion's ``walkway`` / ``ped_crossing`` (Multi)Polygons
            in global x/y (empty without such a map layer).
    """

    token: str
    scene_name: str
    location: str
    timestamp_us: int
    cameras: dict[str, CameraView]
    boxes: tuple[Box, ...]
    drivable_area_global: list[shapely.Geometry] | None = None
    _load_lidar: Callable[[], LidarSweep | None] = field(repr=False, compare=False, default=None)
    lanes: LaneCenterlines | None = field(repr=False, compare=False, default=None)
    map_source: str | None = None
    walkways_global: tuple[shapely.Geometry, ...] = ()
    ped_crossings_global: tuple[shapely.Geometry, ...] = ()

    @functools.cached_property
    def lidar(self) -> LidarSweep | None:
        return None if self._load_lidar is None else self._load_lidar()

    def with_lidar(self, lidar: LidarSweep | None, **changes: Any) -> "Sample":
        """This sample with ``lidar`` as its sweep (None: no LiDAR), and the other ``changes`` to its fields."""
        return replace(self, _load_lidar=lambda: lidar, **changes)

    def evolve(self, **changes: Any) -> "Sample":
        """This sample with ``changes`` to its fields, sharing its LiDAR sweep (read once, by whichever asks first)."""
        return replace(self, _load_lidar=lambda: self.lidar, **changes)
