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
from .view_blur import SPREAD_SCALE, uncertainty_blurred
from .volume import as_numpy

PREDICTED_WIDTH_PX = 320



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


def auto_exposed(lighting: SampleLighting, view: CameraView, radiance: np.ndarray) -> np.ndarray:
    """A non-input view's prediction ``radiance`` (at the reference exposure) at its camera's auto-exposure
    (:func:`auto_exposure_target`; left at the reference exposure if that is unknown)."""
    target = auto_exposure_target(lighting, view)
    return radiance if target is None else exposed_to_mean_ldr(radiance, target)


def predicted_ldr(lighting: SampleLighting, view: CameraView, width: int = PREDICTED_WIDTH_PX) -> np.ndarray:
    """:func:`predicted_radiance` through the contract's response at EV 0: (h, width, 3) in [0, 1]."""
    return hdr_to_ldr(predicted_radiance(lighting, view, width))
