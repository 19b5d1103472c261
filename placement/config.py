"""Every placement threshold in one frozen dataclass.

The defaults follow the paper's supplement (drivable surface, 10-40 m, >= 1 m from static and >= 3 m
from dynamic classes, yaw along or against the ego heading with 3 deg noise; use 15 deg for
augmentation) plus the checks streetaug adds (LiDAR obstacles, lidarseg classes, camera view).
Derive variants with ``dataclasses.replace(PlacementConfig(), yaw_sigma_deg=15.0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

@dataclass(frozen=True)
class PlacementConfig:
    """Thresholds of the placement rules (metres, degrees, counts).

    Attributes:
        min_distance_m, max_distance_m: horizontal (global x/y) distance from the camera centre to the
            box centre must lie in [min, max].
        dynamic_clearance_m: minimum footprint-to-footprint distance to annotated vehicle/human/animal boxes.
        static_clearance_m: minimum footprint-to-footprint distance to other annotated boxes; also the
            margin around the footprint in which unannotated LiDAR obstacles and non-drivable lidarseg
            points are not allowed (the paper's 1 m from static background classes).
        mutual_clearance_m: minimum footprint distance between objects inserted into the same image
            (inserted objects are vehicles, so the dynamic clearance by default).
        yaw_sigma_deg: std of the Gaussian yaw noise around the lane / ego heading (3 realistic, 15 augmentation).
        opposite_heading_probability: probability of facing against the ego heading (not used on lanes,
            whose direction of travel is known).
        min_visible_fraction: minimum fraction of the projected 3D box (convex hull of its corners)
            inside the image, and minimum fraction of the box's image that is both inside the image and
            not hidden behind LiDAR returns nearer by more than ``occlusion_tolerance_m`` (a wall, a
            bus); the whole box must also be in front of the camera (z >= near_plane_m).
        truncated_share: share of objects placed cut by the image frame (part of the projected box outside the
            image, at most ``1 - min_visible_fraction``) where candidates of both kinds pass every rule; the others
            are wholly in the image. Each object draws which kind it takes (:func:`~streetaug.placement.place.place_one`).
            The default makes the placed cars on the real scene-0916 cut by the frame as often as its annotated cars
            10-40 m from the camera and at least half in the image are (0.127 of 1289 over its 41 keyframes x 6
            cameras): where only one kind passes it is taken, so 0 still cuts 3.7 % of the cars there and 1 cuts
            58.5 % (``benchmarks/bench_placement_truncation.py``, 272 placements each). Tracks draw it too, judged in
            their anchor camera at the anchor keyframe (:func:`~streetaug.placement.track.anchor_truncated`); passing
            tracks cut there are rare on scene-0916, so it changes little: 6.3 % of 16 tracks cut at the anchor before,
            5.6 % of 18 after, and of all their sightings 13.7 % -> 13.0 % (real cars 12.7 %;
            ``--seeds 0 --track-seeds 6``).
        near_plane_m: minimum camera-frame z of every box corner.
        n_candidates: candidates sampled per object.
        n_objects: objects to place per image (each mutually non-colliding); the caller passes that many
            sizes to :func:`streetaug.placement.place.place_objects`.
        obstacle_min_height_m, obstacle_max_height_m: a LiDAR point counts as an obstacle when its height
            above the local ground plane is in this range (and it lies in no annotated box).
        obstacle_max_points: tolerated obstacle points near a footprint (LiDAR noise).
        lidarseg_max_points: tolerated non-drivable lidarseg points near a footprint (label noise).
        ground_radius_m: LiDAR points within this horizontal radius of the box centre fit the local ground.
        ground_min_points: fewer ground points than this -> fall back to the ego ground plane.
        ground_inlier_m: plane-fit inlier band (metres, along the normal).
        ground_max_tilt_deg: fitted planes steeper than this are rejected (fallback to the ego plane).
        ground_max_offset_m, ground_max_offset_per_m: fitted planes whose height differs from the ego's
            ground plane by more than ``offset_m + offset_per_m * distance from the ego`` are rejected
            (10 % grade by default: a road does not climb faster).
        ground_box_radius_m, ground_box_tolerance_m: annotated objects standing within this radius of a
            placement give the ground's height there when the LiDAR fit is further than the tolerance from
            theirs (their median height above the ego's ground plane).
        grid_resolution_m: cell size of bird's-eye drivable grids built from LiDAR.
        closing_radius_m: morphological closing radius applied to those grids.
        ray_fill_max_gap_m: along one azimuth, two consecutive drivable points closer than this fill the
            cells between them (the sparse far LiDAR rings).
        azimuth_bin_deg: azimuth bin of that fill.
        corridor_half_width_m: LiDAR ground fallback: only points with |y_ego| below this (the ego's corridor).
        lidar_ground_band_m: LiDAR ground fallback: points within this height of the ego ground plane are ground.
        map_roi_m: the map's drivable polygons are clipped to this radius around the camera.
        require_unoccluded_corners: the paper's occlusion rule (for realism; off for augmentation, where
            the renderer's depth test handles occlusion): no top box corner hidden behind LiDAR points
            nearer by more than ``occlusion_tolerance_m``.
        occlusion_tolerance_m: depth margin of that rule and of the visible fraction.
        kerb_distance_m: an object whose footprint is this close to the edge of the drivable area is
            labelled ``vehicle.parked``; otherwise ``vehicle.moving``.
        use_lanes: orient objects along the map's lanes where it has them (else the ego heading).
        lane_max_distance_m: a candidate takes the direction of the nearest lane centre line within
            this distance (about half a lane plus margin); farther candidates use the ego heading.
    """

    min_distance_m: float = 10.0
    max_distance_m: float = 40.0
    dynamic_clearance_m: float = 3.0
    static_clearance_m: float = 1.0
    mutual_clearance_m: float = 3.0
    yaw_sigma_deg: float = 3.0
    opposite_heading_probability: float = 0.5
    min_visible_fraction: float = 0.5
    truncated_share: float = 0.16
    near_plane_m: float = 0.5
    n_candidates: int = 400
    n_objects: int = 1
    obstacle_min_height_m: float = 0.3
    obstacle_max_height_m: float = 2.0
    obstacle_max_points: int = 2
    lidarseg_max_points: int = 2
    ground_radius_m: float = 4.0
    ground_min_points: int = 8
    ground_inlier_m: float = 0.08
    ground_max_tilt_deg: float = 12.0
    ground_max_offset_m: float = 0.5
    ground_max_offset_per_m: float = 0.1
    ground_box_radius_m: float = 15.0
    ground_box_tolerance_m: float = 0.35
    grid_resolution_m: float = 0.25
    closing_radius_m: float = 0.75
    ray_fill_max_gap_m: float = 15.0
    azimuth_bin_deg: float = 0.5
    corridor_half_width_m: float = 6.0
    lidar_ground_band_m: float = 0.25
    map_roi_m: float = 80.0
    require_unoccluded_corners: bool = False
    occlusion_tolerance_m: float = 1.0
    kerb_distance_m: float = 1.0
    use_lanes: bool = True
    lane_max_distance_m: float = 2.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_distance_m < self.max_distance_m:
            raise ValueError(
                f"PlacementConfig: need 0 <= min_distance_m < max_distance_m, got "
                f"{self.min_distance_m}, {self.max_distance_m}"
            )
        for name in ("dynamic_clearance_m", "static_clearance_m", "mutual_clearance_m", "yaw_sigma_deg",
                     "grid_resolution_m", "ground_radius_m"):
            if getattr(self, name) < 0:
                raise ValueError(f"PlacementConfig.{name} must be >= 0, got {getattr(self, name)}")
        if self.n_candidates < 1 or self.n_objects < 1:
            raise ValueError(
                f"PlacementConfig: n_candidates and n_objects must be >= 1, got {self.n_candidates}, {self.n_objects}"
            )
        if not 0.0 <= self.truncated_share <= 1.0:
            raise ValueError(f"PlacementConfig.truncated_share must be in [0, 1], got {self.truncated_share}")
        if not 0.0 <= self.min_visible_fraction <= 1.0:
            raise ValueError(f"PlacementConfig.min_visible_fraction must be in [0, 1], got {self.min_visible_fraction}")
