"""Image error metrics shared by the benchmarks, ``streetaug bench`` and ``streetaug stability``."""

from __future__ import annotations

import numpy as np


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
