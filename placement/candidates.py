"""Candidate boxes of one object: sampled in the camera's field of view, then stood on the local ground.

Sampling draws, per object and in this order, r ~ U[min, max] (horizontal distance from the camera), an
azimuth uniform in the camera's field of view, a flip to the opposite heading and N(0, yaw_sigma_deg)
yaw noise; the heading is the nearest lane's (within ``lane_max_distance_m``) or the ego's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from streetaug.augment.core import InputError
from streetaug.datasets.sample import CameraView

from .class_rules import ClassRule
from .config import PlacementConfig
from .ground import GroundPlane, ego_ground_plane
from .parking import kerb_poses
from .rules import box_corners_object, box_footprint_rect, footprint_corners
from .scene import PlacementScene


def object_transforms(
    bottom_xy: np.ndarray, yaw_rad: np.ndarray, ground_z: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """T_global_from_object (N, 4, 4) for objects standing on planes.

    Args:
        bottom_xy: (N, 2) global x/y of the bottom centre.
        yaw_rad: (N,) heading in the global x/y plane (rad, from +x towards +y).
        ground_z: (N,) ground height at bottom_xy.
        normals: (N, 3) unit ground normals (z > 0); become the object's +z.
    """
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    h = np.stack([np.cos(yaw_rad), np.sin(yaw_rad), np.zeros_like(yaw_rad)], axis=1)
    x = h - np.einsum("nd,nd->n", h, n)[:, None] * n
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(n, x)
    T = np.tile(np.eye(4), (len(n), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x, y, n
    T[:, :3, 3] = np.concatenate([bottom_xy, np.asarray(ground_z).reshape(-1, 1)], axis=1)
    return T


@dataclass(frozen=True)
class CameraAzimuthRange:
    """The horizontal field of view of a camera on the ground.

    Attributes:
        heading_rad: heading of the optical axis in global x/y (rad, from +x towards +y).
        left_rad, right_rad: largest angle to the left / right of it that is still in the image.
    """

    heading_rad: float
    left_rad: float
    right_rad: float


def camera_azimuth_range(view: CameraView) -> CameraAzimuthRange:
    """The azimuths (global x/y) the camera of ``view`` sees; candidates are sampled within them."""
    fwd = view.T_global_from_cam[:3, 2]
    if np.hypot(fwd[0], fwd[1]) < 1e-3:
        raise InputError(f"camera {view.channel}: optical axis is vertical; cannot place objects on the ground")
    fx, cx = view.K[0, 0], view.K[0, 2]
    return CameraAzimuthRange(float(np.arctan2(fwd[1], fwd[0])), float(np.arctan((cx + 0.5) / fx)),
                              float(np.arctan((view.width - 0.5 - cx) / fx)))


@dataclass(frozen=True)
class Candidates:
    """The sampled candidates of one object (global frame).

    Attributes:
        xy: (n, 2) float64 bottom-centre x/y.
        yaw_rad: (n,) float64 heading in (-pi, pi].
        on_lane: (n,) bool whether the heading came from a lane of the map.
        footprints_xy: (n, 4, 2) flat footprints (:func:`footprint_corners`).
    """

    xy: np.ndarray
    yaw_rad: np.ndarray
    on_lane: np.ndarray
    footprints_xy: np.ndarray


LANE_REACH_OFF_CENTRE_M = 4.0  # extra lane search distance outside the lane zone (kerb, road edge, sidewalk)
OVERSAMPLE = 8  # draws per candidate: candidates whose centre suits the zone are kept first


def sample_candidates(scene: PlacementScene, wlh: np.ndarray, rng: np.random.Generator,
                      rule: ClassRule | None = None, zone: str = "lane") -> Candidates:
    """``config.n_candidates`` candidates of one object in the camera's field of view, in ``zone``.

    Draws ``OVERSAMPLE`` x n of (r, azimuth, flip, noise, random heading) from ``rng`` (a fixed count, so the
    stream does not depend on the scene) and keeps, in draw order, those whose centre suits the zone
    (:meth:`SurfaceZones.plausible_centres`) first, then the others. The heading follows ``rule.heading``:
    ``lane`` the nearest lane's direction (within ``lane_max_distance_m``) or the ego's (either way); ``path``
    the same either way (across the road on a crossing); ``across`` that plus 90 deg; ``random`` uniform. In the
    ``kerb`` zone of a ``lane``-heading rule with ``zone_weights: scene`` the candidate stands as the nearest parked
    box of its class does, else along the road edge (lanes only where no parked box is near: :func:`kerb_poses`).
    ``rule`` None: a car's rule (lane heading) with the scene's config.
    """
    config = scene.config if rule is None else rule.config(scene.config)
    n = config.n_candidates
    m = n if rule is None else OVERSAMPLE * n  # without a rule: the stream of earlier versions (tracks)
    fov = camera_azimuth_range(scene.view)
    R_ego = scene.view.T_global_from_ego[:3, :3]
    yaw_ego = float(np.arctan2(R_ego[1, 0], R_ego[0, 0]))
    r = rng.uniform(config.min_distance_m, config.max_distance_m, m)
    az = fov.heading_rad + rng.uniform(-fov.right_rad, fov.left_rad, m)
    flip = rng.random(m) < config.opposite_heading_probability
    noise = np.radians(rng.normal(0.0, config.yaw_sigma_deg, m))
    uniform_yaw = rng.uniform(-np.pi, np.pi, m) if rule is not None else np.zeros(m)
    xy = scene.camera_xy + r[:, None] * np.stack([np.cos(az), np.sin(az)], axis=1)
    if rule is not None:
        good = scene.zones.plausible_centres(zone, xy, wlh, rule)
        order = np.concatenate([np.flatnonzero(good), np.flatnonzero(~good)])[:n]
    else:
        order = np.arange(n)
    xy, flip, noise, uniform_yaw = xy[order], flip[order], noise[order], uniform_yaw[order]
    heading_mode = "lane" if rule is None else rule.heading
    heading = yaw_ego + np.pi * flip
    on_lane = np.zeros(n, dtype=bool)
    if scene.lanes is not None:
        # by the kerb and off the road, the nearest lane is farther than half a lane away
        reach = config.lane_max_distance_m + (LANE_REACH_OFF_CENTRE_M if zone != "lane" and rule is not None else 0.0)
        lane_heading, on_lane = scene.lanes.heading_at(xy, reach)
        along = lane_heading + (np.pi * flip if heading_mode != "lane" else 0.0)
        heading = np.where(on_lane, along, heading)
    w, l, _ = wlh
    if rule is not None and rule.parks_like_the_scene(zone):
        # parked as the nearest parked box of the class stands (angle to the edge, distance in), else along the edge
        xy, kerb_heading, styled = kerb_poses(scene.zones, scene.parking_style(rule), xy, heading, l, w)
        on_lane &= ~styled
        heading = np.where(on_lane, heading, kerb_heading)
    if heading_mode == "across" or (heading_mode == "path" and zone == "crossing"):
        heading = heading + np.pi / 2
    if heading_mode == "random":
        heading, noise, on_lane = uniform_yaw, np.zeros(n), np.zeros(n, dtype=bool)
    yaw = np.mod(heading + noise + np.pi, 2 * np.pi) - np.pi
    return Candidates(xy, yaw, on_lane, footprint_corners(xy, yaw, l, w))


@dataclass(frozen=True)
class StoodCandidates:
    """Candidates standing on their local ground (arrays over the M candidates of one chunk).

    Attributes:
        index: (M,) int64 their indices among the object's candidates.
        planes: the local ground plane of each.
        T_global_from_object: (M, 4, 4) the standing boxes (:func:`object_transforms`).
        centers: (M, 3) box centres (global); ``footprints_xy`` (M, 4, 2) :func:`box_footprint_rect`.
        T_cam_from_object: (M, 4, 4); ``corners_cam`` (M, 8, 3) the box corners in the camera frame.
    """

    index: np.ndarray
    planes: list[GroundPlane]
    T_global_from_object: np.ndarray
    centers: np.ndarray
    footprints_xy: np.ndarray
    T_cam_from_object: np.ndarray
    corners_cam: np.ndarray

    @property
    def ground_points(self) -> np.ndarray:
        return np.array([p.point_global for p in self.planes]).reshape(-1, 3)

    @property
    def ground_normals(self) -> np.ndarray:
        return np.array([p.normal_global for p in self.planes]).reshape(-1, 3)


def stand_candidates(scene: PlacementScene, cands: Candidates, index: np.ndarray, wlh: np.ndarray,
                     config: PlacementConfig | None = None) -> StoodCandidates:
    """Stand candidates ``index`` on the ground fitted below them: roll/pitch from the plane, heading kept.

    ``config`` (default the scene's) sets the fit radius. Small objects (footprint diagonal under
    ``SUPPORT_MAX_SIZE_M``) then sit on the LiDAR returns right around their footprint: the plane moves along
    its normal by their median height above it when enough of them lie within ``SUPPORT_BAND_M`` of it (a cone
    on a kerb step, a pedestrian on a raised sidewalk, which a wider fit would average with the road).
    """
    config = config or scene.config
    fitter = scene.ground_for(config)
    planes = fitter.fit_many(cands.xy[index])
    if is_small(wlh):
        T_ge = scene.view.T_global_from_ego
        planes = [support_plane(p, scene.obstacle_points, fp, ego_ground_plane(T_ge, fp.mean(axis=0)))
                  for p, fp in zip(planes, cands.footprints_xy[index])]
    g_point = np.array([p.point_global for p in planes]).reshape(-1, 3)
    g_normal = np.array([p.normal_global for p in planes]).reshape(-1, 3)
    T_go = object_transforms(cands.xy[index], cands.yaw_rad[index], g_point[:, 2], g_normal)
    centers = T_go[:, :3, 3] + 0.5 * wlh[2] * T_go[:, :3, 2]
    T_co = scene.view.T_cam_from_global[None] @ T_go
    corners_cam = np.einsum("nij,kj->nki", T_co[:, :3, :3], box_corners_object(wlh)) + T_co[:, None, :3, 3]
    return StoodCandidates(index, planes, T_go, centers, box_footprint_rect(T_go, wlh), T_co, corners_cam)


SUPPORT_MAX_SIZE_M = 3.0  # footprint diagonal below which an object reads the ground right under it


def is_small(wlh: np.ndarray) -> bool:
    """Whether a box [w, l, h] is small enough to stand on the returns right under it (:func:`support_plane`)."""
    return float(np.hypot(wlh[0], wlh[1])) < SUPPORT_MAX_SIZE_M
SUPPORT_MARGIN_M = 0.4  # around the footprint
SUPPORT_BAND_M = 0.25  # returns this close to the fitted plane count as the ground under the object
SUPPORT_MIN_POINTS = 4
UNSEEN_MAX_OFFSET_M = 0.3  # an unseen small object's ground kept this close to the ego's road (else the ego's)


def support_plane(plane: GroundPlane, points_global: np.ndarray, footprint_xy: np.ndarray,
                  ego_plane: GroundPlane | None = None) -> GroundPlane:
    """``plane`` moved along its normal onto the ground right under the footprint (4, 2) grown by
    ``SUPPORT_MARGIN_M``, from the LiDAR returns (P, 3) there.

    With fewer than ``SUPPORT_MIN_POINTS`` returns there the ground under the object is unseen: a plane fitted
    farther away is kept only within ``UNSEEN_MAX_OFFSET_M`` of the ego's road (``ego_plane``, below the same
    point), else the ego's plane is used (off the road, the surface rule then refuses it). The returned plane's
    ``n_points`` is the number of returns it stands on (0: unseen).

    The ground is the lowest surface: when returns lie more than ``SUPPORT_BAND_M`` below the plane (it was fitted
    on a wall's top, a parapet, a hoarding), the plane drops to them (the median of those within
    ``SUPPORT_BAND_M`` of their 10th-percentile height); otherwise it moves to the lower quartile height of the
    returns within ``SUPPORT_BAND_M`` of it (a raised sidewalk; a footprint straddling a kerb step rests on the
    road rather than hovering over it).
    """
    def unseen() -> GroundPlane:  # n_points 0: nothing seen under the object
        if ego_plane is None or abs(plane.point_global[2] - ego_plane.point_global[2]) <= UNSEEN_MAX_OFFSET_M:
            return GroundPlane(plane.point_global, plane.normal_global, plane.source, 0)
        return ego_plane

    if len(points_global) == 0:
        return unseen()
    c = footprint_xy.mean(axis=0)
    r = float(np.max(np.linalg.norm(footprint_xy - c, axis=1))) + SUPPORT_MARGIN_M
    near = np.linalg.norm(points_global[:, :2] - c, axis=1) <= r
    h_all = (points_global[near] - plane.point_global) @ plane.normal_global
    below = h_all[h_all < -SUPPORT_BAND_M]
    if len(below) >= SUPPORT_MIN_POINTS:  # the plane is above what is under the object: drop to the floor
        floor = float(np.percentile(below, 10))
        h = below[below <= floor + SUPPORT_BAND_M]
        level = float(np.median(h))
    else:
        h = h_all[np.abs(h_all) <= SUPPORT_BAND_M]
        level = float(np.percentile(h, 25)) if len(h) else 0.0  # straddling a kerb: the road, not above it
    if len(h) < SUPPORT_MIN_POINTS:
        return unseen()
    dz = level
    # a plane moved by dz along its normal rises by dz / n_z at the same x/y
    return GroundPlane(plane.point_global + np.array([0.0, 0.0, dz / plane.normal_global[2]]), plane.normal_global,
                       plane.source, len(h))


__all__ = ["CameraAzimuthRange", "Candidates", "StoodCandidates", "camera_azimuth_range", "object_transforms",
           "is_small", "sample_candidates", "stand_candidates", "support_plane"]
