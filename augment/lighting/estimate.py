"""Lighting estimation, first level: ephemeris sun + parametric sky fitted to the image's radiometric scale.

Levels:

* ``L0`` — the paper's "no light" baseline: a constant dome with the image's mean linear radiance.
* ``L1`` — sun direction from the ephemeris (location + timestamp), sky from :mod:`.sky`; its
  ``scale`` (physical -> image units), ``cloud_cover`` (hence sun visibility) are fitted to the image.

Evidence (computed on a copy of the image downscaled to <= 480 px wide, in linear HDR =
``ldr_uint8_to_hdr``, i.e. the contract's camera response at EV 0):

* **Ground**: grey (low-chroma) pixels whose ray hits the ground plane (camera ``camera_height_m``
  above it, up from the camera pose) 4-40 m away and within 8 m laterally. Their log-luminance is split in two by Otsu's
  threshold; if the split is clearly bimodal (separation ratio eta >= 0.75, both classes >= 8 %,
  contrast >= 1.8) the upper class is "sunlit" and the lower "shadow" and
  ``contrast = lit / shadow``. A horizontal Lambertian ground of albedo ``GROUND_ALBEDO`` has
  ``L_lit = scale * albedo * (E_sun_h + E_sky_h) / pi`` and ``L_shadow = scale * albedo * E_sky_h / pi``,
  so the contrast fixes the sun visibility (cloud cover) and ``L_lit`` the scale.
* **Sky**: pixels at least 3 deg above the horizon, bright, smooth (low gradient), in regions touching
  the top of the image, not saturated. Their blue/red ratio against the model's clear-sky and overcast
  ratios gives a second cloud-cover estimate; their brightness against the model gives ``scale_sky``.
* Without ground shadows, the ground median pins the scale; if both the "all sunlit" and "all in
  shadow" readings are possible, the one closer to the sky's scale wins.

The result is on the image's scale: a grey Lambertian object with the road's albedo rendered under
``light_cam`` and passed through ``hdr_to_ldr`` comes out as bright as the sunlit road.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ..conventions import check_shape, ldr_uint8_to_hdr, luminance, pixel_rays
from .light import DistantLight
from .sky import (
    OVERCAST_RGB,
    make_sky_light,
    sky_horizontal_irradiance,
    sky_radiance,
    sun_horizontal_irradiance,
    sun_visibility,
)
from .sun import location_latlon, sun_direction_global, up_direction_camera

GROUND_ALBEDO = 0.15  # assumed road albedo (asphalt 0.1-0.2)
DEFAULT_TURBIDITY = 3.0
DEFAULT_CAMERA_HEIGHT_M = 1.5
ENVMAP_HEIGHT, ENVMAP_WIDTH = 128, 256
SKY_MIN_ELEVATION_DEG = 3.0
SATURATED_LDR = 0.97
WORK_WIDTH = 480
CAMERA_CLEAR_BLUE_RED = 1.35
CLOUD_GRID = np.linspace(0.0, 1.0, 41)


@dataclass(frozen=True)
class LightingEstimate:
    """The lighting of one image, in its camera frame and on its radiometric scale.

    Attributes:
        light_cam: environment (camera-frame equirect, sun excluded) + sun, camera frame, image units.
        sun_dir_cam: (3,) unit vector towards the sun (camera frame), or None (night / unknown).
        sun_source: "ephemeris" | "image" | "none".
        sun_visibility: 0..1 fraction of the sun getting through clouds (0 when there is no sun).
        level: "L0" | "L1".
        reason: why this level, which evidence was used, which fallbacks were taken.
        params: turbidity, cloud_cover, scale, evidence numbers (JSON-serialisable).
        timing_s: seconds per step.
    """

    light_cam: DistantLight
    sun_dir_cam: np.ndarray | None
    sun_source: str
    sun_visibility: float
    level: str
    reason: str
    params: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- evidence


@dataclass(frozen=True)
class _Work:
    """The downscaled image and its pixel rays."""

    hdr: np.ndarray  # (h, w, 3) float64 linear
    ldr: np.ndarray  # (h, w, 3) float64 in [0, 1]
    rays_cam: np.ndarray  # (h, w, 3) unit camera-frame rays
    elevation: np.ndarray  # (h, w) rad above the horizon


def _prepare(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray) -> _Work:
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    check_shape(K, (3, 3), "K")
    H, W = image_rgb.shape[:2]
    f = min(1.0, WORK_WIDTH / W)
    w, h = max(int(round(W * f)), 8), max(int(round(H * f)), 8)
    small = cv2.resize(np.ascontiguousarray(image_rgb), (w, h), interpolation=cv2.INTER_AREA)
    sx, sy = w / W, h / H
    Ks = np.array(K, dtype=np.float64).copy()
    Ks[0] *= sx
    Ks[1] *= sy
    Ks[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    Ks[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rays = pixel_rays(Ks, np.stack([u.ravel(), v.ravel()], axis=1)).reshape(h, w, 3)
    elevation = np.arcsin(np.clip(rays @ up_cam, -1.0, 1.0))
    return _Work(ldr_uint8_to_hdr(small).astype(np.float64), small / 255.0, rays, elevation)


def _otsu_log(values: np.ndarray) -> tuple[float, float, float, float]:
    """Otsu split of log values: (eta, weight of the lower class, mean lo, mean hi) (log domain)."""
    hist, edges = np.histogram(values, bins=64)
    centres = 0.5 * (edges[:-1] + edges[1:])
    p = hist / max(hist.sum(), 1)
    w0 = np.cumsum(p)
    m = np.cumsum(p * centres)
    mt = m[-1]
    w1 = 1.0 - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        sb = (mt * w0 - m) ** 2 / (w0 * w1)
    sb[~np.isfinite(sb)] = 0.0
    k = int(np.argmax(sb))
    var = float(p @ (centres - mt) ** 2)
    eta = float(sb[k] / var) if var > 0 else 0.0
    thr = edges[k + 1]
    lo, hi = values[values < thr], values[values >= thr]
    if len(lo) == 0 or len(hi) == 0:
        return 0.0, 0.0, float(np.median(values)), float(np.median(values))
    return eta, len(lo) / len(values), float(np.median(lo)), float(np.median(hi))


def _ground_evidence(work: _Work, up_cam: np.ndarray, camera_height_m: float) -> dict | None:
    """Sunlit / shadow / median ground luminance, or None when too little ground is visible."""
    cos_down = -(work.rays_cam @ up_cam)  # > 0 for rays going down
    with np.errstate(divide="ignore"):
        dist = np.where(cos_down > 1e-3, camera_height_m / np.maximum(cos_down, 1e-3), np.inf)
    points = work.rays_cam * dist[..., None]
    lateral = np.abs(points[..., 0])
    horizontal = np.sqrt(np.maximum(dist**2 - camera_height_m**2, 0.0))
    mask = (horizontal > 4.0) & (horizontal < 40.0) & (lateral < 8.0) & np.isfinite(dist)
    mask &= work.ldr.max(axis=-1) < SATURATED_LDR
    # Roads are grey: drop saturated colours (vegetation, barriers, painted cars).
    chroma = (work.ldr.max(axis=-1) - work.ldr.min(axis=-1)) / np.maximum(work.ldr.max(axis=-1), 1e-3)
    grey = mask & (chroma < 0.25)
    if grey.sum() >= 0.3 * mask.sum():
        mask = grey
    if mask.sum() < 50:
        return None
    lum = np.maximum(luminance(work.hdr[mask]), 1e-6)
    log_lum = np.log(lum)
    eta, w_lo, mu_lo, mu_hi = _otsu_log(log_lum)
    contrast = float(np.exp(mu_hi - mu_lo))
    bimodal = eta >= 0.75 and 0.08 <= w_lo <= 0.92 and contrast >= 1.8
    return {
        "pixels": int(mask.sum()),
        "median": float(np.median(lum)),
        "lit": float(np.exp(mu_hi)) if bimodal else float(np.median(lum)),
        "shadow": float(np.exp(mu_lo)) if bimodal else float(np.median(lum)),
        "contrast": contrast if bimodal else 1.0,
        "otsu_eta": eta,
        "shadow_fraction": float(w_lo) if bimodal else 0.0,
        "bimodal": bool(bimodal),
    }


def _sky_mask(work: _Work) -> np.ndarray:
    """Bright, smooth pixels above the horizon in regions that touch the top of the image."""
    lum_ldr = luminance(work.ldr)
    gx = cv2.Sobel(lum_ldr, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(lum_ldr, cv2.CV_64F, 0, 1, ksize=3)
    grad = cv2.GaussianBlur(np.hypot(gx, gy), (5, 5), 0)
    above = work.elevation > np.radians(SKY_MIN_ELEVATION_DEG)
    if not above.any():
        return above
    bright = lum_ldr >= max(0.3, float(np.percentile(lum_ldr[above], 50)))
    candidate = (above & bright & (grad < 0.12)).astype(np.uint8)
    n, labels = cv2.connectedComponents(candidate, connectivity=4)
    top_labels = np.unique(labels[0][candidate[0] > 0])
    return np.isin(labels, top_labels[top_labels > 0]) & (candidate > 0)


def _sky_evidence(work: _Work, sky_mask: np.ndarray) -> dict | None:
    frac = float(sky_mask.mean())
    if sky_mask.sum() < 30:
        return None
    unsat = sky_mask & (work.ldr.max(axis=-1) < SATURATED_LDR)
    out = {"fraction": frac, "saturated_fraction": float(1.0 - unsat.sum() / sky_mask.sum())}
    if unsat.sum() >= 20 and unsat.sum() >= 0.2 * sky_mask.sum():
        rgb = work.hdr[unsat]
        out["mask"] = unsat
        out["median_lum"] = float(np.median(luminance(rgb)))
        out["blue_red"] = float(np.median(rgb[:, 2]) / max(np.median(rgb[:, 0]), 1e-9))
    return out


# ----------------------------------------------------------------------------- fitting


def _cloud_from_contrast(contrast: float, e_sun_h: float, e_sky_h0: float, e_sky_h1: float) -> float:
    """Cloud cover whose model lit/shadow ratio ``1 + E_sun_h vis(c) / E_sky_h(c)`` is closest to ``contrast``."""
    c = CLOUD_GRID
    vis = np.array([sun_visibility(x) for x in c])
    e_sky = (1 - c) * e_sky_h0 + c * e_sky_h1
    model = 1.0 + e_sun_h * vis / np.maximum(e_sky, 1e-12)
    return float(c[np.argmin(np.abs(np.log(model) - np.log(max(contrast, 1.0))))])


def _fit_l1(work: _Work, up_cam: np.ndarray, sun_dir_cam: np.ndarray, camera_height_m: float, turbidity: float):
    """Returns (cloud_cover, scale, evidence dict, list of reason strings)."""
    R_up = _up_rotation(up_cam)
    sun_up = R_up @ sun_dir_cam
    e_sun = float(luminance(sun_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky0 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky1 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 1.0)))
    ground = _ground_evidence(work, up_cam, camera_height_m)
    sky = _sky_evidence(work, _sky_mask(work))
    notes: list[str] = []
    evidence: dict = {"ground": ground, "sky": None}

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
    evidence["sky"] = sky

    # Cloud cover.
    if e_sun <= 0:
        cloud = 1.0 if cloud_sky is None else cloud_sky
        notes.append("sun below the horizon")
    elif ground is not None and ground["bimodal"]:
        cloud = _cloud_from_contrast(ground["contrast"], e_sun, e_sky0, e_sky1)
        notes.append(f"sun visibility from ground lit/shadow contrast {ground['contrast']:.2f}")
    elif cloud_sky is not None:
        cloud = cloud_sky
        notes.append(f"cloud cover from sky colour (blue/red {sky['blue_red']:.2f})")
    else:
        cloud = 0.5
        notes.append("no shadow or sky-colour evidence: cloud cover 0.5 assumed")

    vis = sun_visibility(cloud)
    e_sky_c = (1 - cloud) * e_sky0 + cloud * e_sky1
    e_lit = e_sun * vis + e_sky_c
    scale_sky = None
    if sky_clear_lum is not None:
        model_sky = (1 - cloud) * sky_clear_lum + cloud * sky_over_lum
        scale_sky = sky["median_lum"] / max(model_sky, 1e-12)
    scale_lit = scale_shadow = None
    if ground is not None:
        scale_lit = np.pi * ground["lit"] / (GROUND_ALBEDO * e_lit)
        scale_shadow = np.pi * ground["shadow"] / (GROUND_ALBEDO * e_sky_c)
    if ground is not None and ground["bimodal"]:
        scale = scale_lit
        notes.append("scale from the sunlit ground")
    elif ground is not None:
        scale = scale_lit
        if scale_sky is not None and e_sun * vis > 0.5 * e_sky_c:
            if abs(np.log(scale_shadow / scale_sky)) < abs(np.log(scale_lit / scale_sky)):
                scale = scale_shadow
                notes.append("ground read as in shadow (closer to the sky's scale)")
        notes.append("scale from the ground median")
    elif scale_sky is not None:
        scale = scale_sky
        notes.append("no ground visible: scale from the sky")
    else:
        scale = None
    evidence.update(
        scale_from_ground_lit=scale_lit, scale_from_ground_shadow=scale_shadow, scale_from_sky=scale_sky,
        model_sun_horizontal=e_sun * vis, model_sky_horizontal=e_sky_c,
    )
    return cloud, scale, evidence, notes


def _up_rotation(up_cam: np.ndarray) -> np.ndarray:
    from .sky import rotation_up_from_frame

    return rotation_up_from_frame(up_cam, np.array([0.0, 0.0, 1.0]))


def _l0_light(hdr: np.ndarray) -> tuple[DistantLight, np.ndarray]:
    mean = hdr.reshape(-1, 3).mean(axis=0)
    env = np.broadcast_to(mean.astype(np.float32), (ENVMAP_HEIGHT, ENVMAP_WIDTH, 3)).copy()
    return DistantLight(env, None), mean


def _clean(obj):
    """JSON-friendly copy (numpy scalars -> floats, dicts/lists recursively)."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


