"""The parametric first level: the sky model (:mod:`.sky`) fitted to one image, with the ephemeris sun or none.

Levels L0 and L1 of one camera (see :mod:`.levels`); which of these builders runs is the front door's choice
(:mod:`.api`):

* :func:`l0_estimate` — the paper's "no light" baseline: a constant dome with the image's mean linear radiance.
* :func:`ephemeris_estimate` — sun direction from the ephemeris (location + timestamp), sky from :mod:`.sky`;
  its ``scale`` (physical -> image units) and ``cloud_cover`` (hence sun visibility) fitted to the image.
* :func:`night_estimate` — the ephemeris puts the sun below the horizon: no sun, a diffuse (overcast-shaped)
  sky scaled to the image's ground (:func:`diffuse_estimate`).

How the evidence (:mod:`.evidence`) fixes the fit: a horizontal Lambertian ground of albedo ``GROUND_ALBEDO``
has ``L_lit = scale * albedo * (E_sun_h + E_sky_h) / pi`` and ``L_shadow = scale * albedo * E_sky_h / pi``, so
the ground's lit/shadow contrast fixes the sun visibility (cloud cover) and ``L_lit`` the scale. The sky's
blue/red ratio against the model's clear-sky and overcast ratios gives a second cloud-cover estimate, its
brightness against the model ``scale_sky``. The strongest annotated object's shadow contrast
(>= ``OBJECT_SHADOW_MIN_CONTRAST``) proves a visible sun and outranks the ground split (a faint one proves
nothing: the object may stand in a building's shadow). Without ground shadows the ground median pins the
scale; if both the "all sunlit" and "all in shadow" readings are possible, the one closer to the sky's scale
wins. The result is on the image's scale: a grey Lambertian object with the road's albedo rendered under
``light_cam`` and passed through ``hdr_to_ldr`` comes out as bright as the sunlit road.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ...datasets.sample import Box, CameraView, LidarSweep
from ..core import ldr_to_hdr, ldr_uint8_to_hdr, luminance
from .evidence import (
    PreparedImage,
    box_shadow_evidence,
    ground_evidence,
    image_sky_mask,
    prepare_image,
    sky_evidence,
)
from .light import DistantLight
from .sky import (
    OVERCAST_RGB,
    make_sky_light,
    rotation_up_from_frame,
    sky_horizontal_irradiance,
    sky_radiance,
    sun_horizontal_irradiance,
    sun_visibility,
)
from .sun import SunPosition, location_latlon, sun_direction_global, up_direction_camera
from .types import ENVMAP_HEIGHT, ENVMAP_WIDTH, LightingEstimate, ParametricFit, json_clean

GROUND_ALBEDO = 0.15  # assumed road albedo (asphalt 0.1-0.2)
DEFAULT_TURBIDITY = 3.0
DEFAULT_CAMERA_HEIGHT_M = 1.5
# An object's predicted shadow at least this much darker than the road around it is a sun shadow: under a
# diffuse sky the road next to an object loses at most about half its sky (ambient occlusion <= 2x; the foot of
# an endless wall), times ~1.25 for the road's own patchiness; a visible sun at 30-70 deg elevation makes
# 1 + E_sun / E_sky ~ 3.8-7 (clear) -- 2.5 is its visibility ~0.45-0.6.
OBJECT_SHADOW_MIN_CONTRAST = 2.5
# Sun shadows must be on at least this fraction of the usable objects: in sunshine a good part of the objects
# on a street stand in the sun; under clouds a "shadow" that marked is a coincidence (a canopy's or shelter's
# shade, a dark wet patch) on a few objects of many.
OBJECT_SHADOW_MIN_FRACTION = 0.2
# With at least this many usable objects and too few sun shadows on them, the objects say "no visible sun":
# the ground's lit/shadow split is then read as albedo (grass, wet patches), not sun and shade.
NO_SHADOW_MIN_OBJECTS = 3
CAMERA_CLEAR_BLUE_RED = 1.35
CLOUD_GRID = np.linspace(0.0, 1.0, 41)
# Lit/shadow ground contrast above which a night timestamp contradicts the image (sun shadows).
NIGHT_SUSPICIOUS_CONTRAST = 2.5
CLOUD_SOURCE_RANK = ("object_shadows", "no_object_shadows", "ground_contrast", "sky_colour", "night", "assumed")


def up_rotation(up_cam: np.ndarray) -> np.ndarray:
    """(3, 3) rotation from the camera frame to a z-up frame (``up_cam`` -> +z)."""
    return rotation_up_from_frame(up_cam, np.array([0.0, 0.0, 1.0]))


@dataclass(frozen=True)
class L1Evidence:
    """One image's evidence for L1 and the sky model's constants at its sun.

    Attributes:
        e_sun: luminance of the clear-sky sun's horizontal irradiance (model units).
        e_sky0, e_sky1: luminance of the clear / overcast sky's horizontal irradiance.
        ground: :func:`.evidence.ground_evidence` record, or None.
        sky: :func:`.evidence.sky_evidence` record (without its mask) + the model's clear blue/red, or None.
        sky_clear_lum, sky_over_lum: the clear / overcast model's median luminance at the sky pixels, or None.
        cloud_sky: cloud cover from the sky's colour, or None.
        box_shadows: :func:`.evidence.box_shadow_evidence` record, or None.
    """

    e_sun: float
    e_sky0: float
    e_sky1: float
    ground: dict | None
    sky: dict | None
    sky_clear_lum: float | None
    sky_over_lum: float | None
    cloud_sky: float | None
    box_shadows: dict | None


@dataclass(frozen=True)
class ViewInputs:
    """One view's L1 inputs: geometry, ephemeris and image evidence (``evidence`` None without a sun position).

    Attributes:
        view: the camera view.
        location: the log's location, or None.
        up_cam: (3,) unit gravity up, camera frame.
        camera_height_m: the camera's height above the ground (from the poses, else the default).
        sun_pos: the ephemeris sun, or None (no location / timestamp).
        sun_dir_cam: (3,) unit sun direction (camera frame), or None.
        fallback: why there is no ephemeris sun ("" when there is one).
        work: the prepared image (with the LiDAR's surface pixels), or None without a sun position.
        evidence: the image's L1 evidence, or None without a sun position.
        t_start: ``time.perf_counter()`` when the view's estimation started.
    """

    view: CameraView
    location: str | None
    up_cam: np.ndarray
    camera_height_m: float
    sun_pos: SunPosition | None
    sun_dir_cam: np.ndarray | None
    fallback: str
    work: PreparedImage | None
    evidence: L1Evidence | None
    t_start: float


def cloud_from_contrast(contrast: float, e_sun_h: float, e_sky_h0: float, e_sky_h1: float) -> float:
    """Cloud cover whose model lit/shadow ratio ``1 + E_sun_h vis(c) / E_sky_h(c)`` is closest to ``contrast``."""
    c = CLOUD_GRID
    vis = np.array([sun_visibility(x) for x in c])
    e_sky = (1 - c) * e_sky_h0 + c * e_sky_h1
    model = 1.0 + e_sun_h * vis / np.maximum(e_sky, 1e-12)
    return float(c[np.argmin(np.abs(np.log(model) - np.log(max(contrast, 1.0))))])


def l1_evidence(work: PreparedImage, up_cam: np.ndarray, sun_dir_cam: np.ndarray, camera_height_m: float,
                turbidity: float, box_shadows: dict | None = None) -> L1Evidence:
    """The image's evidence for L1 (object shadows, ground lit/shadow, sky colour and level) and the model's
    constants at the sun ``sun_dir_cam`` (3,) (camera frame)."""
    R_up = up_rotation(up_cam)
    sun_up = R_up @ sun_dir_cam
    e_sun = float(luminance(sun_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky0 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky1 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 1.0)))
    ground = ground_evidence(work, up_cam, camera_height_m)
    sky = sky_evidence(work, image_sky_mask(work))

    # Sky model at the observed sky pixels (for colour and scale).
    sky_clear_lum = sky_over_lum = None
    cloud_sky = None
    if sky is not None and "mask" in sky:
        dirs_up = work.rays_cam[sky["mask"]] @ R_up.T
        m0 = sky_radiance(dirs_up, sun_up, turbidity, 0.0)
        m1 = sky_radiance(dirs_up, sun_up, turbidity, 1.0)
        sky_clear_lum = float(np.median(luminance(m0)))
        sky_over_lum = float(np.median(luminance(m1)))
        br_clear = float(np.median(m0[:, 2]) / max(np.median(m0[:, 0]), 1e-9))
        # Cameras white-balance and desaturate the sky: a clear sky reads blue/red ~1.3-1.6, not the
        # model's ~2; cap the clear reference at CAMERA_CLEAR_BLUE_RED.
        br_ref = min(br_clear, CAMERA_CLEAR_BLUE_RED)
        br_over = float(OVERCAST_RGB[2] / OVERCAST_RGB[0]) - 0.03
        if br_ref - br_over > 0.1:
            cloud_sky = float(np.clip((br_ref - sky["blue_red"]) / (br_ref - br_over), 0.0, 1.0))
        sky = {k: v for k, v in sky.items() if k != "mask"} | {"model_blue_red_clear": br_clear}
    return L1Evidence(e_sun, e_sky0, e_sky1, ground, sky, sky_clear_lum, sky_over_lum, cloud_sky, box_shadows)


def object_shadow_verdict(per_object_contrast: Sequence[float]) -> tuple[str, int, int, float | None]:
    """What the objects' predicted shadows say: ("sun" | "no_sun" | "unknown", usable objects, sun-shadowed
    objects, median contrast of the sun-shadowed ones or None).

    "sun": at least one object, and ``OBJECT_SHADOW_MIN_FRACTION`` of them, with a shadow at least
    ``OBJECT_SHADOW_MIN_CONTRAST`` darker than the road around it; "no_sun": fewer than that among at least
    ``NO_SHADOW_MIN_OBJECTS``; "unknown" otherwise (too few objects).
    """
    c = np.asarray(list(per_object_contrast), dtype=np.float64)
    hard = c[c >= OBJECT_SHADOW_MIN_CONTRAST]
    n, k = len(c), len(hard)
    if k >= 1 and k >= OBJECT_SHADOW_MIN_FRACTION * n:
        return "sun", n, k, float(np.median(hard))
    if n >= NO_SHADOW_MIN_OBJECTS:
        return "no_sun", n, k, None
    return "unknown", n, k, None


def _no_shadow_cloud(ev: L1Evidence, cloud_sky: float | None) -> float:
    """Cloud cover when the objects show no sun shadows: the sky colour's, but at least the cover whose sun
    would have drawn shadows of ``OBJECT_SHADOW_MIN_CONTRAST``; overcast (1) without a sky colour."""
    if cloud_sky is None:
        return 1.0
    floor = cloud_from_contrast(OBJECT_SHADOW_MIN_CONTRAST, ev.e_sun, ev.e_sky0, ev.e_sky1)
    return float(max(cloud_sky, floor))


def cloud_from_evidence(ev: L1Evidence) -> tuple[float, str, str]:
    """Cloud cover from one image's evidence: (cloud, source, note); source ranks the evidence
    (:data:`CLOUD_SOURCE_RANK`). The objects' shadows (:func:`object_shadow_verdict`) decide first; when they
    show none, the ground split is not read as sun and shade."""
    ground, sky, boxes = ev.ground, ev.sky, ev.box_shadows
    if ev.e_sun <= 0:
        return (1.0 if ev.cloud_sky is None else ev.cloud_sky), "night", "sun below the horizon"
    verdict, n, k, hard = object_shadow_verdict(boxes["per_object_contrast"] if boxes else [])
    if verdict == "sun":
        cloud = cloud_from_contrast(hard, ev.e_sun, ev.e_sky0, ev.e_sky1)
        return cloud, "object_shadows", (f"sun visibility from the road in/out of the predicted shadows of {k} of "
                                         f"{n} annotated objects (median contrast {hard:.2f})")
    if verdict == "no_sun":
        cloud = _no_shadow_cloud(ev, ev.cloud_sky)
        how = f"sky colour (blue/red {sky['blue_red']:.2f})" if ev.cloud_sky is not None else "no sky colour"
        return cloud, "no_object_shadows", (f"no sun shadow on {n - k} of {n} annotated objects: cloud cover "
                                            f"{cloud:.2f} from {how}")
    if ground is not None and ground["bimodal"]:
        cloud = cloud_from_contrast(ground["contrast"], ev.e_sun, ev.e_sky0, ev.e_sky1)
        return cloud, "ground_contrast", f"sun visibility from ground lit/shadow contrast {ground['contrast']:.2f}"
    if ev.cloud_sky is not None:
        return ev.cloud_sky, "sky_colour", f"cloud cover from sky colour (blue/red {sky['blue_red']:.2f})"
    return 0.5, "assumed", "no shadow or sky-colour evidence: cloud cover 0.5 assumed"


def shared_cloud(inputs: Sequence[ViewInputs]) -> tuple[float | None, str | None, dict]:
    """Cloud cover pooled over the views of one moment -> (cloud or None, the note, {source: [[channel, cloud],
    ...]} of the views' own decisions).

    The annotated objects of all views are judged together (:func:`object_shadow_verdict`; an object seen by
    several cameras counts once, with its strongest contrast): sun shadows on them give the cloud cover from
    their median contrast; none on enough objects, the views' median sky colour (floored as in
    :func:`cloud_from_evidence`). Otherwise the median of the views with the best-ranked own evidence.
    """
    found: dict[str, list] = {}
    objects: dict[str, float] = {}
    skies: list[float] = []
    ref_ev = None
    for vi in inputs:
        if vi.evidence is None:
            continue
        ev = vi.evidence
        cloud, source, _ = cloud_from_evidence(ev)
        found.setdefault(source, []).append((vi.view.channel, cloud))
        if ev.e_sun <= 0:
            continue
        ref_ev = ref_ev or ev
        if ev.cloud_sky is not None:
            skies.append(ev.cloud_sky)
        boxes = ev.box_shadows or {}
        for i, (token, c) in enumerate(zip(boxes.get("per_object_token", []), boxes.get("per_object_contrast", []))):
            key = token or f"{vi.view.channel}:{i}"  # boxes without a token: one object per view and box
            objects[key] = max(objects.get(key, 0.0), float(c))
    record = {k: [list(x) for x in v] for k, v in found.items()}
    if ref_ev is not None:
        verdict, n, k, hard = object_shadow_verdict(list(objects.values()))
        if verdict == "sun":
            cloud = cloud_from_contrast(hard, ref_ev.e_sun, ref_ev.e_sky0, ref_ev.e_sky1)
            return cloud, (f"cloud cover {cloud:.2f} from the predicted shadows of {k} of {n} annotated objects in "
                           f"the views (median contrast {hard:.2f})"), record
        if verdict == "no_sun":
            cloud = _no_shadow_cloud(ref_ev, float(np.median(skies)) if skies else None)
            return cloud, (f"cloud cover {cloud:.2f}: no sun shadow on {n - k} of {n} annotated objects in the "
                           f"views; " + (f"sky colour of {len(skies)} views" if skies else "no sky colour")), record
    for source in CLOUD_SOURCE_RANK:
        if source in found:
            channels = [c for c, _ in found[source]]
            cloud = float(np.median([v for _, v in found[source]]))
            return cloud, f"cloud cover {cloud:.2f} from {source.replace('_', ' ')} of {', '.join(channels)}", record
    return None, None, {}


def _scales(ev: L1Evidence, cloud: float) -> dict:
    """The scale each piece of evidence implies at ``cloud`` (None where it is missing) and the model's
    horizontal irradiances."""
    vis = sun_visibility(cloud)
    e_sky_c = (1 - cloud) * ev.e_sky0 + cloud * ev.e_sky1
    e_lit = ev.e_sun * vis + e_sky_c
    scale_sky = None
    if ev.sky_clear_lum is not None:
        model_sky = (1 - cloud) * ev.sky_clear_lum + cloud * ev.sky_over_lum
        scale_sky = ev.sky["median_lum"] / max(model_sky, 1e-12)
    scale_lit = scale_shadow = None
    if ev.ground is not None:
        scale_lit = np.pi * ev.ground["lit"] / (GROUND_ALBEDO * e_lit)
        scale_shadow = np.pi * ev.ground["shadow"] / (GROUND_ALBEDO * e_sky_c)
    return {"scale_from_ground_lit": scale_lit, "scale_from_ground_shadow": scale_shadow,
            "scale_from_sky": scale_sky, "model_sun_horizontal": ev.e_sun * vis, "model_sky_horizontal": e_sky_c,
            "e_lit": e_lit}


def solve_l1(ev: L1Evidence, cloud: float | None = None,
             cloud_note: str | None = None) -> tuple[float, float | None, dict, list[str]]:
    """(cloud_cover, scale or None, evidence record, reason notes) of one image; ``cloud`` overrides its own."""
    ground, boxes = ev.ground, ev.box_shadows
    notes: list[str] = []
    if cloud is None:
        cloud, _, note = cloud_from_evidence(ev)
        notes.append(note)
    else:
        notes.append(cloud_note or f"cloud cover {cloud:.2f} given")
    sc = _scales(ev, cloud)
    e_lit, sun_h, sky_h = sc.pop("e_lit"), sc["model_sun_horizontal"], sc["model_sky_horizontal"]
    scale_lit, scale_shadow, scale_sky = sc["scale_from_ground_lit"], sc["scale_from_ground_shadow"], sc["scale_from_sky"]
    lit_objects = [lit for c, lit in zip(boxes["per_object_contrast"], boxes["per_object_lit"])
                   if c >= OBJECT_SHADOW_MIN_CONTRAST] if boxes is not None and "per_object_lit" in boxes else []
    if lit_objects and sun_h > 0.5 * sky_h:
        scale = np.pi * float(np.median(lit_objects)) / (GROUND_ALBEDO * e_lit)
        notes.append("scale from the sunlit road next to the sun-shadowed objects")
    elif ground is not None and ground["bimodal"] and sun_h > 0.5 * sky_h:
        scale = scale_lit
        notes.append("scale from the sunlit ground")
    elif ground is not None:
        # the ground median (a bimodal ground without a visible sun is two albedos, not sun and shade)
        scale_lit = np.pi * ground["median"] / (GROUND_ALBEDO * e_lit)
        scale_shadow = np.pi * ground["median"] / (GROUND_ALBEDO * sky_h)
        scale = scale_lit
        if scale_sky is not None and sun_h > 0.5 * sky_h:
            if abs(np.log(scale_shadow / scale_sky)) < abs(np.log(scale_lit / scale_sky)):
                scale = scale_shadow
                notes.append("ground read as in shadow (closer to the sky's scale)")
        notes.append("scale from the ground median")
    elif scale_sky is not None:
        scale = scale_sky
        notes.append("no ground visible: scale from the sky")
    else:
        scale = None
    evidence = {"ground": ground, "sky": ev.sky, "object_shadows": boxes, **sc}
    return cloud, scale, evidence, notes


def l0_estimate(image: np.ndarray, timing: dict) -> LightingEstimate:
    """L0: a constant dome on the image's scale, no sun: the radiance the camera records as the image's mean
    colour (rendered from the camera and passed through the response, it gives that colour: the best constant
    view of the image; the mean *linear* radiance would be brighter by the response's curvature)."""
    t1 = time.perf_counter()
    mean_ldr = np.asarray(image, np.float64).reshape(-1, 3).mean(axis=0) / 255.0
    mean = ldr_to_hdr(mean_ldr).astype(np.float32)
    light = DistantLight(np.broadcast_to(mean.astype(np.float32), (ENVMAP_HEIGHT, ENVMAP_WIDTH, 3)).copy(), None)
    timing["fit"] = time.perf_counter() - t1
    timing["total"] = time.perf_counter() - t1
    return LightingEstimate(
        light, None, "none", 0.0, "L0", "L0: constant dome of the radiance recorded as the image's mean colour",
        {"mean_radiance_rgb": mean.tolist()}, timing,
    )


def _ephemeris(view: CameraView, location: str | None) -> tuple[SunPosition | None, str]:
    """The ephemeris sun of a view, or (None, why not)."""
    if location is None:
        return None, "no location: ephemeris unavailable"
    if view.timestamp_us is None or view.timestamp_us <= 0:
        return None, "no timestamp: ephemeris unavailable"
    try:
        location_latlon(location)
        return sun_direction_global(location, view.timestamp_us), ""
    except ValueError as exc:
        return None, f"ephemeris unavailable ({exc})"


def view_inputs(view: CameraView, location: str | None, timing: dict, boxes: list[Box] | None = None,
                lidar: LidarSweep | None = None) -> ViewInputs:
    """A view's geometry, its ephemeris sun and (with a sun position) its prepared image and L1 evidence."""
    t0 = time.perf_counter()
    image = np.asarray(view.image)
    up_cam = up_direction_camera(view)
    cam_z = float(view.T_global_from_cam[2, 3] - view.T_global_from_ego[2, 3])
    camera_height_m = cam_z if 0.5 <= cam_z <= 4.0 else DEFAULT_CAMERA_HEIGHT_M
    sun_pos, fallback = _ephemeris(view, location)
    if sun_pos is None:
        return ViewInputs(view, location, up_cam, camera_height_m, None, None, fallback, None, None, t0)
    R_cam_from_global = np.asarray(view.T_cam_from_global)[:3, :3]
    sun_dir_cam = R_cam_from_global @ sun_pos.direction_global
    sun_dir_cam = sun_dir_cam / np.linalg.norm(sun_dir_cam)
    lidar_cam = None if lidar is None else lidar.points_in(np.asarray(view.T_cam_from_global))
    work = prepare_image(image, view.K, up_cam, lidar_cam)
    timing["prepare"] = time.perf_counter() - t0
    t2 = time.perf_counter()
    box_shadows = box_shadow_evidence(work, np.asarray(view.T_cam_from_global), boxes, sun_pos.direction_global) \
        if boxes else None
    ev = l1_evidence(work, up_cam, sun_dir_cam, camera_height_m, DEFAULT_TURBIDITY, box_shadows)
    timing["evidence"] = time.perf_counter() - t2
    return ViewInputs(view, location, up_cam, camera_height_m, sun_pos, sun_dir_cam, fallback, work, ev, t0)


def ephemeris_estimate(vi: ViewInputs, timing: dict, cloud: float | None = None,
                       cloud_note: str | None = None) -> LightingEstimate:
    """L1 of a view whose ephemeris sun is above the horizon (``cloud`` overrides the view's own cloud cover)."""
    t2 = time.perf_counter()
    up_cam, sun_dir_cam, sun_pos, work = vi.up_cam, vi.sun_dir_cam, vi.sun_pos, vi.work
    cloud, scale, evidence, notes = solve_l1(vi.evidence, cloud, cloud_note)
    if scale is None:
        mean_lum = float(luminance(work.hdr.reshape(-1, 3).mean(axis=0)))
        e = luminance(sky_horizontal_irradiance(up_rotation(up_cam) @ sun_dir_cam, DEFAULT_TURBIDITY, cloud))
        scale = np.pi * mean_lum / (GROUND_ALBEDO * max(float(e), 1e-12))
        notes.append("neither ground nor sky usable: scale from the image mean")
    timing["fit"] = time.perf_counter() - t2
    t3 = time.perf_counter()
    light = make_sky_light(
        sun_dir_cam, up_cam, DEFAULT_TURBIDITY, cloud, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, float(scale)
    )
    timing["envmap"] = time.perf_counter() - t3
    timing["total"] = time.perf_counter() - vi.t_start
    reason = f"L1: sun from the ephemeris ({vi.location}, elevation {sun_pos.elevation_deg:.1f} deg); "
    fit = ParametricFit(DEFAULT_TURBIDITY, cloud, float(scale), GROUND_ALBEDO, vi.camera_height_m, up_cam,
                        sun_dir_cam, sun_pos.elevation_deg, sun_pos.azimuth_deg, vi.location, json_clean(evidence))
    return LightingEstimate(light, sun_dir_cam, "ephemeris", sun_visibility(cloud), "L1", reason + "; ".join(notes),
                            fit.to_json(), timing, fit=fit)


def night_estimate(vi: ViewInputs, timing: dict) -> LightingEstimate:
    """Sun below the horizon: no sun; the light is diffuse (twilight sky, street lights), so an
    overcast-shaped dome scaled to the image's ground (:func:`diffuse_estimate`).

    A clear-sky model with the sun below the horizon is the wrong shape here, and fitting its tiny
    irradiance to the image's ground would blow the scale up.  When the image nevertheless shows hard
    sun shadows on the ground, the timestamp (or the location) is probably wrong: the reason says so.
    """
    est = diffuse_estimate(np.asarray(vi.view.image), vi.view.K, vi.up_cam, vi.camera_height_m, timing)
    ground = (vi.evidence.ground if vi.evidence is not None else None) or {}
    how = est.reason.rsplit("; ", 1)[-1]
    reason = (f"L1: sun {vi.sun_pos.elevation_deg:.1f} deg below the horizon (night/twilight): no sun, diffuse "
              f"sky; {how}")
    if ground.get("bimodal") and ground.get("contrast", 1.0) >= NIGHT_SUSPICIOUS_CONTRAST:
        reason += (f"; the ground shows sun-like shadows (lit/shadow contrast {ground['contrast']:.1f}) although "
                   f"the ephemeris puts the sun below the horizon: check the timestamp and location")
    fit = replace(est.fit, sun_elevation_deg=vi.sun_pos.elevation_deg, sun_azimuth_deg=vi.sun_pos.azimuth_deg,
                  location=vi.location)
    return replace(est, reason=reason, params=fit.to_json(), fit=fit)


def diffuse_estimate(image: np.ndarray, K: np.ndarray, up_cam: np.ndarray, camera_height_m: float,
                     timing: dict) -> LightingEstimate:
    """No sun: an overcast-shaped sky whose ground irradiance matches the image's ground (else its sky, else
    its mean)."""
    t1 = time.perf_counter()
    work = prepare_image(image, np.asarray(K, dtype=np.float64), up_cam)
    ground = ground_evidence(work, up_cam, camera_height_m)
    sky = sky_evidence(work, image_sky_mask(work))
    # A nominal sun at 45 deg only sets the overcast sky's level; the overcast sky has no azimuth.
    sun_up = np.array([0.0, np.cos(np.pi / 4), np.sin(np.pi / 4)])
    e_sky = float(luminance(sky_horizontal_irradiance(sun_up, DEFAULT_TURBIDITY, 1.0)))
    if ground is not None:
        scale = np.pi * ground["median"] / (GROUND_ALBEDO * e_sky)
        how = "scale from the ground median"
    elif sky is not None and "median_lum" in sky:
        zen = e_sky * 9.0 / (7.0 * np.pi)
        scale = sky["median_lum"] / zen
        how = "scale from the sky"
    else:
        scale = np.pi * float(luminance(work.hdr.reshape(-1, 3).mean(axis=0))) / (GROUND_ALBEDO * e_sky)
        how = "scale from the image mean"
    sun_cam = up_rotation(up_cam).T @ sun_up
    light = make_sky_light(sun_cam, up_cam, DEFAULT_TURBIDITY, 1.0, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, scale)
    timing["fit"] = time.perf_counter() - t1
    timing["total"] = time.perf_counter() - t1
    reason = f"no sun: diffuse overcast-shaped sky; {how}"
    evidence = {"ground": ground, "sky": sky and {k: v for k, v in sky.items() if k != "mask"}}
    fit = ParametricFit(DEFAULT_TURBIDITY, 1.0, float(scale), GROUND_ALBEDO, camera_height_m, np.asarray(up_cam),
                        sun_cam, evidence=json_clean(evidence))
    return LightingEstimate(light, None, "none", 0.0, "L1", reason, fit.to_json(), timing, fit=fit)
