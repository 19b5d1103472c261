"""The lighting of a whole sample: one sun, one sky dome and one VSG volume shared by all its cameras.

The paper's multi-view extension: the sky's parameters are pooled over the views (here the cloud cover,
from the strongest evidence any camera has) and all images are unprojected into one volume defined in a
common frame. The *volume frame* is z up (global up), x along the reference camera's horizontal viewing
direction, origin on the ground under the reference camera (the first camera given). Radiance is on the
reference camera's scale; each camera's exposure relative to the reference (nuScenes cameras run their own
auto-exposure) comes from the LiDAR points neighbouring cameras both see (:mod:`.exposure`): images are
divided by it when unprojected (:func:`~.build.observe_view`), and :meth:`SampleLighting.for_view`
multiplies the shared lighting by it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
import torch

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
from .build import (
    DistantSun,
    ViewObservation,
    build_sky_dome,
    build_volume,
    lidar_points_in_volume,
    model_sky_world,
    observe_view,
    structure_heights,
)
from .estimate import (
    DEFAULT_TURBIDITY,
    ENVMAP_HEIGHT,
    ENVMAP_WIDTH,
    GROUND_ALBEDO,
    LightingEstimate,
    _clean,
    _estimate_l0,
    _l1_cloud,
    _l1_estimate,
    _l1_view_evidence,
)
from .exposure import exposure_ratios
from .levels import (
    L2_GRID,
    L3_GRID,
    HeightMap,
    check_level,
    choose_level,
    predicted_errors,
    region_points,
)
from .light import DistantLight, SunLight
from .volume import HybridLighting, LogGrid, world_envmap_directions, world_to_frame_envmap

DOME_HEIGHT, DOME_WIDTH = 128, 512
CLOUD_SOURCE_RANK = ("object_shadows", "ground_contrast", "sky_colour", "night", "assumed")
DEFAULT_PLACEMENT_DISTANCES_M = (12.0, 20.0, 30.0)


@dataclass(frozen=True)
class SampleLighting:
    """The lighting of one sample, shared by its cameras.

    Attributes:
        level: "L0" | "L1" | "L2" | "L3" (for ``auto``: the level chosen).
        reason: why this level and which evidence/fallbacks were used.
        reference: channel of the reference camera (volume frame and radiometric scale).
        per_view: channel -> the L0/L1 estimate of each input camera (its own frame and scale).
        exposure_ratio: channel -> that camera's image units per reference unit.
        hybrid: sky dome + sun + volume in the volume frame (L2/L3), else None.
        T_global_from_vol: (4, 4) volume frame -> global.
        params: JSON-serialisable numbers (cloud cover, grid, build statistics, auto's predicted errors).
        timing_s: seconds per step.
        view_keys: channel -> (channel, sample_data_token, image_path) of the input views.
    """

    level: str
    reason: str
    reference: str
    per_view: dict
    exposure_ratio: dict
    hybrid: HybridLighting | None
    T_global_from_vol: np.ndarray
    params: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    view_keys: dict = field(default_factory=dict)

    def for_view(self, view) -> LightingEstimate:
        """A camera-frame estimate for ``view`` (one of the sample's cameras) sharing this sample's sun, sky and volume."""
        known = self.per_view.get(view.channel)
        same = known is not None and _same_view(self.view_keys.get(view.channel), view)
        if self.level in ("L0", "L1"):
            if same:
                est = known
            elif self.level == "L0":
                est = _estimate_l0(np.asarray(view.image), {})
            else:
                fit = _l1_view_evidence(view, self.params.get("location"), {})
                est = _l1_estimate(fit, {}, self.params.get("cloud_cover"), "cloud cover shared by the sample")
            return replace(est, level=self.level, reason=_join(self.reason, est.reason))
        T_vol_from_cam = invert_transform(self.T_global_from_vol) @ np.asarray(view.T_global_from_cam)
        R_vol_from_cam = T_vol_from_cam[:3, :3]
        ratio = float(self.exposure_ratio.get(view.channel, 1.0)) if same else 1.0
        note = "" if same else f"; {view.channel} was not an input view: reference exposure assumed"
        hybrid = self.hybrid
        env = world_to_frame_envmap(hybrid.sky_world, R_vol_from_cam, ENVMAP_HEIGHT, ENVMAP_WIDTH) * np.float32(ratio)
        sun = sun_dir_cam = None
        if hybrid.sun_dir is not None:
            sun_dir_cam = R_vol_from_cam.T @ hybrid.sun_dir
            sun = SunLight(sun_dir_cam, hybrid.sun_irradiance.detach().numpy().astype(np.float64) * ratio,
                           hybrid.sun_half_angle_rad, float(self.params.get("sun_visibility", 1.0)))
        base = known if same else None
        params = dict(self.params)
        if base is not None:
            params["l1"] = base.params
        return LightingEstimate(
            light_cam=DistantLight(env, sun), sun_dir_cam=sun_dir_cam,
            sun_source=self.params.get("sun_source", "none") if sun is not None else "none",
            sun_visibility=float(self.params.get("sun_visibility", 0.0)) if sun is not None else 0.0,
            level=self.level, reason=self.reason + note, params=params, timing_s=dict(self.timing_s),
            hybrid=hybrid, T_vol_from_cam=T_vol_from_cam, radiometric_scale=ratio,
        )


def _same_view(key, view) -> bool:
    return key is not None and key == (view.channel, view.sample_data_token, view.image_path)


def _join(a: str, b: str) -> str:
    return a if not b or b in a else f"{a}; {b}"


def volume_frame(view) -> np.ndarray:
    """``T_global_from_vol`` (4, 4): z = global up, x = the camera's horizontal viewing direction, origin on the
    ground (the ego's z = 0) under the camera centre."""
    T = np.asarray(view.T_global_from_cam)
    fwd = T[:3, 2]
    yaw = float(np.arctan2(fwd[1], fwd[0]))
    ground_z = float(np.asarray(view.T_global_from_ego)[2, 3])
    return make_transform(yaw_to_quat(yaw), [T[0, 3], T[1, 3], ground_z])


def _shared_cloud(fits: list) -> tuple[float | None, str | None, dict]:
    """Cloud cover pooled over views: the median of the views with the best kind of evidence."""
    found = {}
    for fit in fits:
        if fit.ev is None:
            continue
        cloud, source, _ = _l1_cloud(fit.ev)
        found.setdefault(source, []).append((fit.view.channel, cloud))
    for source in CLOUD_SOURCE_RANK:
        if source in found:
            channels = [c for c, _ in found[source]]
            cloud = float(np.median([v for _, v in found[source]]))
            return cloud, f"cloud cover {cloud:.2f} from {source.replace('_', ' ')} of {', '.join(channels)}", {
                k: [list(x) for x in v] for k, v in found.items()}
    return None, None, {}


def _placement_points_vol(views, T_vol_from_cams, query_point_cam) -> np.ndarray:
    """Ground points (P, 3) of the placements to judge: the query point, else 12/20/30 m along each camera's axis."""
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


def _height_map(observations: list[ViewObservation], lidar_vol: np.ndarray | None) -> tuple[HeightMap, dict]:
    """Occluder heights from LiDAR + unprojected pixels with the street-canyon prior of :func:`structure_heights`."""
    cam = np.concatenate([o.points for o in observations]) if observations else np.zeros((0, 3))
    cap = np.concatenate([o.capped for o in observations]) if observations else np.zeros(0, bool)
    cam_map = HeightMap.from_points(cam)
    cap_map = HeightMap.from_points(np.concatenate([cam[cap][:, :2], np.ones((cap.sum(), 1))], axis=1))
    all_pts = np.concatenate([cam, lidar_vol]) if lidar_vol is not None and len(lidar_vol) else cam
    hmap = HeightMap.from_points(all_pts)
    n = hmap.heights_m.shape[0]
    c = (np.arange(n) + 0.5) * hmap.cell_m - hmap.half_extent_m
    r = np.hypot(c[:, None], c[None, :])
    cam_top = np.where(cam_map.heights_m > 0, cam_map.heights_m, -np.inf)
    heights, stats = structure_heights(hmap.heights_m, cam_top, cap_map.heights_m > 0, r, hmap.heights_m >= 1.0)
    return HeightMap(heights.astype(np.float32), hmap.cell_m, hmap.half_extent_m), stats


def _restrict(obs: ViewObservation, grid: LogGrid) -> ViewObservation:
    """Move the points outside the grid's box to the observation's pixels "at infinity" (distant scenery)."""
    lo, hi = grid.bounds()
    inside = ((obs.points >= lo) & (obs.points <= hi)).all(axis=1)
    if inside.all():
        return obs
    d = obs.points[~inside] - obs.camera_centre
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    n_out = int((~inside).sum())
    return replace(
        obs, points=obs.points[inside], radiance=obs.radiance[inside], view_dirs=obs.view_dirs[inside],
        capped=obs.capped[inside], far_dirs=np.concatenate([obs.far_dirs, d]),
        far_radiance=np.concatenate([obs.far_radiance, obs.radiance[~inside]]),
        far_is_sky=np.concatenate([obs.far_is_sky, np.zeros(n_out, bool)]),
        far_saturated=np.concatenate([obs.far_saturated, np.zeros(n_out, bool)]),
    )


def _sky_horizontal_irradiance(dome: np.ndarray) -> np.ndarray:
    """(3,) irradiance of a world-convention dome's upper hemisphere on a horizontal surface."""
    H, W = dome.shape[:2]
    d = world_envmap_directions(H, W).reshape(-1, 3)
    w = equirect_solid_angles(H, W).reshape(-1) * np.maximum(d[:, 2], 0.0)
    return w @ dome.reshape(-1, 3).astype(np.float64)


def estimate_sample_lighting(sample, cameras: Sequence[str], level: str) -> "SampleLighting":
    """The lighting of a sample built once from the given cameras' images (the first is the reference).

    Args:
        sample: a :class:`streetaug.datasets.sample.Sample` (cameras, LiDAR, location).
        cameras: camera channels to use, e.g. ``["CAM_FRONT", "CAM_FRONT_LEFT"]``.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
    """
    from ..core import InputError

    cams = list(cameras)
    if not cams:
        raise InputError(f"sample {sample.token}: no cameras given; available: {', '.join(sorted(sample.cameras))}")
    missing = [c for c in cams if c not in sample.cameras]
    if missing:
        raise InputError(f"sample {sample.token}: camera(s) {missing} not found; available: {', '.join(sorted(sample.cameras))}")
    return estimate_views_lighting([sample.cameras[c] for c in cams], sample.location, level, lidar=sample.lidar,
                                   boxes=sample.boxes)


def estimate_views_lighting(views: Sequence, location: str | None, level: str, lidar=None, boxes=None,
                            query_point_cam: np.ndarray | None = None,
                            grid: LogGrid | None = None) -> SampleLighting:
    """Lighting shared by camera views of one moment (see module doc); ``views[0]`` is the reference.

    Args:
        views: ``CameraView`` objects.
        location: the log's location for the ephemeris, or None.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        lidar: the sample's ``LidarSweep`` or None.
        boxes: the sample's annotated ``Box`` objects (global frame) or None (evidence of the sun's visibility).
        query_point_cam: placement (reference camera frame) for L2's centre and auto's judgement.
        grid: override of the level's volume grid (benchmarks).
    """
    check_level(level)
    views = list(views)
    if not views:
        raise ValueError("estimate_views_lighting: no views given")
    t_start = time.perf_counter()
    timing: dict = {}
    for v in views:
        np.asarray(v.image)  # decode first: decoding is not part of the timings
    t0 = time.perf_counter()
    ref = views[0]
    T_global_from_vol = volume_frame(ref)
    keys = {v.channel: (v.channel, v.sample_data_token, v.image_path) for v in views}

    def done(result: SampleLighting) -> SampleLighting:
        return replace(result, view_keys=keys)

    if level == "L0":
        per_view = {v.channel: _estimate_l0(np.asarray(v.image), {}) for v in views}
        timing["total"] = time.perf_counter() - t0
        return done(SampleLighting("L0", "L0: constant dome of each image's mean linear radiance", ref.channel,
                                   per_view, {c: 1.0 for c in per_view}, None, T_global_from_vol,
                                   {"location": location}, timing))
    fits = [_l1_view_evidence(v, location, {}, boxes, lidar) for v in views]
    cloud, cloud_note, cloud_evidence = _shared_cloud(fits) if len(views) > 1 else (None, None, {})
    per_view = {f.view.channel: _l1_estimate(f, {}, cloud, cloud_note) for f in fits}
    ref_est = per_view[ref.channel]
    cloud = float(ref_est.params["cloud_cover"])
    scale_ref = float(ref_est.params["scale"])
    # L1 fits each camera on its own scale; the shared volume (below) needs the cameras' exposure ratios.
    ratios = {v.channel: 1.0 for v in views}
    timing["l1"] = time.perf_counter() - t0
    params = {
        "location": location, "cloud_cover": cloud, "scale": scale_ref, "reference_camera": ref.channel,
        "cameras": [v.channel for v in views], "exposure_ratio": ratios,
        "cloud_evidence": cloud_evidence,
        "sun_source": ref_est.sun_source, "sun_visibility": ref_est.sun_visibility, "turbidity": DEFAULT_TURBIDITY,
    }
    reason_l1 = ref_est.reason
    if level == "L1":
        timing["total"] = time.perf_counter() - t0
        return done(SampleLighting("L1", reason_l1, ref.channel, per_view, ratios, None, T_global_from_vol,
                                   _clean(params), timing))

    # ---- exposure of each camera relative to the reference, then observations in the volume frame
    t = time.perf_counter()
    ratios, params["exposure"] = exposure_ratios(views, lidar.points_global if lidar is not None else None)
    params["exposure_ratio"] = ratios
    timing["exposure"] = time.perf_counter() - t
    t = time.perf_counter()
    T_vol_from_global = invert_transform(T_global_from_vol)
    T_vol_from_cams = [T_vol_from_global @ np.asarray(v.T_global_from_cam) for v in views]
    lidar_vol = lidar_points_in_volume(lidar, T_vol_from_global) if lidar is not None else None
    widest = L3_GRID if grid is None or grid.half_extent_xy_m < L3_GRID.half_extent_xy_m else grid
    observations = [_restrict(_observe(v, T_vc, ratios[v.channel], lidar_vol, fit.work), widest)
                    for v, T_vc, fit in zip(views, T_vol_from_cams, fits)]
    timing["observe"] = time.perf_counter() - t

    # ---- level choice
    placements = _placement_points_vol(views, T_vol_from_cams, query_point_cam)
    l2_centre = placements[:, :2].mean(axis=0)
    if level == "auto":
        t = time.perf_counter()
        level, auto_reason, params["auto"] = _choose_auto(ref_est, fits[0], T_vol_from_cams[0], observations,
                                                          lidar_vol, placements, cloud, scale_ref)
        timing["auto"] = time.perf_counter() - t
        if level in ("L0", "L1"):
            if level == "L0":
                per_view = {v.channel: _estimate_l0(np.asarray(v.image), {}) for v in views}
            timing["total"] = time.perf_counter() - t0
            return done(SampleLighting(level, _join(auto_reason, reason_l1 if level == "L1" else ""), ref.channel,
                                       per_view, ratios, None, T_global_from_vol, _clean(params), timing))
    else:
        auto_reason = f"{level} requested"
    if grid is None:
        grid = L3_GRID if level == "L3" else replace(L2_GRID, centre_xy_m=(float(l2_centre[0]), float(l2_centre[1])))
    if grid is not widest:
        observations = [_restrict(o, grid) for o in observations]

    # ---- sky dome + sun + volume
    hybrid, build_params = _build_hybrid(ref_est, T_vol_from_cams[0], observations, lidar_vol, grid, cloud,
                                         scale_ref, timing)
    geometry = "LiDAR densified" if lidar is not None else "no LiDAR: street-canyon prior"
    reason = (f"{level}: " if not auto_reason.startswith("auto") else "") + _join(
        auto_reason, f"sky dome + VSG volume {grid.shape} over +-{grid.half_extent_xy_m:g} m from "
        f"{len(views)} view(s) ({geometry}); {reason_l1}")
    params.update(build_params, T_global_from_vol=T_global_from_vol.tolist())
    timing["total"] = time.perf_counter() - t0
    timing["wall_with_decode"] = time.perf_counter() - t_start
    return done(SampleLighting(level, reason, ref.channel, per_view, ratios, hybrid, T_global_from_vol,
                               _clean(params), timing))


def _observe(view, T_vol_from_cam: np.ndarray, ratio: float, lidar_vol: np.ndarray | None, work) -> ViewObservation:
    """One camera's observation (:func:`observe_view`) with the LiDAR and the ground plane z = 0 in its frame."""
    T_cam_from_vol = invert_transform(T_vol_from_cam)
    n_cam = T_cam_from_vol[:3, :3] @ np.array([0.0, 0.0, 1.0])
    ground = (n_cam, float(-n_cam @ T_cam_from_vol[:3, 3]))
    pts_cam = transform_points(T_cam_from_vol, lidar_vol) if lidar_vol is not None else None
    return observe_view(view, T_vol_from_cam, ratio, pts_cam, ground, work=work)


def _choose_auto(ref_est: LightingEstimate, ref_fit, T_vol_from_cam: np.ndarray, observations: list[ViewObservation],
                 lidar_vol: np.ndarray | None, placements: np.ndarray, cloud: float, scale: float) -> tuple[str, str, dict]:
    """``auto``: predicted errors of each level at the placements from the occluder height map -> (level, reason, info)."""
    hmap, canyon = _height_map(observations, lidar_vol)
    pts = np.concatenate([region_points(p) for p in placements])
    sun = ref_est.light_cam.sun
    e_sun = float(luminance(sun.irradiance_rgb)) if sun is not None else 0.0
    sun_vol = (T_vol_from_cam[:3, :3] @ ref_est.sun_dir_cam) if ref_est.sun_dir_cam is not None else None
    model = model_sky_world(_sky_sun_vol(ref_est, T_vol_from_cam), DEFAULT_TURBIDITY, cloud, GROUND_ALBEDO, scale, 32, 64)
    e_sky_h = float(luminance(_sky_horizontal_irradiance(model)))
    hdr = ref_fit.work.hdr if ref_fit.work is not None else ldr_uint8_to_hdr(np.asarray(ref_fit.view.image))
    l0_e = float(np.pi * luminance(hdr.reshape(-1, 3).mean(axis=0)))
    errors, evidence = predicted_errors(hmap, pts, sun_vol, e_sun, e_sky_h, l0_e, placements[:, :2].mean(axis=0))
    level, reason = choose_level(errors)
    return level, reason, {"predicted_errors": errors, "evidence": evidence, "canyon": canyon,
                           "placements_vol": placements.tolist()}


def _build_hybrid(ref_est: LightingEstimate, T_vol_from_cam: np.ndarray, observations: list[ViewObservation],
                  lidar_vol: np.ndarray | None, grid: LogGrid, cloud: float, scale: float,
                  timing: dict) -> tuple[HybridLighting, dict]:
    """Sky dome (model corrected by the images), the sun (L1's, following the dome's correction) and the volume."""
    t = time.perf_counter()
    model = model_sky_world(_sky_sun_vol(ref_est, T_vol_from_cam), DEFAULT_TURBIDITY, cloud, GROUND_ALBEDO, scale,
                            DOME_HEIGHT, DOME_WIDTH)
    dome, dome_stats = build_sky_dome(model, observations)
    timing["sky_dome"] = time.perf_counter() - t
    t = time.perf_counter()
    out = {"grid": grid.to_json(), "sky_dome": dome_stats}
    sun_dir_vol = sun_irr = None
    if ref_est.light_cam.sun is not None:
        sun_dir_vol = T_vol_from_cam[:3, :3] @ ref_est.light_cam.sun.direction
        factor, how = _sun_factor(dome, model)
        sun_irr = np.asarray(ref_est.light_cam.sun.irradiance_rgb, dtype=np.float64) * factor
        out["sun_irradiance_factor"] = {"factor": factor, "from": how}
    light = DistantSun(sun_dir_vol, np.zeros(3) if sun_irr is None else sun_irr, _sky_horizontal_irradiance(dome))
    params_t, out["volume"] = build_volume(grid, observations, lidar_vol, light, dome, GROUND_ALBEDO)
    timing["volume"] = time.perf_counter() - t
    hybrid = HybridLighting(
        torch.from_numpy(dome), sun_dir_vol, None if sun_irr is None else torch.from_numpy(sun_irr.astype(np.float32)),
        grid=grid, params=params_t,
    )
    return hybrid, out


def _sun_factor(dome: np.ndarray, model: np.ndarray) -> tuple[float, str]:
    """How much to scale L1's sun so that it follows the image's correction of the sky dome.

    The observed sky pixels set the dome's level on the image's scale; L1's model (with the fitted cloud
    cover) sets the sun/sky ratio, which is kept: the sun is scaled like the dome's horizontal sky irradiance.
    (Deriving the sun from a lit/shadow contrast instead overestimates it wherever the shadowed road also loses
    sky to the occluder: +94 % at an 11 deg sun on the bundled scenes.) Clamped to [0.25, 4].
    """
    factor = float(luminance(_sky_horizontal_irradiance(dome))) / max(
        float(luminance(_sky_horizontal_irradiance(model))), 1e-12)
    return float(np.clip(factor, 0.25, 4.0)), "the dome's correction of the sky model (L1's sun/sky ratio kept)"


def _sky_sun_vol(ref_est: LightingEstimate, T_vol_from_cam: np.ndarray) -> np.ndarray:
    """The sun direction that shapes the sky model (the real one, also below the horizon; nominal without one)."""
    d = np.asarray(ref_est.params.get("sky_sun_direction_camera", [0.0, -0.7071, 0.7071]), dtype=np.float64)
    return rotate_vectors(T_vol_from_cam, d[None])[0]