# ----------------------------------------------------------------------------- public API


def estimate_lighting(view, location: str | None, level: str = "L1") -> LightingEstimate:
    """Lighting of a ``CameraView`` (camera frame, image scale).

    Args:
        view: a :class:`streetaug.datasets.sample.CameraView` (image, K, poses, timestamp_us).
        location: the log's location (e.g. ``singapore-onenorth``) for the ephemeris; None if unknown.
        level: "L0" (constant dome of the image's mean radiance) or "L1" (ephemeris sun + fitted sky).
    """
    if level not in ("L0", "L1"):
        raise ValueError(f"level must be 'L0' or 'L1', got {level!r}")
    t0 = time.perf_counter()
    image = np.asarray(view.image)
    timing = {"decode": time.perf_counter() - t0}
    if level == "L0":
        t1 = time.perf_counter()
        light, mean = _l0_light(ldr_uint8_to_hdr(image))
        timing["fit"] = time.perf_counter() - t1
        timing["total"] = time.perf_counter() - t1
        return LightingEstimate(
            light, None, "none", 0.0, "L0", "L0 requested: constant dome of the image's mean linear radiance",
            {"mean_radiance_rgb": mean.tolist()}, timing,
        )
    up_cam = up_direction_camera(view)
    cam_z = float(view.T_global_from_cam[2, 3])
    camera_height_m = cam_z if 0.5 <= cam_z <= 4.0 else DEFAULT_CAMERA_HEIGHT_M
    sun_pos = None
    fallback = ""
    if location is None:
        fallback = "no location: ephemeris unavailable"
    elif view.timestamp_us is None or view.timestamp_us <= 0:
        fallback = "no timestamp: ephemeris unavailable"
    else:
        try:
            location_latlon(location)
            sun_pos = sun_direction_global(location, view.timestamp_us)
        except ValueError as exc:
            fallback = f"ephemeris unavailable ({exc})"
    if sun_pos is None:
        est = _estimate_diffuse(image, view.K, up_cam, camera_height_m, t0, timing)
        return replace(est, reason=f"{fallback}; {est.reason}")

    t1 = time.perf_counter()
    R_cam_from_global = np.asarray(view.T_cam_from_global)[:3, :3]
    sun_dir_cam = R_cam_from_global @ sun_pos.direction_global
    sun_dir_cam = sun_dir_cam / np.linalg.norm(sun_dir_cam)
    work = _prepare(image, view.K, up_cam)
    timing["prepare"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    cloud, scale, evidence, notes = _fit_l1(work, up_cam, sun_dir_cam, camera_height_m, DEFAULT_TURBIDITY)
    night = sun_pos.elevation_deg <= 0.0
    if scale is None:
        mean_lum = float(luminance(work.hdr.reshape(-1, 3).mean(axis=0)))
        R_up = _up_rotation(up_cam)
        e = luminance(sky_horizontal_irradiance(R_up @ sun_dir_cam, DEFAULT_TURBIDITY, cloud))
        scale = np.pi * mean_lum / (GROUND_ALBEDO * max(float(e), 1e-12))
        notes.append("neither ground nor sky usable: scale from the image mean")
    timing["fit"] = time.perf_counter() - t2
    t3 = time.perf_counter()
    light = make_sky_light(
        sun_dir_cam, up_cam, DEFAULT_TURBIDITY, cloud, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, float(scale)
    )
    timing["envmap"] = time.perf_counter() - t3
    timing["total"] = time.perf_counter() - t1
    if night:
        reason = f"L1: sun {sun_pos.elevation_deg:.1f} deg below the horizon (night/twilight): no sun, dim sky; "
        source, sun_out, visibility = "none", None, 0.0
    else:
        reason = f"L1: sun from the ephemeris ({location}, elevation {sun_pos.elevation_deg:.1f} deg); "
        source, sun_out, visibility = "ephemeris", sun_dir_cam, sun_visibility(cloud)
    params = {
        "turbidity": DEFAULT_TURBIDITY,
        "cloud_cover": cloud,
        "scale": float(scale),
        "ground_albedo_assumed": GROUND_ALBEDO,
        "camera_height_m": camera_height_m,
        "up_camera": up_cam.tolist(),
        "sun_elevation_deg": sun_pos.elevation_deg,
        "sun_azimuth_deg": sun_pos.azimuth_deg,
        "location": location,
        "evidence": evidence,
    }
    return LightingEstimate(light, sun_out, source, visibility, "L1", reason + "; ".join(notes), _clean(params), timing)


def _estimate_diffuse(image, K, up_cam, camera_height_m, t0, timing) -> LightingEstimate:
    """No reliable sun: an overcast-shaped sky whose ground irradiance matches the image's ground."""
    t1 = time.perf_counter()
    work = _prepare(image, np.asarray(K, dtype=np.float64), up_cam)
    ground = _ground_evidence(work, up_cam, camera_height_m)
    sky = _sky_evidence(work, _sky_mask(work))
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
    R_up = _up_rotation(up_cam)
    sun_cam = R_up.T @ sun_up
    light = make_sky_light(sun_cam, up_cam, DEFAULT_TURBIDITY, 1.0, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, scale)
    timing["fit"] = time.perf_counter() - t1
    timing["total"] = time.perf_counter() - t1
    reason = (
        "L1 without metadata: no reliable sun (the learned sky predictor is not implemented yet), "
        f"diffuse overcast-shaped sky; {how}"
    )
    params = {
        "turbidity": DEFAULT_TURBIDITY, "cloud_cover": 1.0, "scale": float(scale),
        "ground_albedo_assumed": GROUND_ALBEDO, "camera_height_m": camera_height_m,
        "up_camera": np.asarray(up_cam).tolist(), "evidence": {"ground": ground, "sky": sky and {k: v for k, v in sky.items() if k != "mask"}},
    }
    return LightingEstimate(light, None, "none", 0.0, "L1", reason, _clean(params), timing)


def estimate_lighting_from_image(image_rgb: np.ndarray, K: np.ndarray) -> LightingEstimate:
    """Lighting of an image without metadata: camera assumed level (up = -y, horizon at the principal
    point row), 1.5 m above the ground; no sun (``sun_source="none"``), diffuse sky scaled to the image."""
    image_rgb = np.asarray(image_rgb)
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    if image_rgb.dtype != np.uint8:
        raise ValueError(f"image_rgb must be uint8 RGB, got dtype {image_rgb.dtype}")
    t0 = time.perf_counter()
    return _estimate_diffuse(image_rgb, K, np.array([0.0, -1.0, 0.0]), DEFAULT_CAMERA_HEIGHT_M, t0, {})
