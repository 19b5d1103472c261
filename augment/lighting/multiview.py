"""The volume levels (L2/L3, and ``auto``'s choice) of a sample: one sky dome and one VSG volume shared by its cameras.

The paper's multi-view extension: all images are unprojected into one volume defined in a common frame. The
*volume frame* is z up (global up), x along the reference camera's horizontal viewing direction, origin on the
ground under the reference camera (the first camera given). Radiance is on the reference camera's scale; each
camera's exposure relative to the reference (nuScenes cameras run their own auto-exposure) comes from the LiDAR
points neighbouring cameras both see (:mod:`.exposure`): images are divided by it when unprojected
(:func:`~.observe.observe_view`), and :meth:`~.types.SampleLighting.for_view` multiplies the shared lighting by
it. The sun and the per-camera L1 estimates come from the front door (:mod:`.api`), which chose their source.

An *earlier keyframe* (the sample's previous one, :class:`EarlierKeyframe`) adds its cameras' seen surfaces, at
rank 1 (:mod:`.seen_surfaces`), without what the instant's cameras saw through: they fill only the rays the
instant's own surfaces leave open. (Its pixels in the volume were tried too and hurt: the instant's own
observations are the better evidence.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ...datasets.sample import CameraView, LidarSweep
from ..core import (
    equirect_solid_angles,
    invert_transform,
    ldr_uint8_to_hdr,
    luminance,
    make_transform,
    rotate_vectors,
    transform_points,
    yaw_to_quat,
)
from .build import DistantSun, build_volume, lidar_points_in_volume, structure_heights
from .exposure import exposure_ratios, lidar_luminance, pair_ratio
from .fill import clipped_ldr, mean_colour_of_ldr
from .levels import L2_GRID, L3_GRID, HeightMap, choose_level, predicted_errors, region_points
from .observe import ViewObservation, observe_view, restrict_to_grid
from .seen_surfaces import DepthView, SeenSurfaces, carved
from .parametric import DEFAULT_TURBIDITY, GROUND_ALBEDO, ViewInputs, l0_estimate
from .skydome import build_sky_dome, camera_envmap_to_world, model_sky_world
from .types import LightingEstimate, SampleLighting, join_reasons, json_clean
from .volume import HybridLighting, LogGrid, world_envmap_directions

DOME_HEIGHT, DOME_WIDTH = 128, 512
DEFAULT_PLACEMENT_DISTANCES_M = (12.0, 20.0, 30.0)
NOMINAL_SKY_SUN_CAM = (0.0, -0.7071, 0.7071)  # shapes the parametric sky without a sun direction


def volume_frame(view: CameraView) -> np.ndarray:
    """``T_global_from_vol`` (4, 4): z = global up, x = the camera's horizontal viewing direction, origin on the
    ground (the ego's z = 0) under the camera centre."""
    T = np.asarray(view.T_global_from_cam)
    fwd = T[:3, 2]
    yaw = float(np.arctan2(fwd[1], fwd[0]))
    ground_z = float(np.asarray(view.T_global_from_ego)[2, 3])
    return make_transform(yaw_to_quat(yaw), [T[0, 3], T[1, 3], ground_z])


def placement_points_vol(T_vol_from_cams: list[np.ndarray], query_point_cam: np.ndarray | None) -> np.ndarray:
    """Ground points (P, 3) of the placements to judge: the query point (first camera's frame), else 12/20/30 m
    along each camera's axis."""
    if query_point_cam is not None:
        q = transform_points(T_vol_from_cams[0], np.asarray(query_point_cam, dtype=np.float64)[None])[0]
        return np.array([[q[0], q[1], 0.0]])
    out = []
    for T in T_vol_from_cams:
        fwd = T[:3, 2].copy()
        fwd[2] = 0.0
        fwd /= max(np.linalg.norm(fwd), 1e-9)
        for dist in DEFAULT_PLACEMENT_DISTANCES_M:
            p = T[:3, 3] + dist * fwd
            out.append([p[0], p[1], 0.0])
    return np.array(out)


def height_map(observations: list[ViewObservation], lidar_vol: np.ndarray | None) -> tuple[HeightMap, dict]:
    """Occluder heights from LiDAR + unprojected pixels with the street-canyon prior of :func:`structure_heights`."""
    cam = np.concatenate([o.points for o in observations]) if observations else np.zeros((0, 3))
    cap = np.concatenate([o.capped for o in observations]) if observations else np.zeros(0, bool)
    cam_map = HeightMap.from_points(cam)
    cap_map = HeightMap.from_points(np.concatenate([cam[cap][:, :2], np.ones((cap.sum(), 1))], axis=1))
    # the map of camera and LiDAR points together: the camera points' map merged with the LiDAR's (a max per cell)
    hmap = cam_map.merged(HeightMap.from_points(lidar_vol)) if lidar_vol is not None and len(lidar_vol) else cam_map
    n = hmap.heights_m.shape[0]
    c = (np.arange(n) + 0.5) * hmap.cell_m - hmap.half_extent_m
    r = np.hypot(c[:, None], c[None, :])
    cam_top = np.where(cam_map.heights_m > 0, cam_map.heights_m, -np.inf)
    heights, stats = structure_heights(hmap.heights_m, cam_top, cap_map.heights_m > 0, r, hmap.heights_m >= 1.0)
    return HeightMap(heights.astype(np.float32), hmap.cell_m, hmap.half_extent_m), stats


def sky_horizontal_irradiance_world(dome: np.ndarray) -> np.ndarray:
    """(3,) irradiance of a world-convention dome's upper hemisphere on a horizontal surface."""
    H, W = dome.shape[:2]
    d = world_envmap_directions(H, W).reshape(-1, 3)
    w = equirect_solid_angles(H, W).reshape(-1) * np.maximum(d[:, 2], 0.0)
    return w @ dome.reshape(-1, 3).astype(np.float64)


def sky_model_world(ref_est: LightingEstimate, T_vol_from_cam: np.ndarray, height: int, width: int) -> np.ndarray:
    """The reference camera's sky (sun excluded) as a world-convention map (height, width, 3), reference scale:
    its parametric fit (the real sun direction shapes it, also below the horizon), or, for the learned image
    model, its camera-frame environment map turned into the volume frame."""
    fit = ref_est.fit
    if fit is None:
        return camera_envmap_to_world(ref_est.light_cam.envmap, T_vol_from_cam[:3, :3], height, width)
    sun_vol = rotate_vectors(T_vol_from_cam, np.asarray(fit.sky_sun_dir_cam, dtype=np.float64)[None])[0]
    return model_sky_world(sun_vol, fit.turbidity, fit.cloud_cover, fit.ground_albedo, fit.scale, height, width)


def choose_auto(ref_est: LightingEstimate, ref_inputs: ViewInputs, T_vol_from_cam: np.ndarray,
                observations: list[ViewObservation], lidar_vol: np.ndarray | None,
                placements: np.ndarray) -> tuple[str, str, dict]:
    """``auto``: predicted errors of each level at the placements from the occluder height map -> (level, reason, info)."""
    hmap, canyon = height_map(observations, lidar_vol)
    pts = np.concatenate([region_points(p) for p in placements])
    sun = ref_est.light_cam.sun
    e_sun = float(luminance(sun.irradiance_rgb)) if sun is not None else 0.0
    sun_vol = (T_vol_from_cam[:3, :3] @ ref_est.sun_dir_cam) if ref_est.sun_dir_cam is not None else None
    model = sky_model_world(ref_est, T_vol_from_cam, 32, 64)
    e_sky_h = float(luminance(sky_horizontal_irradiance_world(model)))
    work = ref_inputs.work
    hdr = work.hdr if work is not None else ldr_uint8_to_hdr(np.asarray(ref_inputs.view.image))
    l0_e = float(np.pi * luminance(hdr.reshape(-1, 3).mean(axis=0)))
    errors, evidence = predicted_errors(hmap, pts, sun_vol, e_sun, e_sky_h, l0_e, placements[:, :2].mean(axis=0))
    level, reason = choose_level(errors)
    return level, reason, {"predicted_errors": errors, "evidence": evidence, "canyon": canyon,
                           "placements_vol": placements.tolist()}


def sun_factor(dome: np.ndarray, model: np.ndarray) -> tuple[float, str]:
    """How much to scale L1's sun so that it follows the image's correction of the sky dome.

    The observed sky pixels set the dome's level on the image's scale; L1's model (with the fitted cloud
    cover) sets the sun/sky ratio, which is kept: the sun is scaled like the dome's horizontal sky irradiance.
    (Deriving the sun from a lit/shadow contrast instead overestimates it wherever the shadowed road also loses
    sky to the occluder: +94 % at an 11 deg sun on the bundled scenes.) Clamped to [0.25, 4].
    """
    factor = float(luminance(sky_horizontal_irradiance_world(dome))) / max(
        float(luminance(sky_horizontal_irradiance_world(model))), 1e-12)
    return float(np.clip(factor, 0.25, 4.0)), "the dome's correction of the sky model (L1's sun/sky ratio kept)"


def build_hybrid(ref_est: LightingEstimate, T_vol_from_cam: np.ndarray, observations: list[ViewObservation],
                 lidar_vol: np.ndarray | None, grid: LogGrid, timing: dict,
                 earlier_depth_views: Sequence[DepthView] = ()) -> tuple[HybridLighting, dict]:
    """Sky dome (model corrected by the images), the sun (L1's, following the dome's correction), the volume and
    the cameras' seen surfaces (with ``earlier_depth_views``, rank 1, after them)."""
    t = time.perf_counter()
    model = sky_model_world(ref_est, T_vol_from_cam, DOME_HEIGHT, DOME_WIDTH)
    # the seen mean colours: of every pixel (the dome's), of the pixels inside the volume (the volume's)
    near_ldr = [clipped_ldr(o.radiance) for o in observations if len(o.radiance)]
    far_ldr = [clipped_ldr(o.far_radiance) for o in observations if len(o.far_radiance)]
    anchor = mean_colour_of_ldr(near_ldr + far_ldr) if near_ldr or far_ldr else None
    dome, dome_stats = build_sky_dome(model, observations, anchor_rgb=anchor)
    timing["sky_dome"] = time.perf_counter() - t
    t = time.perf_counter()
    out = {"grid": grid.to_json(), "sky_dome": dome_stats}
    sun_dir_vol = sun_irr = None
    if ref_est.light_cam.sun is not None:
        sun_dir_vol = T_vol_from_cam[:3, :3] @ ref_est.light_cam.sun.direction
        factor, how = sun_factor(dome, model)
        sun_irr = np.asarray(ref_est.light_cam.sun.irradiance_rgb, dtype=np.float64) * factor
        out["sun_irradiance_factor"] = {"factor": factor, "from": how}
    light = DistantSun(sun_dir_vol, np.zeros(3) if sun_irr is None else sun_irr, sky_horizontal_irradiance_world(dome))
    params, out["volume"] = build_volume(grid, observations, lidar_vol, light, dome, GROUND_ALBEDO,
                                         seen_anchor_rgb=mean_colour_of_ldr(near_ldr) if near_ldr else None)
    timing["volume"] = time.perf_counter() - t
    t = time.perf_counter()
    surfaces = SeenSurfaces.from_views([o.depth_view for o in observations if o.depth_view is not None]
                                       + list(earlier_depth_views))
    timing["seen_surfaces"] = time.perf_counter() - t
    out["seen_surfaces"] = {"faces": 0 if surfaces is None else surfaces.n_faces,
                            "cameras": [] if surfaces is None else list(surfaces.channels)}
    hybrid = HybridLighting(
        dome, sun_dir_vol, None if sun_irr is None else sun_irr.astype(np.float32),
        grid=grid, params=params, seen=surfaces,
    )
    return hybrid, out


def _observe(view: CameraView, T_vol_from_cam: np.ndarray, ratio: float, lidar_vol: np.ndarray | None,
             vi: ViewInputs | None, lidar_origin_vol: np.ndarray | None = None) -> ViewObservation:
    """One camera's observation (:func:`observe_view`) with the LiDAR (its returns and, if given, its centre) and
    the ground plane z = 0 in its frame."""
    T_cam_from_vol = invert_transform(T_vol_from_cam)
    n_cam = T_cam_from_vol[:3, :3] @ np.array([0.0, 0.0, 1.0])
    ground = (n_cam, float(-n_cam @ T_cam_from_vol[:3, 3]))
    pts_cam = transform_points(T_cam_from_vol, lidar_vol) if lidar_vol is not None else None
    origin_cam = None if lidar_origin_vol is None else transform_points(T_cam_from_vol, np.asarray(lidar_origin_vol)[None])[0]
    return observe_view(view, T_vol_from_cam, ratio, pts_cam, ground, work=None if vi is None else vi.work,
                        lidar_origin_cam=origin_cam)


@dataclass(frozen=True)
class EarlierKeyframe:
    """The sample's previous keyframe as an extra input of the volume levels: its cameras saw from further back
    what is now behind and above the instant's cameras (see module doc).

    Attributes:
        views: its camera views (channels of the same rig; each measured against the same channel now).
        lidar: its LiDAR sweep (their depth), or None.
    """

    views: tuple[CameraView, ...]
    lidar: LidarSweep | None


def earlier_exposure_ratios(views: Sequence[CameraView], ratios: dict[str, float], earlier: EarlierKeyframe,
                            points_global: np.ndarray | None) -> list[float]:
    """Each earlier view's exposure relative to the reference: its channel's ratio now times that channel's
    change of exposure between the keyframes (:func:`.exposure.pair_ratio` on the LiDAR points ``points_global``
    (N, 3) both images see; 1 when they share too few); a channel not input now: the reference's, times its
    change relative to the reference camera now."""
    now = {v.channel: v for v in views}
    out = []
    for e in earlier.views:
        same = now.get(e.channel, views[0])
        change = 1.0
        if points_global is not None and len(points_global):
            change, _ = pair_ratio(lidar_luminance(same, points_global), lidar_luminance(e, points_global))
        out.append(float(ratios.get(same.channel, 1.0)) * change)
    return out


def earlier_depth_views(earlier: EarlierKeyframe, views: Sequence[CameraView], ratios: dict[str, float],
                        lidar: LidarSweep | None, T_vol_from_global: np.ndarray,
                        instant: Sequence[DepthView] = ()) -> tuple[list[DepthView], dict]:
    """The earlier keyframe's cameras' depth views at rank 1 (volume frame, reference scale), without what the
    ``instant`` cameras' depth views saw through (:func:`.seen_surfaces.carved`), and their exposure ratios
    (channel -> ratio)."""
    pts = [sw.points_global for sw in (lidar, earlier.lidar) if sw is not None]
    e_ratios = earlier_exposure_ratios(views, ratios, earlier, np.concatenate(pts) if pts else None)
    e_lidar = lidar_points_in_volume(earlier.lidar, T_vol_from_global) if earlier.lidar is not None else None
    out = []
    for v, k in zip(earlier.views, e_ratios):
        dv = _observe(v, T_vol_from_global @ np.asarray(v.T_global_from_cam), k, e_lidar, None).depth_view
        if dv is not None:
            out.append(replace(carved(dv, list(instant)), channel=f"{v.channel}@earlier", rank=1))
    return out, {v.channel: k for v, k in zip(earlier.views, e_ratios)}


@dataclass(frozen=True)
class SceneObservations:
    """Every camera's observation in the volume frame (inside the widest grid used) and the LiDAR there.

    Attributes:
        T_vol_from_cams: (4, 4) per camera, camera -> volume frame.
        observations: per camera, restricted to ``widest``.
        lidar_vol: (N, 3) LiDAR points in the volume frame (ego car removed), or None.
        widest: the grid the observations were restricted to.
        exposure_ratio: channel -> that camera's image units per reference unit.
        exposure: the exposure measurement record.
        earlier: the earlier keyframe's depth views (rank 1), empty without one.
    """

    T_vol_from_cams: list[np.ndarray]
    observations: list[ViewObservation]
    lidar_vol: np.ndarray | None
    widest: LogGrid
    exposure_ratio: dict[str, float]
    exposure: dict
    earlier: tuple[DepthView, ...] = ()


def observe_scene(views: Sequence[CameraView], inputs: Sequence[ViewInputs], T_global_from_vol: np.ndarray,
                  lidar: LidarSweep | None, grid: LogGrid | None, timing: dict,
                  earlier: EarlierKeyframe | None = None) -> SceneObservations:
    """Each camera's exposure relative to the reference, then its pixels unprojected into the volume frame; the
    earlier keyframe's cameras' depth views."""
    t = time.perf_counter()
    ratios, exposure = exposure_ratios(views, lidar.points_global if lidar is not None else None)
    timing["exposure"] = time.perf_counter() - t
    t = time.perf_counter()
    T_vol_from_global = invert_transform(T_global_from_vol)
    T_vol_from_cams = [T_vol_from_global @ np.asarray(v.T_global_from_cam) for v in views]
    lidar_vol = lidar_points_in_volume(lidar, T_vol_from_global) if lidar is not None else None
    widest = L3_GRID if grid is None or grid.half_extent_xy_m < L3_GRID.half_extent_xy_m else grid
    origin = None if lidar is None else (T_vol_from_global @ np.asarray(lidar.T_global_from_lidar))[:3, 3]
    observations = [restrict_to_grid(_observe(v, T_vc, ratios[v.channel], lidar_vol, vi, origin), widest)
                    for v, T_vc, vi in zip(views, T_vol_from_cams, inputs)]
    timing["observe"] = time.perf_counter() - t
    depth_views: list[DepthView] = []
    if earlier is not None and earlier.views:
        t = time.perf_counter()
        depth_views, exposure["earlier"] = earlier_depth_views(
            earlier, views, ratios, lidar, T_vol_from_global, [o.depth_view for o in observations if o.depth_view is not None])
        timing["observe_earlier"] = time.perf_counter() - t
    return SceneObservations(T_vol_from_cams, observations, lidar_vol, widest, ratios, exposure, tuple(depth_views))


def volume_sample_lighting(base: SampleLighting, views: Sequence[CameraView], inputs: Sequence[ViewInputs],
                           level: str, lidar: LidarSweep | None, query_point_cam: np.ndarray | None,
                           grid: LogGrid | None, timing: dict, t0: float,
                           earlier: EarlierKeyframe | None = None) -> SampleLighting:
    """L2, L3 or ``auto`` of a sample from its L1 lighting ``base`` (per-camera estimates, sun, params).

    ``auto`` may settle on L0 or L1 (then without a volume); ``grid`` overrides the level's grid (benchmarks);
    ``earlier``: the previous keyframe's seen surfaces fill what the instant's leave open.
    """
    ref_est = base.per_view[base.reference]
    params = dict(base.params)
    scene = observe_scene(views, inputs, base.T_global_from_vol, lidar, grid, timing, earlier)
    params["exposure_ratio"], params["exposure"] = scene.exposure_ratio, scene.exposure
    base = replace(base, exposure_ratio=scene.exposure_ratio)
    placements = placement_points_vol(scene.T_vol_from_cams, query_point_cam)
    l2_centre = placements[:, :2].mean(axis=0)
    if level == "auto":
        t = time.perf_counter()
        level, auto_reason, params["auto"] = choose_auto(ref_est, inputs[0], scene.T_vol_from_cams[0],
                                                         scene.observations, scene.lidar_vol, placements)
        timing["auto"] = time.perf_counter() - t
        if level in ("L0", "L1"):
            per_view = base.per_view
            if level == "L0":
                per_view = {v.channel: l0_estimate(np.asarray(v.image), {}) for v in views}
            timing["total"] = time.perf_counter() - t0
            reason = join_reasons(auto_reason, base.reason if level == "L1" else "")
            return replace(base, level=level, reason=reason, per_view=per_view, params=json_clean(params),
                           timing_s=timing)
    else:
        auto_reason = f"{level} requested"
    if grid is None:
        grid = L3_GRID if level == "L3" else replace(L2_GRID, centre_xy_m=(float(l2_centre[0]), float(l2_centre[1])))
    observations = scene.observations
    if grid is not scene.widest:
        observations = [restrict_to_grid(o, grid) for o in observations]
    hybrid, build_params = build_hybrid(ref_est, scene.T_vol_from_cams[0], observations, scene.lidar_vol, grid, timing,
                                        scene.earlier)
    geometry = "LiDAR densified" if lidar is not None else "no LiDAR: street-canyon prior"
    reason = (f"{level}: " if not auto_reason.startswith("auto") else "") + join_reasons(
        auto_reason, f"sky dome + VSG volume {grid.shape} over +-{grid.half_extent_xy_m:g} m from "
        f"{len(views)} view(s) ({geometry})" + (f", the seen surfaces of {len(scene.earlier)} view(s) of the "
                                               f"previous keyframe behind them" if scene.earlier else "")
        + f"; {base.reason}")
    params.update(build_params, T_global_from_vol=base.T_global_from_vol.tolist())
    timing["total"] = time.perf_counter() - t0
    return replace(base, level=level, reason=reason, hybrid=hybrid, params=json_clean(params), timing_s=timing)
