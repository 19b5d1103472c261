"""The camera response (LDR <-> linear HDR) and luminance.

``LDR = softclip(clamp(HDR * 2^EV, 0)^(1/2.2))`` with the paper's soft clip, tau = 0.95.  LDR values are
floats in [0, 1] (divide uint8 by 255).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

GAMMA = 2.2
SOFTCLIP_TAU = 0.95


def softclip(x: np.ndarray, tau: float = SOFTCLIP_TAU) -> np.ndarray:
    """The paper's soft clip: identity up to tau, then an exponential shoulder towards 1."""
    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    high = x > tau  # the shoulder is worked out only where it acts
    out[high] = 1.0 - (1.0 - tau) * np.exp(-(x[high] - tau) / (1.0 - tau))
    return out


def inverse_softclip(y: np.ndarray, tau: float = SOFTCLIP_TAU) -> np.ndarray:
    """Inverse of :func:`softclip` on [0, 1); values >= 1 map to a large finite number."""
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0 - 1e-6)
    inv = tau - (1.0 - tau) * np.log(np.maximum((1.0 - y) / (1.0 - tau), 1e-12))
    return np.where(y <= tau, y, inv)


def hdr_to_ldr(hdr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Linear HDR radiance -> LDR floats in [0, 1] with the camera response of the contract."""
    x = np.clip(np.asarray(hdr, dtype=np.float64) * 2.0**ev, 0.0, None)
    return softclip(x ** (1.0 / GAMMA))


def ldr_to_hdr(ldr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """LDR floats in [0, 1] -> linear HDR radiance (inverse camera response of the contract)."""
    return inverse_softclip(ldr) ** GAMMA / 2.0**ev


@lru_cache(maxsize=16)
def _uint8_table(ev: float) -> np.ndarray:
    """(256,) read-only float32 linear HDR of every 8-bit level at exposure ``ev``."""
    table = ldr_to_hdr(np.arange(256, dtype=np.float64) / 255.0, ev).astype(np.float32)
    table.flags.writeable = False
    return table


def ldr_uint8_to_hdr(image: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """uint8 (H, W, 3) image -> float32 linear HDR (H, W, 3) (a 256-entry table for uint8 input)."""
    image = np.asarray(image)
    if image.dtype == np.uint8:
        return _uint8_table(float(ev))[image]
    return ldr_to_hdr(image.astype(np.float64) / 255.0, ev).astype(np.float32)


def hdr_to_ldr_uint8(hdr: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Linear HDR (H, W, 3) -> uint8 image with the contract's camera response (rounded)."""
    return np.clip(np.round(hdr_to_ldr(hdr, ev) * 255.0), 0, 255).astype(np.uint8)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (..., 3) -> (...)."""
    rgb = np.asarray(rgb)
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


SATURATION_LDR = 0.97  # LDR values at or above this (any channel) are clipped
SATURATION_RADIANCE = ldr_to_hdr(np.full(3, SATURATION_LDR))  # (3,) the radiance where the response saturates


def clipped_to_lower_bound(hdr: np.ndarray, ldr: np.ndarray) -> np.ndarray:
    """Linear radiance (..., 3) with clipped pixels (``ldr`` (..., 3) in [0, 1], any channel >= ``SATURATION_LDR``)
    set to the radiance where the response saturates: what a clipped pixel proves is "at least this bright".
    The inverse response of an LDR 1.0 is the soft clip's far tail (~2.4x that level), not a measurement."""
    hdr = np.asarray(hdr, dtype=np.float64)
    clipped = np.asarray(ldr).max(axis=-1) >= SATURATION_LDR
    return np.where(clipped[..., None], np.minimum(hdr, SATURATION_RADIANCE), hdr)

