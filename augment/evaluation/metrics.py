"""Image error metrics shared by the benchmarks, ``streetaug bench`` and ``streetaug stability``."""

from __future__ import annotations

import cv2
import numpy as np

from ..core import equirect_solid_angles


def psnr_db(a: np.ndarray, b: np.ndarray, where: np.ndarray | None = None, peak: float = 255.0) -> float:
    """PSNR (dB) of two images over a boolean mask (whole image by default).

    ``peak`` is the signal peak (255 for 8-bit images, 1 for images in [0, 1]). Returns inf when the
    images agree and nan when the mask is empty.
    """
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    if where is not None:
        d = d[where]
    if d.size == 0:
        return float("nan")
    mse = float(np.mean(d**2))
    return float("inf") if mse == 0 else float(10 * np.log10(peak**2 / mse))


def env_log_error(estimated: np.ndarray, true: np.ndarray) -> float:
    """Environment-map error: solid-angle-weighted mean over the sphere and the channels of
    (log(1 + L_est) - log(1 + L_true))^2, for equirectangular (H, W, 3) maps (the estimate is resized to the
    true map's size; the sun, when drawn into the maps, counts like any pixel)."""
    true = np.asarray(true, np.float32)
    H, W = true.shape[:2]
    estimated = np.asarray(estimated, np.float32)
    if estimated.shape[:2] != (H, W):
        estimated = cv2.resize(estimated, (W, H), interpolation=cv2.INTER_AREA)
    w = equirect_solid_angles(H, W)[..., None]
    d = np.log1p(np.maximum(estimated, 0.0)) - np.log1p(np.maximum(true, 0.0))
    return float(np.sum(w * d**2) / (3 * np.sum(w)))
