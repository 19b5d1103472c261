"""The view a lighting estimate predicts for a camera: its light field at the camera's centre along the pixels' rays.

This is how a map is checked against an image (and how ``auto`` chooses the level of a written map): a map
on the image's scale, rendered from the camera's own centre and passed through the contract's response at
EV 0, reproduces the image's colours where the camera saw something.

* L0/L1 (distant light): the camera's own estimate if it was an input (its frame and exposure), else the
  reference camera's distant light turned into its frame (reference exposure);
* L2/L3: the volume's radiance traced from the camera's centre (lifted out of solid voxels) along each pixel's
  ray, sun excluded, times the camera's exposure ratio if it was an input; from a centre no input camera stood
  at, each pixel blurred by how uncertain the place of what it shows is (:func:`uncertainty_blurred`: the
  expected view, not a sharp guess; none for an input camera's own view).

A camera that was *not* an input (another camera of the instant, or the same camera at another time) has an
exposure no input measured: its auto-exposure sets it. Auto-exposure holds an image's mean brightness steady
(the 246 camera images of scene-0916 have mean values 0.31-0.46, half of them within 0.39-0.43, whatever the
scene's brightness), so the prediction is exposed like that camera would expose it
(:func:`auto_exposure_target`, :func:`exposed_to_mean_ldr`): a scale per view, taken from the inputs only.
"""

from __future__ import annotations

import cv2
import numpy as np

from ...datasets.sample import CameraView
from ..core import hdr_to_ldr, invert_transform, pixel_rays
from .types import SampleLighting
from .volume import as_numpy

PREDICTED_WIDTH_PX = 320
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


def view_rays(view: CameraView, width: int = PREDICTED_WIDTH_PX) -> tuple[np.ndarray, int]:
    """Camera-frame unit rays (h * width, 3) through the pixel centres of the view shrunk to ``width``, and h."""
    H, W = view.height, view.width
    h = view_height_px(view, width)
    u, v = np.meshgrid((np.arange(width) + 0.5) * W / width - 0.5, (np.arange(h) + 0.5) * H / h - 0.5)
    return pixel_rays(view.K, np.stack([u.ravel(), v.ravel()], 1)), h


def view_height_px(view: CameraView, width: int) -> int:
    """Rows of the view shrunk to ``width`` columns (aspect kept)."""
    return max(int(round(view.height * width / view.width)), 1)


def observed_ldr(view: CameraView, width: int = PREDICTED_WIDTH_PX) -> np.ndarray:
    """The camera's real image (h, width, 3) in [0, 1], shrunk with an area filter (what a prediction is judged
    against)."""
    h = view_height_px(view, width)
    return cv2.resize(np.asarray(view.image), (width, h), interpolation=cv2.INTER_AREA).astype(np.float64) / 255.0


def auto_exposure_target(lighting: SampleLighting, view: CameraView) -> float | None:
    """The mean image value in [0, 1] the camera of ``view`` would expose to: that camera's own input image if it
    was an input channel (at another time), else the mean over the input images; None if unknown."""
    means = lighting.input_mean_ldr
    if view.channel in means:
        return float(means[view.channel])
    return float(np.mean(list(means.values()))) if means else None


def exposed_to_mean_ldr(radiance: np.ndarray, target_ldr: float, iters: int = 48) -> np.ndarray:
    """``radiance`` (..., 3) times the exposure whose image through the contract's response at EV 0 has the mean
    value ``target_ldr`` (bisection in log exposure over +-16 stops; the mean grows monotonically with it)."""
    rad = np.asarray(radiance, dtype=np.float64)
    lo, hi = -16.0 * np.log(2.0), 16.0 * np.log(2.0)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if float(hdr_to_ldr(rad * np.exp(mid)).mean()) < target_ldr:
            lo = mid
        else:
            hi = mid
    return rad * np.exp(0.5 * (lo + hi))


def predicted_radiance(lighting: SampleLighting, view: CameraView, width: int = PREDICTED_WIDTH_PX) -> np.ndarray:
    """Linear radiance (h, width, 3) that ``lighting`` predicts for ``view`` (see module doc); nothing is
    fitted to the view's image."""
    rays, h = view_rays(view, width)
    same = lighting.is_input(view)
    if lighting.hybrid is None:
        if same:
            light = lighting.per_view[view.channel].light_cam
        else:
            ref = lighting.per_view[lighting.reference]
            R = np.asarray(view.T_cam_from_global)[:3, :3] @ np.asarray(lighting.T_global_from_ref_cam)[:3, :3]
            light = ref.light_cam.rotated(R)
        rad = light.radiance(np.zeros_like(rays), rays).reshape(h, width, 3)
        return rad if same else auto_exposed(lighting, view, rad)
    T = invert_transform(lighting.T_global_from_vol) @ np.asarray(view.T_global_from_cam)
    centre = lighting.hybrid.lift_out_of_solid(T[:3, 3])
    dirs = rays @ T[:3, :3].T
    rad, spread = lighting.hybrid.radiance_spread(np.repeat(centre[None], len(dirs), axis=0), dirs, include_sun=False)
    rad = rad.reshape(h, width, 3)
    if not same:  # an input camera's own view is known: no blur there
        focal_px = float(view.K[0][0]) * width / view.width
        rad = uncertainty_blurred(rad, SPREAD_SCALE * focal_px * spread.reshape(h, width))
    return rad * float(lighting.exposure_ratio.get(view.channel, 1.0)) if same else auto_exposed(lighting, view, rad)


def uncertainty_blurred(image: np.ndarray, sigma_px: np.ndarray, smooth_px: float | None = None) -> np.ndarray:
    """``image`` (h, w, 3) linear, each pixel Gaussian-blurred by its own ``sigma_px`` (h, w) (the map first
    smoothed by ``smooth_px``, default ``SPREAD_SMOOTH_PX``: a surface's uncertainty reaches across its silhouette), interpolated linearly
    between the copies blurred by ``VIEW_BLUR_LEVELS_PX`` (clamped at the largest); the image itself where the
    map is 0 (a view from an input camera's own centre)."""
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


def auto_exposed(lighting: SampleLighting, view: CameraView, radiance: np.ndarray) -> np.ndarray:
    """A non-input view's prediction ``radiance`` (at the reference exposure) at its camera's auto-exposure
    (:func:`auto_exposure_target`; left at the reference exposure if that is unknown)."""
    target = auto_exposure_target(lighting, view)
    return radiance if target is None else exposed_to_mean_ldr(radiance, target)


def predicted_ldr(lighting: SampleLighting, view: CameraView, width: int = PREDICTED_WIDTH_PX) -> np.ndarray:
    """:func:`predicted_radiance` through the contract's response at EV 0: (h, width, 3) in [0, 1]."""
    return hdr_to_ldr(predicted_radiance(lighting, view, width))
