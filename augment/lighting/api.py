"""The lighting's front door: one camera, a sample's cameras, or a bare image -> its lighting, at any level.

This is the only place that chooses where the sun comes from (:func:`view_estimate`), for every level and every
input:

* the **ephemeris** (:mod:`.sun`) when the view has a location and a timestamp and the sun is above the horizon:
  the parametric sky fitted to the image (:func:`.parametric.ephemeris_estimate`);
* **no sun** when the ephemeris puts it below the horizon (night / twilight,
  :func:`.parametric.night_estimate`);
* the **learned image model** (:mod:`.skynet`, :func:`.learned.learned_sky_estimate`) when the ephemeris cannot
  place the sun (no location, no timestamp, a bare image): the sun from the image when the model is
  confident, else a diffuse sky.

Levels (see :mod:`.levels`): ``L0`` a constant dome of the image's mean radiance; ``L1`` the sun and sky
above, distant light only; ``L2`` / ``L3`` the L1 sun + a sky dome corrected by the images + a VSG volume near
the placement / around the camera (:mod:`.multiview`); ``auto`` the cheapest sufficient one. The volume levels
build on the per-camera L1 estimates made here, so they share the same sun.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Sequence

import numpy as np

from ...datasets.sample import Box, CameraView, LidarSweep, Sample
from ..core import InputError, check_shape, make_transform
from .evidence import prepare_image
from .exposure import exposure_ratios
from .image_dome import image_corrected_envmap, seen_pixels
from .learned import learned_sky_estimate
from .multiview import EarlierKeyframe, volume_frame, volume_sample_lighting
from .parametric import (
    DEFAULT_CAMERA_HEIGHT_M,
    DEFAULT_TURBIDITY,
    ViewInputs,
    ephemeris_estimate,
    l0_estimate,
    night_estimate,
    shared_cloud,
    view_inputs,
)
from .predicted_view import observed_ldr, predicted_ldr
from .types import LightingEstimate, SampleLighting, check_level, join_reasons, json_clean, view_key
from .volume import LogGrid


def _work(vi: ViewInputs):
    return vi.work if vi.work is not None else prepare_image(np.asarray(vi.view.image), vi.view.K, vi.up_cam)


def _ego_forward_cam(view: CameraView) -> np.ndarray:
    """(3,) the ego's forward axis (+x, the street's direction when driving) in the view's camera frame."""
    return np.asarray(view.T_ego_from_cam, np.float64)[0, :3]


def seen_estimate(est: LightingEstimate, vi: ViewInputs) -> LightingEstimate:
    """An L1 estimate whose map takes the image's radiance where the camera saw something
    (:func:`.image_dome.image_corrected_envmap`): on the image's scale in every direction it saw, the model's
    shape corrected per elevation elsewhere. The sun is unchanged."""
    t0 = time.perf_counter()
    envmap, stats = image_corrected_envmap(est.light_cam.envmap, seen_pixels(_work(vi)), vi.up_cam,
                                           forward_cam=_ego_forward_cam(vi.view))
    timing = dict(est.timing_s) | {"image_envmap": time.perf_counter() - t0}
    return replace(est, light_cam=replace(est.light_cam, envmap=envmap),
                   params=json_clean(dict(est.params) | {"image_envmap": stats}), timing_s=timing,
                   reason=f"{est.reason}; map: the image's radiance where seen ({100 * stats['seen_fraction']:.0f} % "
                          f"of the sphere), the model corrected per elevation elsewhere")


