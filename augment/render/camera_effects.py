"""Match the inserted object to the image's blur and noise (the paper's failure case (a): a rendered
object is sharper and cleaner than the photo around it).

Both are measured on the input image in LDR units (the contract's camera response, 1.0 = full scale):

* **Noise** (Immerkaer 1996, made robust): the image is filtered with the 3 x 3 mask
  ``[[1,-2,1],[-2,4,-2],[1,-2,1]]`` (the difference of two Laplacians, blind to flat and linear
  intensity), whose output on i.i.d. noise of std sigma has std 6 sigma.  Edges and clipped pixels are
  excluded and the median absolute value gives ``sigma = 1.4826 median|h| / 6``.
* **Blur** (Zhuo & Sim 2011, "Defocus map estimation from a single image"): at edge pixels (Canny,
  gradient maxima) the image is re-blurred with a Gaussian of std ``s0``; for a step edge blurred by a
  Gaussian of std sigma the gradient maximum drops by ``R = sqrt(sigma^2 + s0^2) / sigma``, so
  ``sigma = s0 / sqrt(R^2 - 1)``.  The median over the strongest edges is taken.  The result is the
  blur beyond an ideal pixel-integrated (box-filtered) edge, which is what the renderer produces, so it
  can be applied to the rendered object as is (a calibration measured on synthetic edges removes the
  finite-difference bias; see ``benchmarks/bench_render_camera_effects.py``).

Application (:func:`apply_to_object`): the object's premultiplied radiance and alpha are blurred with
the estimated Gaussian, and after compositing, Gaussian noise of the estimated std (less the 8-bit
quantisation noise the render already has) is added where the object covers the image.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from ..core import InputError

NOISE_MASK = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
REBLUR_SIGMA_PX = 1.0
QUANT_NOISE = 1.0 / (255.0 * np.sqrt(12.0))  # std of 8-bit rounding in LDR units
# sigma_est^2 = sigma_true^2 + BLUR_BIAS_PX^2 on ideal box-filtered edges (finite differences); measured.
BLUR_BIAS_PX = 0.82
MIN_EDGE_PIXELS = 50


@dataclass(frozen=True)
class CameraEffects:
    """Blur and noise of an image.

    Attributes:
        blur_sigma_px: std (pixels) of the Gaussian blur beyond ideal pixel integration; 0 = sharp.
        noise_sigma: std of the noise in LDR units (1.0 = full scale), 8-bit quantisation included.
        edge_pixels: how many edge pixels the blur estimate used (0: no edges, blur_sigma_px = 0).
    """

    blur_sigma_px: float
    noise_sigma: float
    edge_pixels: int = 0


def _check(image_rgb: np.ndarray) -> np.ndarray:
    img = np.asarray(image_rgb)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image: expected an (H, W, 3) uint8 RGB array, got {img.shape} {img.dtype}")
    return img.astype(np.float32) / 255.0


def _noise_sigma_channel(channel: np.ndarray, mask: np.ndarray | None = None, near_edge: np.ndarray | None = None,
                         edges_out: list | None = None) -> float:
    """Noise std of one (H, W) float channel: MAD of the Laplacian-difference response off edges and clipping.

    ``edges_out``: receives (the first estimate, the pixels near edges found with it) when ``near_edge`` is None."""
    h = cv2.filter2D(channel, cv2.CV_32F, NOISE_MASK, borderType=cv2.BORDER_REFLECT)
    np.abs(h, out=h)
    if near_edge is None:
        first = 1.4826 * float(np.median(h)) / 6.0
        near_edge = _near_edges(channel, first)
        if edges_out is not None:
            edges_out.append((first, near_edge))
    c8 = np.round(channel * 255.0)
    clipped = cv2.dilate(((c8 <= 1) | (c8 >= 254)).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    keep = ~near_edge & ~clipped
    if mask is not None:
        keep &= mask
    keep[:1] = keep[-1:] = False
    keep[:, :1] = keep[:, -1:] = False
    if keep.sum() < 100:
        keep = np.ones_like(keep) if mask is None else mask.copy()
    return 1.4826 * float(np.median(h[keep], overwrite_input=True)) / 6.0


def _near_edges(gray: np.ndarray, noise_sigma: float) -> np.ndarray:
    """(H, W) bool: pixels within 2 of a Canny edge (:func:`_edges`)."""
    return cv2.dilate(_edges(gray, noise_sigma).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0


def _canny_high(noise_sigma: float) -> float:
    """Canny's high threshold (8-bit levels) for an image of noise std ``noise_sigma``: well above the noise."""
    return max(30.0, 255.0 * 3.46 * 4.0 * noise_sigma)  # Canny's Sobel has noise gain sqrt(12) = 3.46


