"""What placement reads of one camera view of a sample, gathered once: boxes, LiDAR obstacles, ground, depth.

The scene depth is the renderer's (:func:`scene_depth`): placement's occlusion test and the render's depth
test see the same surfaces.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from streetaug.augment.core import PinholeCamera
from streetaug.augment.core.depth import densify_lidar_depth
from streetaug.datasets.nuscenes_format import LIDARSEG_GROUND, LIDARSEG_NON_DRIVABLE, VEHICLE_PARKED
from streetaug.datasets.nuscenes_map import LaneCenterlines
from streetaug.datasets.sample import CameraView, Sample

from .class_rules import ClassRule, ClassRules
from .config import PlacementConfig
from .drivable import DrivableArea
from .ground import LocalGroundFitter
from .parking import ParkingStyle, parked_gap_m, parking_style
from .rules import box_bottoms, box_footprints, points_in_boxes
from .zones import SurfaceZones, surface_zones


def scene_depth(sample: Sample, view: CameraView) -> np.ndarray:
    """The scene depth (H, W) float32 of ``view`` (camera z, metres, inf = unknown), as the renderer sees it.

    The sample's LiDAR densified in the camera with the ego's ground plane where it leaves holes below
    the horizon (:func:`streetaug.augment.core.depth.densify_lidar_depth`; the plane alone without LiDAR).
    """
    lidar = sample.lidar
    points_cam = np.zeros((0, 3)) if lidar is None else lidar.points_in(view.T_cam_from_global)
    return densify_lidar_depth(points_cam, view.K, view.width, view.height, ground_fill=view.ego_ground_plane_cam)


@dataclass(frozen=True, eq=False)
class PlacementScene:
    """What the rules read of one camera view of a sample, gathered once for all objects.

    Attributes:
        sample, view: the sample and the camera being augmented.
        config: the thresholds.
        drivable: where the road is.
        box_footprints_xy: (B, 4, 2) annotated boxes' footprints (global x/y); ``box_is_dynamic`` (B,) bool.
        obstacle_points: (P, 3) LiDAR points (global) in no annotated box (grown by 0.1 m).
        non_drivable_xy: (Q, 2) global x/y of non-drivable lidarseg points; ``non_ground_xy`` (R, 2) those of
            them that are not ground either (no ``flat.*`` class: what blocks a sidewalk).
        ground: the local ground plane fitter.
        given_depth_m: (H, W) the caller's scene depth, or None to compute :func:`scene_depth` when needed.
        class_rules: the rule table whose categories say which annotated boxes are of a class (for
            :meth:`parking_style`), or None (no parking styles).
        box_is_parked: (B,) bool the annotated boxes labelled ``vehicle.parked`` (see :meth:`beside_parked`).
    """

    sample: Sample
    view: CameraView
    config: PlacementConfig
    drivable: DrivableArea
    box_footprints_xy: np.ndarray
    box_is_dynamic: np.ndarray
    obstacle_points: np.ndarray
    non_drivable_xy: np.ndarray
    ground: LocalGroundFitter
    given_depth_m: np.ndarray | None = None
    non_ground_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    class_rules: ClassRules | None = None
    box_is_parked: np.ndarray | None = None

    @classmethod
    def of(cls, sample: Sample, view: CameraView, config: PlacementConfig, drivable: DrivableArea,
           depth_m: np.ndarray | None, class_rules: ClassRules | None = None) -> "PlacementScene":
        """Gather the boxes, the LiDAR obstacles, the lidarseg classes and the ground of ``sample``."""
        boxes = list(sample.boxes)
        box_dyn = np.array([b.is_dynamic for b in boxes], dtype=bool)
        lidar = sample.lidar
        obstacles, non_drivable_xy, non_ground_xy, labels = np.zeros((0, 3)), np.zeros((0, 2)), np.zeros((0, 2)), None
        if lidar is not None:
            points = lidar.points_global
            free = ~points_in_boxes(points, boxes, margin_m=0.1)
            obstacles = points[free]
            if lidar.labels is not None:
                non_drivable = np.isin(lidar.labels, LIDARSEG_NON_DRIVABLE)
                non_drivable_xy = points[non_drivable][:, :2]
                non_ground_xy = points[non_drivable & ~np.isin(lidar.labels, LIDARSEG_GROUND)][:, :2]
                labels = lidar.labels[free]
        fitter = LocalGroundFitter(obstacles if lidar is not None else None, view.T_global_from_ego, labels, config,
                                   box_bottoms([b for b in boxes if b.category.startswith("vehicle.")]))
        return cls(sample, view, config, drivable, box_footprints(boxes), box_dyn, obstacles, non_drivable_xy,
                   fitter, depth_m, non_ground_xy, class_rules,
                   np.array([VEHICLE_PARKED in b.attributes for b in boxes], dtype=bool))

    def beside_parked(self, rule: ClassRule, zone: str) -> np.ndarray:
        """(B,) bool the annotated boxes an object of ``rule`` in ``zone`` keeps only the parking gap from
        (:attr:`parked_gap_m`): for a kerb placement of a rule with ``zone_weights: scene``, the parked vehicles (they
        do not move: a car parks in the bay beside one); none otherwise."""
        if zone == "kerb" and rule.zone_weights == "scene" and self.box_is_parked is not None:
            return self.box_is_parked
        return np.zeros(len(self.box_is_dynamic), dtype=bool)

    @functools.cached_property
    def parked_gap_m(self) -> float:
        """The clearance from parked vehicles of a kerb placement (:func:`~streetaug.placement.parking.parked_gap_m`)."""
        return parked_gap_m(self.sample.boxes, self.config.static_clearance_m)

    def parking_style(self, rule: ClassRule) -> ParkingStyle | None:
        """How the sample's parked boxes of ``rule``'s class stand at the road edge
        (:func:`~streetaug.placement.parking.parking_style`); None without ``class_rules``, for a rule with fixed
        zone weights, or when none is parked."""
        if self.class_rules is None or rule.zone_weights != "scene":
            return None
        if rule.name not in self._styles:
            categories = self.class_rules.categories_of(rule.name)
            self._styles[rule.name] = parking_style(self.zones, self.sample.boxes, categories, self.camera_xy,
                                                    self.config.map_roi_m, self.config.kerb_distance_m)
        return self._styles[rule.name]

    @functools.cached_property
    def _styles(self) -> dict[str, ParkingStyle | None]:
        return {}

    @functools.cached_property
    def zones(self) -> SurfaceZones:
        """The surfaces of each zone around the camera (:func:`~streetaug.placement.zones.surface_zones`)."""
        return surface_zones(self.sample, self.view, self.drivable, self.config)

    def ground_for(self, config: PlacementConfig) -> LocalGroundFitter:
        """The ground fitter with ``config``'s fit radius (one per radius, built on first use)."""
        if config.ground_radius_m == self.config.ground_radius_m:
            return self.ground
        key = float(config.ground_radius_m)
        if key not in self._fitters:
            self._fitters[key] = self.ground.with_config(config)
        return self._fitters[key]

    @functools.cached_property
    def _fitters(self) -> dict[float, LocalGroundFitter]:
        return {}

    @functools.cached_property
    def camera(self) -> PinholeCamera:
        return PinholeCamera(self.view.K, self.view.width, self.view.height)

    @functools.cached_property
    def depth_m(self) -> np.ndarray:
        """(H, W) float32 the scene depth the occlusion rules test against (computed on first use)."""
        return scene_depth(self.sample, self.view) if self.given_depth_m is None else self.given_depth_m

    @property
    def camera_xy(self) -> np.ndarray:
        return self.view.T_global_from_cam[:2, 3]

    @property
    def lanes(self) -> LaneCenterlines | None:
        return self.sample.lanes if self.config.use_lanes else None


__all__ = ["PlacementScene", "scene_depth"]