def instant_estimates(per_view: dict[str, LightingEstimate], inputs: Sequence[ViewInputs],
                      lidar: LidarSweep | None) -> tuple[dict[str, LightingEstimate], dict[str, float], dict]:
    """One L1 light for all cameras of an instant: the reference's (``inputs[0]``) sun and sky model, its map
    corrected by every camera's pixels (each on the reference's scale through its exposure ratio,
    :func:`.exposure.exposure_ratios`), given to each camera turned into its frame and times its ratio.

    Returns (channel -> estimate, channel -> exposure ratio, the exposure report).
    """
    t0 = time.perf_counter()
    views = [vi.view for vi in inputs]
    ratios, report = exposure_ratios(views, lidar.points_global if lidar is not None else None)
    ref_vi = inputs[0]
    ref = per_view[ref_vi.view.channel]
    for vi in inputs[1:]:  # no shared LiDAR points: the ratio of the two images' own L1 scales
        c = vi.view.channel
        how = report.get("per_camera", {}).get(c, "no overlap")
        if how.startswith("no overlap") and ref.fit is not None and per_view[c].fit is not None:
            ratios[c] = float(per_view[c].fit.scale / max(ref.fit.scale, 1e-12))
            report.setdefault("per_camera", {})[c] = "ratio of the images' own L1 scales (no shared LiDAR points)"
    R_ref_from_global = np.asarray(ref_vi.view.T_cam_from_global)[:3, :3]
    pixels = [seen_pixels(_work(vi), R_ref_from_global @ np.asarray(vi.view.T_global_from_cam)[:3, :3],
                          1.0 / ratios[vi.view.channel]) for vi in inputs]
    envmap, stats = image_corrected_envmap(ref.light_cam.envmap, pixels, ref_vi.up_cam,
                                           forward_cam=_ego_forward_cam(ref_vi.view))
    ref_light = replace(ref.light_cam, envmap=envmap)
    seconds = time.perf_counter() - t0
    note = (f"map: the {len(views)} cameras' radiance where seen ({100 * stats['seen_fraction']:.0f} % of the "
            f"sphere), the model corrected per elevation elsewhere; one light for the instant "
            f"({ref_vi.view.channel}'s sun and sky)")
    out = {}
    for vi in inputs:
        c = vi.view.channel
        R = np.asarray(vi.view.T_cam_from_global)[:3, :3] @ R_ref_from_global.T
        light = ref_light.rotated(R)
        k = float(ratios[c])
        light = replace(light, envmap=light.envmap * np.float32(k),
                        sun=None if light.sun is None else replace(light.sun, irradiance_rgb=light.sun.irradiance_rgb * k))
        sun_dir = None if ref.sun_dir_cam is None else R @ ref.sun_dir_cam
        est = per_view[c]
        fit, params = est.fit, dict(est.params)
        if ref.fit is not None:  # the metadata says what the light is: the reference's sky on this exposure
            own = est.fit
            fit = replace(ref.fit, scale=float(ref.fit.scale * k), sky_sun_dir_cam=R @ np.asarray(ref.fit.sky_sun_dir_cam),
                          up_cam=vi.up_cam, camera_height_m=own.camera_height_m if own is not None else vi.camera_height_m)
            params = fit.to_json() | {"own_fit": None if own is None else own.to_json()}
        out[c] = replace(est, light_cam=light, sun_dir_cam=sun_dir, sun_source=ref.sun_source,
                         sun_visibility=ref.sun_visibility, fit=fit,
                         params=json_clean(params | {"image_envmap": stats, "exposure_ratio": k}),
                         timing_s=dict(est.timing_s) | {"image_envmap": seconds},
                         reason=f"{ref.reason}; {note}" if c == ref_vi.view.channel else
                         f"{ref.reason}; {note}; exposure x{k:.3f} of {ref_vi.view.channel}")
    return out, ratios, report


def view_estimate(vi: ViewInputs, timing: dict, cloud: float | None = None,
                  cloud_note: str | None = None) -> LightingEstimate:
    """L1 of one view: the sun from the ephemeris, none (night), or the learned image model (see module doc).

    ``cloud`` overrides the view's own cloud cover (the sample's pooled one) for an ephemeris sun.
    """
    if vi.sun_pos is None:  # the ephemeris cannot place the sun: the image has to
        est = learned_sky_estimate(np.asarray(vi.view.image), vi.view.K, vi.up_cam, vi.camera_height_m)
        return replace(est, reason=f"{vi.fallback}; {est.reason}")
    if vi.sun_pos.elevation_deg <= 0.0:
        return night_estimate(vi, timing)
    return ephemeris_estimate(vi, timing, cloud, cloud_note)