def _edges(gray: np.ndarray, noise_sigma: float, smooth_px: float = 0.0, smoothed: np.ndarray | None = None) -> np.ndarray:
    """Canny edges (bool) with thresholds well above the noise (on an 8-bit copy, optionally pre-smoothed;
    ``smoothed``: ``gray`` already blurred by ``smooth_px``)."""
    if smooth_px > 0:
        gray = _reblurred(gray, smooth_px) if smoothed is None else smoothed
        noise_sigma = noise_sigma / (2.0 * np.sqrt(np.pi) * smooth_px)  # white noise after a Gaussian
    g8 = np.clip(np.round(gray * 255.0), 0, 255).astype(np.uint8)
    hi = _canny_high(noise_sigma)
    return cv2.Canny(g8, hi / 2.0, hi, L2gradient=True) > 0


def _reblurred(gray: np.ndarray, sigma_px: float) -> np.ndarray:
    return cv2.GaussianBlur(gray, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)


def _gray(img: np.ndarray) -> np.ndarray:
    """(H, W) float32 luma of an (H, W, 3) float32 image."""
    return img @ np.array([0.299, 0.587, 0.114], np.float32)


def estimate_noise_sigma(image_rgb: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Noise std (LDR units), the mean of the three channels', of an (H, W, 3) uint8 image.

    ``mask`` (H, W) bool restricts the estimate to some pixels (e.g. an inserted object).
    """
    img = _check(image_rgb)
    return _noise_sigma(img, _gray(img), mask)


def _noise_sigma(img: np.ndarray, gray: np.ndarray, mask: np.ndarray | None = None) -> float:
    """:func:`estimate_noise_sigma` of ``img`` (H, W, 3) float32 (LDR) and its luma ``gray`` (H, W)."""
    found: list[tuple[float, np.ndarray]] = []
    sigma_gray = _noise_sigma_channel(gray, mask, edges_out=found)
    first, near_edge = found[0]
    if _canny_high(sigma_gray) != _canny_high(first):  # else the same thresholds: the same edges
        near_edge = _near_edges(gray, sigma_gray)
    return float(np.mean([_noise_sigma_channel(np.ascontiguousarray(img[..., c]), mask, near_edge) for c in range(3)]))


def _grad(img: np.ndarray) -> np.ndarray:
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT) / 8.0
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REFLECT) / 8.0
    return gx * gx + gy * gy


@functools.cache
def _noise_gain_sq() -> tuple[float, float]:
    """E|grad|^2 per unit noise variance of white noise, without and with the re-blur (measured on a delta)."""
    delta = np.zeros((41, 41), np.float32)
    delta[20, 20] = 1.0
    g0 = float(_grad(delta).sum())
    g1 = float(_grad(cv2.GaussianBlur(delta, (0, 0), REBLUR_SIGMA_PX)).sum())
    return g0, g1


def estimate_blur_sigma(image_rgb: np.ndarray, noise_sigma: float | None = None,
                        mask: np.ndarray | None = None) -> tuple[float, int]:
    """Gaussian blur std (pixels, beyond ideal pixel integration) of an (H, W, 3) uint8 image, and the
    number of edge pixels used; (0.0, n) when fewer than ``MIN_EDGE_PIXELS`` edges are found.

    Gradient magnitudes are corrected for the noise (``E|grad(I + n)|^2 = |grad I|^2 + k sigma^2``) and
    only edges whose re-blurred gradient stands far above the noise are used.  ``mask`` (H, W) bool
    restricts the edges used.
    """
    return _blur_sigma(_gray(_check(image_rgb)), noise_sigma, mask)


def _blur_sigma(gray: np.ndarray, noise_sigma: float | None = None,
                mask: np.ndarray | None = None) -> tuple[float, int]:
    """:func:`estimate_blur_sigma` of the luma ``gray`` (H, W) float32 (LDR) of an image."""
    sigma_n = _noise_sigma_channel(gray) if noise_sigma is None else float(noise_sigma) * 0.668  # grey of 3 channels
    reblurred = _reblurred(gray, REBLUR_SIGMA_PX)
    edges = _edges(gray, sigma_n, smooth_px=REBLUR_SIGMA_PX, smoothed=reblurred)
    if mask is not None:
        edges &= mask
    edges[:4] = edges[-4:] = False
    edges[:, :4] = edges[:, -4:] = False
    ys, xs = np.nonzero(edges)
    if len(ys) < MIN_EDGE_PIXELS:
        return 0.0, int(len(ys))
    k0, k1 = _noise_gain_sq()
    g0 = _grad(gray)[ys, xs] - k0 * sigma_n**2
    g1 = _grad(reblurred)[ys, xs] - k1 * sigma_n**2
    snr_ok = g1 > (6.0 * sigma_n) ** 2 * k0  # the re-blurred edge is far above the unblurred noise gradient
    a, b = g0[snr_ok], g1[snr_ok]
    if len(a) < MIN_EDGE_PIXELS:
        return 0.0, int(len(a))
    strong = b >= np.percentile(b, 50)  # the strongest half
    R2 = a[strong] / np.maximum(b[strong], 1e-12)
    valid = R2 > 1.0 + 1e-3
    if valid.sum() < MIN_EDGE_PIXELS // 2:
        return 0.0, int(valid.sum())
    est = float(np.median(REBLUR_SIGMA_PX / np.sqrt(R2[valid] - 1.0)))
    return float(np.sqrt(max(est * est - BLUR_BIAS_PX**2, 0.0))), int(valid.sum())


def estimate_camera_effects(image_rgb: np.ndarray) -> CameraEffects:
    """Blur and noise of an (H, W, 3) uint8 image (see the module docstring)."""
    img = _check(image_rgb)
    gray = _gray(img)
    noise = _noise_sigma(img, gray)
    blur, n = _blur_sigma(gray, noise)
    return CameraEffects(blur_sigma_px=blur, noise_sigma=noise, edge_pixels=n)


def blur_object_layer(radiance_premult: np.ndarray, alpha: np.ndarray, sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Blur premultiplied radiance (h, w, 3) and alpha (h, w) with the same Gaussian (std ``sigma_px``)."""
    if sigma_px <= 0.05:
        return radiance_premult, alpha
    blur = lambda a: cv2.GaussianBlur(np.ascontiguousarray(a, dtype=np.float32), (0, 0), sigma_px,  # noqa: E731
                                      borderType=cv2.BORDER_CONSTANT)
    return blur(radiance_premult), np.clip(blur(alpha), 0.0, 1.0)


NOISE_CHUNK_PX = 65536  # pixels per noise draw of add_object_noise (~1.5 MB of float64 noise)


def add_object_noise(image_rgb: np.ndarray, alpha: np.ndarray, noise_sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Add Gaussian noise (LDR std ``noise_sigma`` less 8-bit quantisation) where the object covers the image.

    The noise is drawn in row chunks of ~:data:`NOISE_CHUNK_PX` pixels, in order: the same random stream and
    the same bytes as one (h, w, 3) float64 draw (~50 MB for a near object's whole-frame box), with chunks
    where ``alpha`` is 0 left as they are (adding 0 noise does not change an 8-bit level).

    Args:
        image_rgb: (h, w, 3) uint8 composited image (a box of it).
        alpha: (h, w) object alpha in [0, 1]; the noise is weighted by it.
    """
    extra = float(np.sqrt(max(noise_sigma**2 - QUANT_NOISE**2, 0.0)))
    if extra <= 0 or not np.any(alpha > 0):
        return image_rgb
    h, w = image_rgb.shape[:2]
    out = image_rgb.copy()
    rows = max(1, NOISE_CHUNK_PX // max(w, 1))
    for y0 in range(0, h, rows):
        sl = slice(y0, min(y0 + rows, h))
        draw = rng.normal(0.0, extra, size=(sl.stop - y0, w, 3))  # drawn whatever alpha: the stream stays
        a = alpha[sl]
        if not np.any(a > 0):
            continue
        noise = draw.astype(np.float32) * a[..., None]
        del draw
        out[sl] = np.clip(np.round((image_rgb[sl].astype(np.float32) / 255.0 + noise) * 255.0), 0, 255)
    return out
