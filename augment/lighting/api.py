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
from .learned import learned_sky_estimate
from .multiview import volume_frame, volume_sample_lighting
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
from .types import LightingEstimate, SampleLighting, check_level, json_clean, view_key
from .volume import LogGrid


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


def estimate_views_lighting(views: Sequence[CameraView], location: str | None, level: str,
                            lidar: LidarSweep | None = None, boxes: list[Box] | None = None,
                            query_point_cam: np.ndarray | None = None,
                            grid: LogGrid | None = None) -> SampleLighting:
    """Lighting shared by camera views of one moment; ``views[0]`` is the reference (volume frame and scale).

    Args:
        views: the cameras' views.
        location: the log's location for the ephemeris, or None.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        lidar: the sample's LiDAR sweep, or None.
        boxes: the sample's annotated boxes (global frame), or None (evidence of the sun's visibility).
        query_point_cam: placement (reference camera frame, metres) for L2's centre and auto's judgement.
        grid: override of the level's volume grid (benchmarks).
    """
    check_level(level)
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
                          T_global_from_ref_cam=np.asarray(ref.T_global_from_cam))
    if level == "L0":
        per_view = {v.channel: l0_estimate(np.asarray(v.image), {}) for v in views}
        timing["total"] = time.perf_counter() - t0
        return replace(base, per_view=per_view)
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
    l1 = replace(base, level="L1", reason=ref_est.reason, per_view=per_view, params=json_clean(params),
                 sun_source=ref_est.sun_source, sun_visibility=float(ref_est.sun_visibility))
    if level == "L1":
        timing["total"] = time.perf_counter() - t0
        return l1
    out = volume_sample_lighting(l1, views, inputs, level, lidar, query_point_cam, grid, timing, t0)
    if out.hybrid is not None:
        timing["wall_with_decode"] = time.perf_counter() - t_start
    return out


def estimate_sample_lighting(sample: Sample, cameras: Sequence[str], level: str,
                             query_point_cam: np.ndarray | None = None) -> SampleLighting:
    """The lighting of a sample built once from the given cameras' images (the first is the reference).

    Args:
        sample: the sample (cameras, LiDAR, annotated boxes, location).
        cameras: camera channels to use, e.g. ``["CAM_FRONT", "CAM_FRONT_LEFT"]``.
        level: "L0" | "L1" | "L2" | "L3" | "auto".
        query_point_cam: placement (first camera's frame, metres) for L2's centre and auto's judgement.
    """
    cams = list(cameras)
    if not cams:
        raise InputError(f"sample {sample.token}: no cameras given; available: {', '.join(sorted(sample.cameras))}")
    missing = [c for c in cams if c not in sample.cameras]
    if missing:
        raise InputError(f"sample {sample.token}: camera(s) {missing} not found; available: {', '.join(sorted(sample.cameras))}")
    return estimate_views_lighting([sample.cameras[c] for c in cams], sample.location, level, lidar=sample.lidar,
                                   boxes=sample.boxes, query_point_cam=query_point_cam)


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
    return view_estimate(view_inputs(view, location, timing, boxes, lidar), timing)


def image_only_view(image_rgb: np.ndarray, K: np.ndarray,
                    camera_height_m: float = DEFAULT_CAMERA_HEIGHT_M) -> CameraView:
    """A view of an image without metadata: a level camera ``camera_height_m`` above the ground, looking along
    ego +x, at the global origin, no timestamp (0)."""
    H, W = image_rgb.shape[:2]
    T_ego_from_cam = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                                    [0.0, 0.0, camera_height_m])
    return CameraView("IMAGE", "", "", np.asarray(K, dtype=np.float64), W, H, T_ego_from_cam, np.eye(4),
                      0).with_image(image_rgb)


def estimate_lighting_from_image(image_rgb: np.ndarray, K: np.ndarray, level: str = "L1") -> LightingEstimate:
    """Lighting of an image without metadata: a level camera (up = -y) 1.5 m above the ground; the sun from the
    learned image model when it is confident, else none (a diffuse sky), at every level.

    L2/L3/auto add a volume built from the image alone: the ground plane and vertical facades standing on it.
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
        return view_estimate(view_inputs(view, None, {}), {})
    return estimate_views_lighting([view], None, level).for_view(view)