def seen_l1(l1: SampleLighting, inputs: Sequence[ViewInputs], lidar: LidarSweep | None) -> SampleLighting:
    """L1 of a sample with the maps taken from its images: one camera's own (:func:`seen_estimate`), several
    cameras' one light for the instant (:func:`instant_estimates`)."""
    if len(inputs) == 1:
        vi = inputs[0]
        return replace(l1, per_view={vi.view.channel: seen_estimate(l1.per_view[vi.view.channel], vi)})
    per_view, ratios, report = instant_estimates(l1.per_view, inputs, lidar)
    params = dict(l1.params) | {"exposure_ratio": ratios, "exposure": report}
    return replace(l1, per_view=per_view, exposure_ratio=ratios, params=json_clean(params))


def estimate_views_lighting(views: Sequence[CameraView], location: str | None, level: str,
                            lidar: LidarSweep | None = None, boxes: list[Box] | None = None,
                            query_point_cam: np.ndarray | None = None,
                            grid: LogGrid | None = None, earlier: EarlierKeyframe | None = None) -> SampleLighting:
    """Lighting shared by camera views of one moment; ``views[0]`` is the reference (volume frame and scale).

    Args:
        views: the cameras' views.
        location: the log's location for the ephemeris, or None.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        lidar: the sample's LiDAR sweep, or None.
        boxes: the sample's annotated boxes (global frame), or None (evidence of the sun's visibility).
        query_point_cam: placement (reference camera frame, metres) for L2's centre and auto's judgement.
        grid: override of the level's volume grid (benchmarks).
        earlier: the previous keyframe (:func:`earlier_keyframe`): at L2/L3 its cameras' seen surfaces fill
            what the views' own leave open (what is now behind and above them); None: the views alone.
    """
    check_level(level)
    base, inputs, started = _model_l1(views, location, level, lidar, boxes)
    return base if level == "L0" else _from_model_l1(base, inputs, started, level, lidar, query_point_cam, grid,
                                                     earlier)


def _model_l1(views: Sequence[CameraView], location: str | None, level: str, lidar: LidarSweep | None,
              boxes: list[Box] | None) -> tuple[SampleLighting, list[ViewInputs], tuple[float, float]]:
    """The sample's L0 (``level`` "L0"), else its L1 with the sky model's maps (the sun, cloud and scale every
    level builds on); the views' L1 inputs; ``perf_counter`` at the start of the estimate and of the decoding."""
    views = list(views)
    if not views:
        raise ValueError("estimate_views_lighting: no views given")
    t_start = time.perf_counter()
    for v in views:
        np.asarray(v.image)  # decode first: decoding is not part of the timings
    t0 = time.perf_counter()
    timing: dict = {}
    ref = views[0]
    base = SampleLighting("L0", "L0: constant dome of each image's mean linear radiance", ref.channel, {},
                          {v.channel: 1.0 for v in views}, None, volume_frame(ref), {"location": location}, timing,
                          view_keys={v.channel: view_key(v) for v in views},
                          T_global_from_ref_cam=np.asarray(ref.T_global_from_cam),
                          input_mean_ldr={v.channel: float(np.asarray(v.image)[::4, ::4].mean()) / 255.0 for v in views})
    if level == "L0":
        per_view = {v.channel: l0_estimate(np.asarray(v.image), {}) for v in views}
        timing["total"] = time.perf_counter() - t0
        return replace(base, per_view=per_view), [], (t0, t_start)
    inputs = [view_inputs(v, location, {}, boxes, lidar) for v in views]
    cloud, cloud_note, cloud_evidence = shared_cloud(inputs) if len(views) > 1 else (None, None, {})
    per_view = {vi.view.channel: view_estimate(vi, {}, cloud, cloud_note) for vi in inputs}
    ref_est = per_view[ref.channel]
    timing["l1"] = time.perf_counter() - t0
    params = {
        "location": location, "cloud_cover": None if ref_est.fit is None else float(ref_est.fit.cloud_cover),
        "scale": None if ref_est.fit is None else float(ref_est.fit.scale), "reference_camera": ref.channel,
        "cameras": [v.channel for v in views], "exposure_ratio": dict(base.exposure_ratio),
        "cloud_evidence": cloud_evidence,
        "sun_source": ref_est.sun_source, "sun_visibility": ref_est.sun_visibility, "turbidity": DEFAULT_TURBIDITY,
    }
    return replace(base, level="L1", reason=ref_est.reason, per_view=per_view, params=json_clean(params),
                   sun_source=ref_est.sun_source, sun_visibility=float(ref_est.sun_visibility)), inputs, (t0, t_start)


