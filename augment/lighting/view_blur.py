"""The expected view under geometric uncertainty: each pixel blurred by how far what it shows may lie from where
it is drawn.

A light field rendered from a centre no input camera stood at (another camera's view, a later keyframe's, an
inserted object's local environment map) reprojects seen surfaces whose depth is uncertain; drawing them sharp
where their place is a guess costs twice under a squared error (where the outline is drawn and where it is).
:meth:`.volume.HybridLighting.radiance_spread` gives each ray's angular uncertainty; the functions here turn it
into a per-pixel Gaussian blur, for a perspective view (:func:`uncertainty_blurred`) and an equirectangular map
(:func:`uncertainty_blurred_equirect`, wrapping in longitude).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

# A view from a centre no input camera stood at is blurred per pixel by how far what it shows may lie from where
# it is drawn: the seen surface's reprojection uncertainty (:meth:`.seen_surfaces.SeenSurfaces.trace_spread`, an
# angle) times SPREAD_SCALE at the view's focal length, the map smoothed over SPREAD_SMOOTH_PX (320 px view) so
# that it reaches across a surface's silhouette onto what lies behind it (the texture blur cannot: a canopy's
# outline drawn sharp where it is uncertain costs twice, where it is drawn and where it is). SPREAD_SCALE > 1:
# the depth is not the only thing misplaced (the vertical-facade prior above the LiDAR, poses, moved objects).
# Chosen on scene-0916's even stride-4 keyframes (0, 8, 16, 24, 32), six-view forward mean PSNR: no blur 17.37,
# scale 1 / 2 / 4 (smooth 4) 17.50 / 17.59 / 17.64, scale 4 smooth 2 / 8 / 16 / 32 17.58 / 17.69 / 17.72 / 17.71,
# scale 6 smooth 16 17.69; held out (odd keyframes 4 ... 36): 16.27 -> 16.84 (each keyframe +0.35..+1.01).
SPREAD_SCALE = 4.0
SPREAD_SMOOTH_PX = 16.0
VIEW_BLUR_LEVELS_PX = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)
# the same smoothing as an angle, for maps: SPREAD_SMOOTH_PX at a 320 px CAM_FRONT view (focal ~253 px)
SPREAD_SMOOTH_RAD = 0.063


def uncertainty_blurred(image: np.ndarray, sigma_px: np.ndarray, smooth_px: float | None = None) -> np.ndarray:
    """``image`` (h, w, 3) linear, each pixel Gaussian-blurred by its own ``sigma_px`` (h, w) (the map first
    smoothed by ``smooth_px``, default ``SPREAD_SMOOTH_PX``: a surface's uncertainty reaches across its
    silhouette), interpolated linearly between the copies blurred by ``VIEW_BLUR_LEVELS_PX`` (clamped at the
    largest); the image itself where the map is 0 (a view from an input camera's own centre)."""
    sigma = np.asarray(sigma_px, np.float32)
    if not np.any(sigma > 0):
        return image
    smooth_px = SPREAD_SMOOTH_PX if smooth_px is None else smooth_px
    if smooth_px > 0:
        sigma = cv2.GaussianBlur(sigma, (0, 0), smooth_px, borderType=cv2.BORDER_REPLICATE)
    levels = np.asarray(VIEW_BLUR_LEVELS_PX, np.float32)
    sigma = np.clip(sigma, 0.0, levels[-1])
    img = np.asarray(image, np.float32)
    hi = np.clip(np.searchsorted(levels, sigma), 1, len(levels) - 1)
    w_hi = np.clip((sigma - levels[hi - 1]) / (levels[hi] - levels[hi - 1]), 0.0, 1.0)[..., None]
    out = np.zeros_like(img)
    for i, s in enumerate(levels):
        w = np.where((hi == i)[..., None], w_hi, 0.0) + np.where((hi - 1 == i)[..., None], 1.0 - w_hi, 0.0)
        if not np.any(w > 0):
            continue
        blurred = img if s == 0 else cv2.GaussianBlur(img, (0, 0), float(s), borderType=cv2.BORDER_REPLICATE)
        out += w * blurred
    return out


def uncertainty_blurred_equirect(envmap: np.ndarray, spread_rad: np.ndarray) -> np.ndarray:
    """An equirectangular map (h, w, 3) blurred per pixel by ``SPREAD_SCALE`` x its rays' angular uncertainty
    ``spread_rad`` (h, w) (:func:`uncertainty_blurred` in pixels of the map's longitude step, smoothed over
    ``SPREAD_SMOOTH_RAD``), wrapping across the map's left and right edges; the map itself where nothing is
    uncertain."""
    spread = np.asarray(spread_rad, np.float32)
    if not np.any(spread > 0):
        return envmap
    h, w = spread.shape
    px_per_rad = w / (2.0 * math.pi)
    pad = min(w, int(math.ceil(4 * (VIEW_BLUR_LEVELS_PX[-1] + SPREAD_SMOOTH_RAD * px_per_rad))) + 1)
    wrap = ((0, 0), (pad, pad))
    out = uncertainty_blurred(np.pad(np.asarray(envmap, np.float32), wrap + ((0, 0),), mode="wrap"),
                              np.pad(SPREAD_SCALE * px_per_rad * spread, wrap, mode="wrap"),
                              smooth_px=SPREAD_SMOOTH_RAD * px_per_rad)
    return out[:, pad : pad + w]
