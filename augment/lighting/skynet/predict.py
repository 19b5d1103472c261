"""Inference with the shipped networks: sky vectors, single-image sky prediction, test-time refinement.

Frames: sky vectors and domes live in the camera's **heading frame** (see :mod:`.dome`; z up, x = the
optical axis projected on the horizontal plane); ``R_heading_from_cam`` converts camera-frame vectors.
Without metadata the camera is assumed level (up = -y in the camera frame).  Radiance is linear HDR on
the radiometric scale of the input image (``LDR = hdr_to_ldr(HDR)``, the contract's response, EV 0).

Main entry points:

* :func:`predict_sky` — image (+ K, + optional up) -> :class:`SkyPrediction` (sky vector, sun
  direction in the camera frame with a calibrated uncertainty, visibility, or a diffuse fallback).
* :func:`refine_sky` — a few Adam steps on the sky vector (intensity + latent; direction too if no
  ephemeris) so that the decoded dome matches the visible sky pixels (the paper's differentiable
  decoder used at test time).
* :func:`sky_to_light` — sky vector -> :class:`..light.DistantLight` (camera-frame envmap, sun kept
  analytic) for the renderer.
* :func:`estimate_sky_light` — the three above in one call, as used by the lighting estimator.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from ...core import camera_envmap_directions, check_shape, ldr_uint8_to_hdr, luminance, pixel_rays
from ..evidence import sky_mask
from ..light import DistantLight, SunLight
from .dome import dome_directions, dome_pixel_size_rad, dome_solid_angles, heading_from_camera, sample_dome
from .inputs import VIEW_SIZE, quantize_ldr, resize_view, view_rays
from .model import direction_cone_deg
from .sun_cues import (clipped_region_at, detect_sun_disc, glare_centre_cam, glare_extent_deg, glare_region_features,
                       in_view_sky_loglik, sky_features, sky_fit_loglik)
from .weights import load_light_model, load_sky_model

VISIBILITY_MIN = 0.3  # below: no sun is reported (overcast, night, hidden)
UNCERTAINTY_MAX_DEG = 35.0  # above (68 % cone): the direction is too uncertain to report a sun
SUN_REGION_PX = 2.5  # the decoded sun is taken from this radius (dome pixels) around f_dir
MIN_SUN_FRACTION = 0.05  # a decoded peak counts as a sun if it carries this fraction of the dome's irradiance
DISC_VISIBILITY = 0.7  # a sun disc seen in the image: the visibility is at least this
CNN_WEIGHT = 0.1  # exponent of the network's direction distribution in the posterior (a weak prior)
FIT_TEMPERATURE = 4.0  # divides the clear-sky fit's log-likelihood (calibrated on held-in views)
IN_VIEW_PENALTY = 8.0  # log-likelihood penalty of a sun on bright unclipped pixels in view
GLARE_MAX_UNCERTAINTY_DEG = 15.0  # a fitted sun in a clipped region, this sure (cone >= its radius), is seen ...
GLARE_VISIBILITY = 0.5  # ... with at least this visibility (the network underrates suns in view)
GLARE_MIN_ELEVATION_DEG = 4.0  # ... unless it is lower (a clipped twilight glow on the horizon is not a sun)
GLARE_CENTRE_MAX_DEG = 35.0  # a fitted sun in a clipped region of at most this radius moves to the region's centre
# a clipped region (disc or glare) is the sun only if the sky within 8 deg of it is brighter than the sky 15-35 deg
# beyond by at least this log ratio of linear radiance (x 1.2); chosen on training views only
# (benchmarks/tune_glare_rule.py -> results/sun_error_glare_rule_s5.json: optimal 0.12-0.24, its middle)
GLARE_MIN_FALLOFF = 0.18
GLARE_FALLOFF_KEY = "glow_log_ratio_sky"  # the measure of sun_cues.glare_region_features
GLARE_FALLOFF_UNKNOWN_IS_SUN = False  # without sky around it to tell (a patch among leaves, or the whole sky clipped)
FIT_MIN_SKY_FRACTION = 0.1  # below this fraction of sky pixels the clear-sky fit and glare cues are not used
# (they need sky to measure: on scene-0916's street views, median sky fraction 0, the fit moved the network's
# direction away from the sun; threshold chosen on the training sets only, see benchmarks/results/sky_benchmark_real_s6.json)
REFINE_MAX_PIXELS = 3000
SATURATED_LDR = 0.97

_lock = threading.Lock()
_models: dict = {}


@dataclass(frozen=True)
class SkyVector:
    """The paper's sky vector ``f`` (64 floats) in a heading frame.

    Attributes:
        intensity_rgb: (3,) float64 linear HDR radiance of the peak pixel of the decoded dome (image scale).
        direction: (3,) float64 unit vector towards the peak (the sun), heading frame.
        latent: (58,) float64 code of the rest of the sky.
    """

    intensity_rgb: np.ndarray
    direction: np.ndarray
    latent: np.ndarray

    def to_array(self) -> np.ndarray:
        """(64,) float64 ``[intensity (3), direction (3), latent (58)]``."""
        return np.concatenate([self.intensity_rgb, self.direction, self.latent]).astype(np.float64)

    @staticmethod
    def from_array(f: np.ndarray) -> "SkyVector":
        f = np.asarray(f, dtype=np.float64)
        check_shape(f, (64,), "sky vector")
        d = f[3:6] / max(np.linalg.norm(f[3:6]), 1e-12)
        return SkyVector(np.maximum(f[:3], 0.0), d, f[6:].copy())


@dataclass(frozen=True)
class SkyPrediction:
    """What :func:`predict_sky` saw in one image.

    Attributes:
        sky: sky vector (heading frame); when no sun is reported its intensity is lowered to the
            surrounding sky (a diffuse sky).
        sky_raw: the network's sky vector, before that decision.
        R_heading_from_cam: (3, 3) camera -> heading frame.
        sun_dir_cam: (3,) unit direction towards the sun (camera frame), or None when not confident.
        sun_visibility: 0..1 (0 when no sun is reported).
        direction_cam: (3,) the network's peak direction (camera frame), reported or not.
        visibility_raw: the visibility before the decision (the network's, raised when the sun is seen).
        uncertainty_deg: half-angle of the cone around the direction holding 68 % of the predicted
            direction distribution.
        confident: whether a sun is reported.
        reason: one line saying why.
        timing_s: seconds per step.
        cues: what the cues saw (diagnostics, floats / bools / None): the network's visibility, the sky's
            :func:`.sun_cues.sky_features`, the clear-sky fit's direction (camera frame, before any glare move),
            the clipped region under it (:func:`.sun_cues.glare_region_features`) and whether the glare rule fired.
    """

    sky: SkyVector
    sky_raw: SkyVector
    R_heading_from_cam: np.ndarray
    sun_dir_cam: np.ndarray | None
    sun_visibility: float
    direction_cam: np.ndarray
    visibility_raw: float
    uncertainty_deg: float
    confident: bool
    reason: str
    timing_s: dict = field(default_factory=dict)
    cues: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- models


def get_models(sky_weights: str | Path | None = None, light_weights: str | Path | None = None):
    """(sky model, image predictor), loaded once per process (thread-safe) and kept in eval mode."""
    key = (str(sky_weights), str(light_weights))
    with _lock:
        if key not in _models:
            torch.set_grad_enabled(True)
            _models[key] = (load_sky_model(sky_weights), load_light_model(light_weights))
        return _models[key]


@contextmanager
def default_models(models):
    """Within the block, :func:`get_models` without arguments (what the lighting front door uses) returns
    ``models`` = (sky model, image predictor): e.g. to measure other weights through the product path."""
    key = (str(None), str(None))
    with _lock:
        saved = _models.get(key)
        _models[key] = models
    try:
        yield models
    finally:
        with _lock:
            if saved is None:
                _models.pop(key, None)
            else:
                _models[key] = saved


def encode_dome(dome_hdr: np.ndarray, sky_model=None) -> SkyVector:
    """Sky vector of an HDR dome (H, W, 3) on its LDR's scale (the encoder sees ``hdr_to_ldr(dome)``)."""
    model = sky_model or get_models()[0]
    check_shape(dome_hdr, (model.cfg.height, model.cfg.width, 3), "dome")
    ldr = torch.from_numpy(quantize_ldr(dome_hdr).transpose(2, 0, 1)[None].copy())
    with torch.no_grad():
        li, d, z = model.encoder(ldr)
    return SkyVector(np.expm1(li[0].double().numpy()), d[0].double().numpy(), z[0].double().numpy())


def _decode_log(sky_model, log_int, direction, latent):
    return sky_model.decoder(log_int, direction, latent)


def decode_sky(sky: SkyVector, sky_model=None) -> np.ndarray:
    """HDR dome (H, W, 3) float32 (heading frame) decoded from a sky vector."""
    model = sky_model or get_models()[0]
    li = torch.from_numpy(np.log1p(np.maximum(sky.intensity_rgb, 0.0))[None]).float()
    d = torch.from_numpy(np.asarray(sky.direction)[None]).float()
    z = torch.from_numpy(np.asarray(sky.latent)[None]).float()
    with torch.no_grad():
        y = _decode_log(model, li, d, z)[0]
    return np.expm1(np.maximum(y.numpy(), 0.0)).transpose(1, 2, 0).astype(np.float32)


# ----------------------------------------------------------------------------- single image


def _diffuse_intensity(dome: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """RGB (3,) of the sky around ``direction`` (median of a 2-5 pixel ring): a peak without a sun."""
    H, W = dome.shape[:2]
    ang = np.arccos(np.clip(dome_directions(H, W) @ direction, -1, 1)) / dome_pixel_size_rad(H)
    ring = (ang >= 2.0) & (ang <= 5.0)
    if not ring.any():
        ring = np.ones((H, W), bool)
    return np.median(dome[ring], axis=0).astype(np.float64)


def simple_sky_mask(ldr: np.ndarray, rays_h: np.ndarray) -> np.ndarray:
    """(h, w) bool: bright, smooth pixels at least 2 deg above the horizon in regions touching the top row.

    Bright = LDR luminance >= 0.25 and >= the 10th percentile above the horizon: facing away from a low sun
    the sky darkens towards the top of the image, and a higher percentile (40 until v2) left no sky to fit.
    ``ldr`` (h, w, 3) float in [0, 1]; ``rays_h`` (h, w, 3) heading-frame unit rays.
    """
    elevation = np.arcsin(np.clip(rays_h[..., 2], -1.0, 1.0))
    return sky_mask(ldr, elevation, min_elevation_deg=2.0, min_lum=0.25, bright_percentile=10.0, max_grad=0.15)


def _posterior_direction(p: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """Unit mean direction of ``p`` (n,) over ``bins`` (n, 3) within 20 deg of its mode."""
    mode = bins[int(np.argmax(p))]
    near = bins @ mode >= np.cos(np.radians(20.0))
    d = (p[near, None] * bins[near]).sum(axis=0)
    return d / np.linalg.norm(d)


def _clear_sky_posterior(small: np.ndarray, rays_h: np.ndarray, Ks: np.ndarray, R_heading_from_cam: np.ndarray,
                         p: np.ndarray, bins: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The network's direction distribution ``p`` (n,) over ``bins`` (n, 3) (heading frame) to the power
    ``CNN_WEIGHT``, times the clear-sky fit's likelihood on the view ``small`` (h, w, 3) uint8 (rays ``rays_h``
    (h, w, 3), intrinsics ``Ks``, sky pixels ``mask`` (h, w) bool) and the "not on bright unclipped pixels in
    view" term; normalised."""
    ldr_s = small.astype(np.float64) / 255.0
    loglik, _ = sky_fit_loglik(small, rays_h, mask, bins, temperature=FIT_TEMPERATURE)
    # the sun would clip the pixel it sits on: bright unclipped pixels above the horizon are not it
    no_sun = ((ldr_s.max(axis=-1) < SATURATED_LDR) & (luminance(ldr_s) > 0.25)
              & (rays_h[..., 2] > np.sin(np.radians(-1.0))))
    loglik = loglik + in_view_sky_loglik(bins, R_heading_from_cam, Ks, no_sun, IN_VIEW_PENALTY)
    logp = CNN_WEIGHT * np.log(np.maximum(p, 1e-12)) + loglik
    p = np.exp(logp - logp.max())
    return p / p.sum()


def glare_is_sun(region_features: dict) -> bool:
    """Whether a clipped region whose :func:`.sun_cues.glare_region_features` are ``region_features`` may be the
    sun: the sky within 8 deg of it is brighter than the sky 15-35 deg beyond by at least ``GLARE_MIN_FALLOFF``
    (log ratio of linear radiance, ``GLARE_FALLOFF_KEY``): a sun's glare falls off with the angle from it, a
    clipped patch of overcast sky sits in an even sky.  Without enough sky around it to tell (fewer than 8 sky
    pixels in a ring: a patch among leaves): ``GLARE_FALLOFF_UNKNOWN_IS_SUN``."""
    f = region_features.get(GLARE_FALLOFF_KEY, float("nan"))
    if f is None or not np.isfinite(f):
        return GLARE_FALLOFF_UNKNOWN_IS_SUN
    return bool(f >= GLARE_MIN_FALLOFF)


def _decide(sky: SkyVector, R: np.ndarray, vis_used: float, unc: float, cue: str, sky_model,
            unconfirmed: str | None = None) -> SkyPrediction:
    """Report the sun if visible enough, certain enough, above the horizon and not ``unconfirmed`` (why the
    image cannot confirm the network's sun); else a diffuse sky (the peak's intensity lowered to the surrounding
    sky)."""
    direction = sky.direction
    direction_cam = R.T @ direction
    reasons = [unconfirmed] if unconfirmed else []
    if vis_used < VISIBILITY_MIN:
        reasons.append(f"sun visibility {vis_used:.2f} < {VISIBILITY_MIN}")
    if unc > UNCERTAINTY_MAX_DEG:
        reasons.append(f"direction uncertainty {unc:.0f} deg > {UNCERTAINTY_MAX_DEG:.0f}")
    if direction[2] < -0.02:
        reasons.append("peak below the horizon")
    if not reasons:
        reason = f"sun from the image ({cue}): visibility {vis_used:.2f}, 68% cone {unc:.0f} deg"
        return SkyPrediction(sky, sky, R, direction_cam, vis_used, direction_cam, vis_used, unc, True, reason)
    dome = decode_sky(sky, sky_model)
    diffuse = replace(sky, intensity_rgb=_diffuse_intensity(dome, direction))
    reason = f"no reliable sun in the image ({cue}: " + "; ".join(reasons) + "): diffuse sky"
    return SkyPrediction(diffuse, sky, R, None, 0.0, direction_cam, vis_used, unc, False, reason)


def predict_sky(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray | None = None,
                models=None, use_cues: bool = True) -> SkyPrediction:
    """Sky vector and sun of one LDR image without metadata (or with a known up direction).

    Args:
        image_rgb: (H, W, 3) uint8 RGB, the contract's camera response.
        K: (3, 3) intrinsics (pixel centres at integers).
        up_cam: (3,) gravity up in the camera frame; default (0, -1, 0) (a level camera).
        models: (sky model, image predictor), default the shipped ones.
        use_cues: combine the network with the explicit cues of :mod:`.sun_cues`: a sun disc seen in
            the image gives the direction directly (its visibility is at least ``DISC_VISIBILITY``);
            otherwise the network's direction distribution (to the power ``CNN_WEIGHT``: a weak prior)
            is multiplied by the clear-sky fit's likelihood and by the "not on bright unclipped pixels
            in view" term.  If the posterior's direction lands in a clipped region of the image, the
            68 % cone is at least that region's angular radius (the sun can be anywhere under the
            glare) and, if that radius is <= ``GLARE_CENTRE_MAX_DEG`` (a sun's glare, not a blown-out sky),
            the direction moves to the region's centre (:func:`.sun_cues.glare_centre_cam`); a cone still
            <= ``GLARE_MAX_UNCERTAINTY_DEG`` there counts as a seen sun (visibility >= ``GLARE_VISIBILITY``).
            A clipped region (under a disc or under the fitted sun) does any of this only if it glows
            (:func:`glare_is_sun`: the sky next to it is brighter than the sky beyond); otherwise a disc is
            ignored and a fitted sun stays where the fit put it, at the network's visibility.
            With less than ``FIT_MIN_SKY_FRACTION`` of the view classified as sky, there is no sky to fit:
            the network's direction stands, but no sun is reported (nothing in view confirms it) unless a
            sun disc was detected.
            False: the network alone.
    """
    image_rgb = np.asarray(image_rgb)
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    if image_rgb.dtype != np.uint8:
        raise ValueError(f"image_rgb must be uint8 RGB, got dtype {image_rgb.dtype}")
    check_shape(np.asarray(K), (3, 3), "K")
    t0 = time.perf_counter()
    sky_model, net = models or get_models()
    up = np.array([0.0, -1.0, 0.0]) if up_cam is None else np.asarray(up_cam, dtype=np.float64)
    R = heading_from_camera(up)
    h, w = VIEW_SIZE
    small, Ks = resize_view(image_rgb, np.asarray(K, dtype=np.float64), h, w)
    ldr = torch.from_numpy(np.ascontiguousarray(small.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0)
    rays = torch.from_numpy(view_rays(Ks, R, h, w)[None])
    t1 = time.perf_counter()
    with torch.no_grad():
        o = net(ldr, rays)
    t2 = time.perf_counter()
    direction = o["dir"][0].double().numpy()
    p = torch.exp(o["dir_logp"][0]).double().numpy()
    bins = net.bin_dirs.double().numpy()
    vis = float(torch.sigmoid(o["vis_logit"][0]))
    vis_used = vis
    cue = "network"
    cues: dict = {"visibility_network": vis, "glare_fired": False, "glare_moved": False}
    disc = detect_sun_disc(image_rgb, K, up / np.linalg.norm(up)) if use_cues else None
    cues["disc"] = disc is not None
    rays_h = rays[0].numpy().transpose(1, 2, 0).astype(np.float64)
    up_small_cam = R.T @ np.array([0.0, 0.0, 1.0])
    if use_cues:
        mask = simple_sky_mask(small.astype(np.float64) / 255.0, rays_h)
        cues.update(sky_features(small, rays_h, mask))
    sky_cues = bool(use_cues and cues["sky_fraction"] >= FIT_MIN_SKY_FRACTION)  # sky enough to fit and to confirm
    if disc is not None:
        cues.update(disc_radius_deg=disc.radius_deg, disc_halo=disc.halo, disc_at_border=disc.clipped,
                    disc_elevation_deg=float(np.degrees(np.arcsin(np.clip((R @ disc.direction_cam)[2], -1, 1)))))
        disc_region = clipped_region_at(small, Ks, disc.direction_cam)
        if disc_region is not None:
            cues["disc_region"] = glare_region_features(small, Ks, disc_region, disc.direction_cam, up_small_cam, mask)
            if not glare_is_sun(cues["disc_region"]):  # a round clipped patch in an even (overcast) sky: not the sun
                cues["disc_rejected"] = True
                disc = None
    if disc is not None:
        direction = R @ disc.direction_cam
        unc = disc.uncertainty_deg
        vis_used = max(vis, DISC_VISIBILITY)
        cue = f"sun disc at pixel ({disc.pixel_xy[0]:.0f}, {disc.pixel_xy[1]:.0f})"
    else:
        if sky_cues:
            p = _clear_sky_posterior(small, rays_h, Ks, R, p, bins, mask)
            direction = _posterior_direction(p, bins)
            cue = "network x clear-sky fit"
        elif use_cues:
            cue = f"network (sky fraction {cues['sky_fraction']:.2f} < {FIT_MIN_SKY_FRACTION}: no clear-sky fit)"
        cues["clear_sky_fit"] = sky_cues
        unc = direction_cone_deg(p, bins, direction)
        cues.update(direction_fit_cam=R.T @ direction, uncertainty_fit_deg=unc)
        # a fitted sun inside a clipped region of the image is known only to within that region's radius
        region = clipped_region_at(small, Ks, R.T @ direction) if sky_cues else None
        glare = glare_extent_deg(region, Ks, R.T @ direction) if region is not None else None
        if glare is not None:
            centre_cam = glare_centre_cam(region, Ks)
            features = glare_region_features(small, Ks, region, centre_cam, up_small_cam, mask)
            sun_like = glare_is_sun(features)
            cues.update(glare_extent_from_fit_deg=glare, glare_centre_cam=centre_cam, region=features,
                        glare_sun_like=sun_like)
            unc = max(unc, glare)
            cue += f", in a clipped region of radius {glare:.0f} deg"
            if not sun_like:
                cue += " (no glare around it: not the sun)"
            elif glare <= GLARE_CENTRE_MAX_DEG:  # a sun's glare, not a blown-out sky: its middle, not its edge
                direction = R @ centre_cam
                cue += " (its centre)"
                cues["glare_moved"] = True
        if glare is not None and cues.get("glare_sun_like") and unc <= GLARE_MAX_UNCERTAINTY_DEG and \
                direction[2] >= np.sin(np.radians(GLARE_MIN_ELEVATION_DEG)):
            vis_used = max(vis, GLARE_VISIBILITY)  # the fitted sun sits in a compact clipped glare: seen
            cues["glare_fired"] = True
    t3 = time.perf_counter()
    sky = SkyVector(np.expm1(o["log_int"][0].double().numpy()), direction, o["latent"][0].double().numpy())
    # without sky in view nothing confirms the network's sun (a dim night sky, a street under trees)
    unconfirmed = "too little sky in view to confirm it" if use_cues and disc is None and not sky_cues else None
    out = _decide(sky, R, vis_used, unc, cue, sky_model, unconfirmed)
    timing = {"prepare": t1 - t0, "network": t2 - t1, "cues": t3 - t2, "total": time.perf_counter() - t0}
    return replace(out, timing_s=timing, cues=cues)


# ----------------------------------------------------------------------------- refinement


def _grid_sample_dome(log_dome, dirs_h):
    """Bilinear lookup (N, 3) of a (1, 3, H, W) dome at heading-frame directions (N, 3) (torch, differentiable)."""
    H, W = log_dome.shape[2:]
    padded = torch.cat([log_dome[..., -1:], log_dome, log_dome[..., :1]], dim=3)  # wrap in longitude
    lon = torch.atan2(dirs_h[:, 1], dirs_h[:, 0])
    lat = torch.asin(dirs_h[:, 2].clamp(0.0, 1.0))
    x = (lon / (2 * np.pi) + 0.5) * W - 0.5 + 1.0  # pixel coordinate in the padded map
    y = (1.0 - lat / (np.pi / 2)) * H - 0.5
    gx = (x + 0.5) / (W + 2) * 2 - 1
    gy = (y + 0.5) / H * 2 - 1
    grid = torch.stack([gx, gy], dim=-1)[None, None].float()
    out = F.grid_sample(padded, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return out[0, :, 0].T


def refine_sky(sky: SkyVector, image_rgb: np.ndarray, K: np.ndarray, sky_mask: np.ndarray,
               up_cam: np.ndarray | None = None, sun_dir_cam: np.ndarray | None = None, steps: int = 20,
               prior_weight: float = 0.01, lr: float = 0.1, models=None) -> SkyVector:
    """Refine a sky vector against the visible sky pixels of the image through the frozen decoder.

    Args:
        sky: initial sky vector (heading frame of this camera), e.g. ``predict_sky(...).sky``.
        image_rgb: (H, W, 3) uint8 image (contract response).
        K: (3, 3) intrinsics of ``image_rgb``.
        sky_mask: (H, W) bool, True on sky pixels (e.g. the lighting estimator's sky mask).
        up_cam: (3,) gravity up in the camera frame (default level camera, (0, -1, 0)).
        sun_dir_cam: (3,) the ephemeris sun direction (camera frame): overrides the direction, which is
            then kept fixed.  If None the direction is optimised too.
        steps: Adam steps (each ~20-40 ms on one core at 32 x 128).
        prior_weight: weight of the pull towards the initial latent/intensity (the image rarely
            constrains the whole sky).

    Returns the refined sky vector (same frame).  Unsaturated sky pixels are fitted in ``log1p`` HDR;
    saturated ones (LDR >= 0.97) only push the sky up to at least their value.
    """
    image_rgb = np.asarray(image_rgb)
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    sky_mask = np.asarray(sky_mask, dtype=bool)
    check_shape(sky_mask, image_rgb.shape[:2], "sky_mask")
    sky_model = (models or get_models())[0]
    up = np.array([0.0, -1.0, 0.0]) if up_cam is None else np.asarray(up_cam, dtype=np.float64)
    R = heading_from_camera(up)
    direction = np.asarray(sky.direction, dtype=np.float64)
    if sun_dir_cam is not None:
        d = R @ np.asarray(sun_dir_cam, dtype=np.float64)
        direction = d / np.linalg.norm(d)
    jj, ii = np.nonzero(sky_mask)
    if len(jj) < 10 or steps <= 0:
        return replace(sky, direction=direction)
    if len(jj) > REFINE_MAX_PIXELS:  # deterministic subsample
        sel = np.linspace(0, len(jj) - 1, REFINE_MAX_PIXELS).astype(np.int64)
        jj, ii = jj[sel], ii[sel]
    rays_h = pixel_rays(np.asarray(K, dtype=np.float64), np.stack([ii, jj], 1).astype(np.float64)) @ R.T
    above = rays_h[:, 2] > 0.0
    if above.sum() < 10:
        return replace(sky, direction=direction)
    rays_h, jj, ii = rays_h[above], jj[above], ii[above]
    ldr = image_rgb[jj, ii].astype(np.float64) / 255.0
    target = torch.from_numpy(np.log1p(ldr_uint8_to_hdr(image_rgb[jj, ii][None])[0].astype(np.float64))).float()
    saturated = torch.from_numpy(ldr.max(axis=1) >= SATURATED_LDR)
    dirs_t = torch.from_numpy(rays_h).float()

    li0 = torch.from_numpy(np.log1p(np.maximum(sky.intensity_rgb, 0.0))[None]).float()
    z0 = torch.from_numpy(np.asarray(sky.latent)[None]).float()
    d0 = torch.from_numpy(direction[None]).float()
    li = li0.clone().requires_grad_(True)
    z = z0.clone().requires_grad_(True)
    params = [li, z]
    d_raw = d0.clone()
    if sun_dir_cam is None:
        d_raw.requires_grad_(True)
        params.append(d_raw)
    opt = torch.optim.Adam(params, lr=lr)
    for p in sky_model.parameters():
        p.requires_grad_(False)
    for _ in range(int(steps)):
        d = torch.nn.functional.normalize(d_raw, dim=1)
        log_dome = _decode_log(sky_model, li.clamp(min=0.0), d, z)
        pred = _grid_sample_dome(log_dome, dirs_t)
        err = pred - target
        fit = torch.where(saturated[:, None], torch.relu(-err), err) ** 2
        loss = fit.mean() + prior_weight * (((z - z0) ** 2).mean() + 0.1 * ((li - li0) ** 2).mean())
        opt.zero_grad()
        loss.backward()
        opt.step()
    d = torch.nn.functional.normalize(d_raw.detach(), dim=1)[0].double().numpy()
    return SkyVector(np.expm1(li.detach().clamp(min=0.0)[0].double().numpy()), d, z.detach()[0].double().numpy())


# ----------------------------------------------------------------------------- to a light


def split_sun(dome: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dome without the sun (H, W, 3), sun irradiance (3,)): the decoded excess over the surrounding sky
    within ``SUN_REGION_PX`` pixels of ``direction`` (zero if it carries < MIN_SUN_FRACTION of the dome's
    irradiance)."""
    H, W = dome.shape[:2]
    ang = np.arccos(np.clip(dome_directions(H, W) @ direction, -1, 1)) / dome_pixel_size_rad(H)
    region = ang <= SUN_REGION_PX
    ring = (ang > SUN_REGION_PX) & (ang <= 2 * SUN_REGION_PX)
    if not region.any() or not ring.any():
        return dome, np.zeros(3)
    background = np.median(dome[ring], axis=0)
    omega = dome_solid_angles(H, W)
    excess = np.maximum(dome[region] - background, 0.0)
    e_sun = (excess * omega[region][:, None]).sum(axis=0)
    total = (luminance(dome) * omega).sum()
    if luminance(e_sun) < MIN_SUN_FRACTION * total:
        return dome, np.zeros(3)
    residual = dome.copy()
    residual[region] = np.minimum(dome[region], background)
    return residual, e_sun.astype(np.float64)


def sky_to_light(sky: SkyVector, R_heading_from_cam: np.ndarray, sun_visibility: float = 1.0,
                 with_sun: bool = True, height: int = 128, width: int = 256, ground_albedo: float = 0.15,
                 ground_radiance: np.ndarray | None = None, sky_model=None, dome: np.ndarray | None = None) -> DistantLight:
    """Camera-frame distant light of a sky vector.

    The decoded dome fills the upper hemisphere (bilinear); its sun peak becomes an analytic
    :class:`SunLight` along ``sky.direction`` (when ``with_sun`` and it is bright enough); below the
    horizon a uniform ground: ``ground_radiance`` (3,) if given (e.g. the image's road), else
    ``ground_albedo`` x the horizontal irradiance of sky + sun / pi.
    """
    dome = decode_sky(sky, sky_model) if dome is None else dome
    H, W = dome.shape[:2]
    R = np.asarray(R_heading_from_cam, dtype=np.float64)
    direction = np.asarray(sky.direction, dtype=np.float64)
    residual, e_sun = split_sun(dome, direction) if with_sun and direction[2] > 0 else (dome, np.zeros(3))
    d_cam = camera_envmap_directions(height, width).reshape(-1, 3)
    d_h = d_cam @ R.T
    env = sample_dome(residual.astype(np.float64), d_h)
    if ground_radiance is None:
        dirs = dome_directions(H, W).reshape(-1, 3)
        omega = dome_solid_angles(H, W).reshape(-1)
        e_h = (residual.reshape(-1, 3) * (omega * dirs[:, 2])[:, None]).sum(axis=0) + e_sun * max(direction[2], 0.0)
        ground = ground_albedo * e_h / np.pi
    else:
        ground = np.asarray(ground_radiance, dtype=np.float64)
        check_shape(ground, (3,), "ground_radiance")
    env = np.where(d_h[:, 2:3] < 0.0, ground[None], env).reshape(height, width, 3).astype(np.float32)
    sun = None
    if np.any(e_sun > 0):
        sun = SunLight(direction=R.T @ direction, irradiance_rgb=e_sun, visibility=float(np.clip(sun_visibility, 0, 1)))
    return DistantLight(env, sun)


def estimate_sky_light(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray | None = None,
                       sun_dir_cam: np.ndarray | None = None, sky_mask: np.ndarray | None = None,
                       refine_steps: int = 20, refine_direction: bool = False,
                       ground_radiance: np.ndarray | None = None, height: int = 128, width: int = 256,
                       models=None) -> tuple[DistantLight, SkyPrediction, SkyVector]:
    """Predict, override the sun with the ephemeris if given, refine on the sky pixels, build the light.

    Args:
        image_rgb, K, up_cam: as :func:`predict_sky`.
        sun_dir_cam: (3,) ephemeris sun direction (camera frame) or None (image only).  With it, the sun
            is reported whenever the network's visibility is >= VISIBILITY_MIN and the sun is above the
            horizon (the direction uncertainty no longer matters).
        sky_mask: (H, W) bool sky pixels for :func:`refine_sky`; None skips the refinement.
        refine_direction: without ephemeris, let the refinement move the direction too.
        ground_radiance: (3,) radiance below the horizon (image scale), see :func:`sky_to_light`.

    Returns (camera-frame DistantLight on the image's scale, the prediction, the final sky vector).
    """
    models = models or get_models()
    pred = predict_sky(image_rgb, K, up_cam, models=models)
    R = pred.R_heading_from_cam
    if sun_dir_cam is not None:
        d = R @ np.asarray(sun_dir_cam, dtype=np.float64)
        d = d / np.linalg.norm(d)
        with_sun = pred.visibility_raw >= VISIBILITY_MIN and d[2] > 0.0
        visibility = pred.visibility_raw if with_sun else 0.0
        sky = replace(pred.sky_raw if with_sun else pred.sky, direction=d)
        if not with_sun:  # diffuse: no peak at the ephemeris direction either
            sky = replace(sky, intensity_rgb=_diffuse_intensity(decode_sky(sky, models[0]), d))
        fixed_dir_cam = R.T @ d
    else:
        sky, with_sun, visibility = pred.sky, pred.confident, pred.sun_visibility
        fixed_dir_cam = None if (refine_direction and with_sun) else R.T @ sky.direction
    if sky_mask is not None and refine_steps > 0:
        sky = refine_sky(sky, image_rgb, K, sky_mask, up_cam, fixed_dir_cam, steps=refine_steps, models=models)
    light = sky_to_light(sky, R, visibility, with_sun, height, width, ground_radiance=ground_radiance,
                         sky_model=models[0])
    return light, pred, sky