def _from_model_l1(l1: SampleLighting, inputs: list[ViewInputs], started: tuple[float, float], level: str,
                   lidar: LidarSweep | None, query_point_cam: np.ndarray | None, grid: LogGrid | None,
                   earlier: EarlierKeyframe | None = None) -> SampleLighting:
    """A level ("L1" | "L2" | "L3" | "auto") of a sample from its model L1 (:func:`_model_l1`; left unchanged, so
    one model L1 can serve several levels)."""
    t0, t_start = started
    timing = dict(l1.timing_s)
    l1 = replace(l1, timing_s=timing)
    if level == "L1":
        l1 = seen_l1(l1, inputs, lidar)
        timing["total"] = time.perf_counter() - t0
        return l1
    # the volume levels build on the model's sky (the images correct it themselves, in the sky dome)
    views = [vi.view for vi in inputs]
    out = volume_sample_lighting(l1, views, inputs, level, lidar, query_point_cam, grid, timing, t0, earlier)
    if out.level == "L1":  # auto chose L1
        out = seen_l1(out, inputs, lidar)
    if out.hybrid is not None:
        timing["wall_with_decode"] = time.perf_counter() - t_start
    return out


def earlier_keyframe(previous: Sample, cameras: Sequence[str]) -> EarlierKeyframe:
    """The ``cameras`` of the previous keyframe ``previous`` (those it has) and its LiDAR, as the ``earlier``
    input of :func:`estimate_views_lighting`."""
    return EarlierKeyframe(tuple(previous.cameras[c] for c in cameras if c in previous.cameras), previous.lidar)


def estimate_sample_lighting(sample: Sample, cameras: Sequence[str], level: str,
                             query_point_cam: np.ndarray | None = None,
                             previous: Sample | None = None) -> SampleLighting:
    """The lighting of a sample built once from the given cameras' images (the first is the reference).

    Args:
        sample: the sample (cameras, LiDAR, annotated boxes, location).
        cameras: camera channels to use, e.g. ``["CAM_FRONT", "CAM_FRONT_LEFT"]``.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        query_point_cam: placement (first camera's frame, metres) for L2's centre and auto's judgement.
        previous: the sample's previous keyframe, or None: its same cameras' seen surfaces fill what these
            leave open (:func:`earlier_keyframe`).
    """
    cams = list(cameras)
    if not cams:
        raise InputError(f"sample {sample.token}: no cameras given; available: {', '.join(sorted(sample.cameras))}")
    missing = [c for c in cams if c not in sample.cameras]
    if missing:
        raise InputError(f"sample {sample.token}: camera(s) {missing} not found; available: {', '.join(sorted(sample.cameras))}")
    return estimate_views_lighting([sample.cameras[c] for c in cams], sample.location, level, lidar=sample.lidar,
                                   boxes=sample.boxes, query_point_cam=query_point_cam,
                                   earlier=None if previous is None else earlier_keyframe(previous, cams))


def estimate_lighting(view: CameraView, location: str | None, level: str = "L1", *, lidar: LidarSweep | None = None,
                      boxes: list[Box] | None = None, query_point_cam: np.ndarray | None = None) -> LightingEstimate:
    """Lighting of one camera view (camera frame, image scale).

    Args:
        view: the camera view (image, K, poses, timestamp_us).
        location: the log's location (e.g. ``singapore-onenorth``) for the ephemeris; None if unknown.
        level: "L0" | "L1" | "L2" | "L3" | "auto" (see module doc).
        lidar: the sample's LiDAR sweep (L2/L3 geometry; without it the ground plane and vertical facades alone).
        boxes: the sample's annotated boxes (global frame): the road in and out of their predicted shadows is
            evidence of the sun's visibility.
        query_point_cam: (3,) the placement (camera frame, metres) that L2 centres on and ``auto`` judges;
            default: the ground 15 m straight ahead.
    """
    check_level(level)
    if level in ("L2", "L3", "auto"):
        return estimate_views_lighting([view], location, level, lidar=lidar, boxes=boxes,
                                       query_point_cam=query_point_cam).for_view(view)
    t0 = time.perf_counter()
    image = np.asarray(view.image)
    timing = {"decode": time.perf_counter() - t0}
    if level == "L0":
        return l0_estimate(image, timing)
    vi = view_inputs(view, location, timing, boxes, lidar)
    return seen_estimate(view_estimate(vi, timing), vi)


def image_only_view(image_rgb: np.ndarray, K: np.ndarray,
                    camera_height_m: float = DEFAULT_CAMERA_HEIGHT_M) -> CameraView:
    """A view of an image without metadata: a level camera ``camera_height_m`` above the ground, looking along
    ego +x, at the global origin, no timestamp (0)."""
    H, W = image_rgb.shape[:2]
    T_ego_from_cam = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                                    [0.0, 0.0, camera_height_m])
    return CameraView("IMAGE", "", "", np.asarray(K, dtype=np.float64), W, H, T_ego_from_cam, np.eye(4),
                      0).with_image(image_rgb)


def estimate_lighting_from_image(image_rgb: np.ndarray, K: np.ndarray, level: str = "L1",
                                 for_map: bool = False) -> LightingEstimate:
    """Lighting of an image without metadata: a level camera (up = -y) 1.5 m above the ground; the sun from the
    learned image model when it is confident, else none (a diffuse sky), at every level.

    L2/L3/auto add a volume built from the image alone: the ground plane and vertical facades standing on it.
    ``for_map``: ``auto`` judges the levels by their maps (:func:`estimate_views_lighting_for_map`).
    """
    image_rgb = np.asarray(image_rgb)
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    if image_rgb.dtype != np.uint8:
        raise ValueError(f"image_rgb must be uint8 RGB, got dtype {image_rgb.dtype}")
    check_level(level)
    view = image_only_view(image_rgb, K)
    if level == "L0":
        return l0_estimate(image_rgb, {})
    if level == "L1":
        vi = view_inputs(view, None, {})
        return seen_estimate(view_estimate(vi, {}), vi)
    build = estimate_views_lighting_for_map if for_map else estimate_views_lighting
    return build([view], None, level).for_view(view)


MAP_LEVELS = ("L1", "L2", "L3")
MAP_JUDGE_WIDTH_PX = 160


def map_error(lighting: SampleLighting, views: Sequence[CameraView], width: int = MAP_JUDGE_WIDTH_PX) -> float:
    """Mean squared LDR error of the views the lighting predicts for its input cameras (their own centres, EV 0)
    against their images: how far the written map is from what the cameras saw."""
    return float(np.mean([np.mean((predicted_ldr(lighting, v, width) - observed_ldr(v, width)) ** 2) for v in views]))


def estimate_views_lighting_for_map(views: Sequence[CameraView], location: str | None, level: str,
                                    lidar: LidarSweep | None = None, boxes: list[Box] | None = None,
                                    query_point_cam: np.ndarray | None = None,
                                    earlier: EarlierKeyframe | None = None) -> SampleLighting:
    """:func:`estimate_views_lighting` for a caller that writes the map (``predict-light``): ``auto`` judges the
    levels by the error of their maps against the images (:func:`map_error`), cheapest first, and never keeps a
    level whose map is further from the images than the next level's; any other level is built as asked.
    ``earlier``: as :func:`estimate_views_lighting`'s."""
    if level != "auto":
        return estimate_views_lighting(views, location, level, lidar, boxes, query_point_cam, earlier=earlier)
    model, inputs, started = _model_l1(views, location, "L1", lidar, boxes)  # one L1 fit for every candidate
    errors: dict[str, float] = {}
    chosen = None
    for lv in MAP_LEVELS:
        sl = _from_model_l1(model, inputs, started, lv, lidar, query_point_cam, None, earlier)
        errors[lv] = map_error(sl, views)
        if chosen is not None and errors[lv] >= errors[chosen[0]]:
            break
        chosen = (lv, sl)
    level_chosen, sl = chosen
    listing = ", ".join(f"{k} {10 * np.log10(1.0 / max(v, 1e-12)):.1f} dB" for k, v in errors.items())
    reason = (f"auto (map): {level_chosen}, the cheapest level whose map is no further from the images than the "
              f"next level's (PSNR of each level's map rendered into the input cameras: {listing})")
    judged = {"auto_map_psnr_db": {k: float(10 * np.log10(1.0 / max(v, 1e-12))) for k, v in errors.items()}}
    per_view = {c: replace(e, params=json_clean(dict(e.params) | judged)) for c, e in sl.per_view.items()}
    return replace(sl, reason=join_reasons(reason, sl.reason), params=json_clean(dict(sl.params) | judged),
                   per_view=per_view)


def estimate_instant_lighting(sample: Sample, camera: str, level: str, query_point_cam: np.ndarray | None = None,
                              for_map: bool = False, previous: Sample | None = None) -> LightingEstimate:
    """One camera's lighting from the estimate of its whole instant: all the sample's cameras (``camera`` the
    reference), so that every camera of a sample reports the same sun and sky.

    A camera other than ``camera`` whose image cannot be read is left out (the reason and ``params["instant"]``
    name it and why); ``camera``'s own image must be readable (its error names the file).

    Args:
        sample: the sample.
        camera: the camera whose lighting is returned (its frame and scale).
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        query_point_cam: placement (``camera``'s frame, metres) for L2's centre and the placement judgement.
        for_map: ``auto`` judges by the written map (:func:`estimate_views_lighting_for_map`), not the placement.
        previous: the sample's previous keyframe, or None: at L2/L3 its same cameras' seen surfaces fill what
            the instant's leave open (:func:`earlier_keyframe`; about +35 % lighting time on six cameras).
    """
    if camera not in sample.cameras:
        raise InputError(f"sample {sample.token}: camera {camera!r} not found; available: "
                         f"{', '.join(sorted(sample.cameras))}")
    view = sample.cameras[camera]
    np.asarray(view.image)  # the asked camera must be readable: its error names the file
    used, skipped = [view], {}
    for c in sorted(sample.cameras):
        if c == camera:
            continue
        try:
            np.asarray(sample.cameras[c].image)
            used.append(sample.cameras[c])
        except InputError as exc:
            skipped[c] = str(exc)
    build = estimate_views_lighting_for_map if for_map else estimate_views_lighting
    earlier = None if previous is None else earlier_keyframe(previous, [v.channel for v in used])
    sl = build(used, sample.location, level, lidar=sample.lidar, boxes=sample.boxes, query_point_cam=query_point_cam,
               earlier=earlier)
    est = sl.for_view(view)
    note = f"one estimate for the instant from {len(used)} camera(s) ({', '.join(v.channel for v in used)})"
    if skipped:
        note += "; left out (image unreadable): " + "; ".join(f"{c}: {why}" for c, why in skipped.items())
    params = dict(est.params) | {"instant": {"cameras": [v.channel for v in used], "skipped": skipped,
                                             "previous_keyframe": None if previous is None else previous.token}}
    return replace(est, reason=join_reasons(est.reason, note), params=json_clean(params))
