"""Parts of the camera's look beyond the measured blur and noise (:mod:`.camera_effects`): motion blur
from the object's image motion during the exposure, and the source image's JPEG quality.

* **Motion blur**: a point at ``P`` (camera frame, metres) moving at ``v`` (m/s, relative to the camera,
  camera frame) moves in the image at ``du/dt = fx (vx / Z - X vz / Z^2)``, ``dv/dt = fy (vy / Z - Y vz / Z^2)``;
  over an exposure ``t`` (seconds, centred on the timestamp) the object is smeared along a line of that
  length (:func:`motion_kernel`).  nuScenes does not record the exposure: ``DAY_EXPOSURE_S`` /
  ``NIGHT_EXPOSURE_S`` are documented assumptions, to be overridden when known.
* **JPEG quality**: from the luminance quantisation table of the source file (IJG scaling, the table
  libjpeg / OpenCV write), :func:`jpeg_quality_from_file`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

DAY_EXPOSURE_S = 0.002  # assumption: sunny daylight auto exposure (not recorded by nuScenes)
NIGHT_EXPOSURE_S = 0.020  # assumption: the usual 20 ms cap of automotive auto exposure
MIN_MOTION_PX = 0.5  # shorter smears are below the measured blur's resolution and are not applied
MAX_MOTION_PX = 64.0  # longer smears are cut to this (a car 2 m away passing at 30 m/s in 2 ms: ~40 px)
MIN_MOTION_DEPTH_M = 0.5  # a centre nearer the camera plane has no meaningful image motion (none applied)

# IJG base luminance table (ITU T.81 Annex K), row-major (natural) order
IJG_LUMA = np.array([
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99], np.float64)


def image_motion_px(K: np.ndarray, point_cam: np.ndarray, velocity_cam_mps: np.ndarray, exposure_s: float) -> np.ndarray:
    """(2,) image displacement (pixels, u right / v down) of ``point_cam`` (3,) moving at ``velocity_cam_mps``
    (3,) relative to the camera during ``exposure_s`` seconds (zero behind or within ``MIN_MOTION_DEPTH_M`` of
    the camera plane, e.g. an object beside the camera whose shadow alone reaches the image)."""
    X, Y, Z = np.asarray(point_cam, np.float64)
    vx, vy, vz = np.asarray(velocity_cam_mps, np.float64)
    if Z <= MIN_MOTION_DEPTH_M or not np.all(np.isfinite([X, Y, vx, vy, vz])):
        return np.zeros(2)
    du = K[0, 0] * (vx / Z - X * vz / Z**2)
    dv = K[1, 1] * (vy / Z - Y * vz / Z**2)
    return np.array([du, dv]) * float(exposure_s)


def motion_kernel(motion_px: np.ndarray, samples_per_px: int = 8) -> np.ndarray:
    """(k, k) float32 normalised line kernel of a smear ``motion_px`` (2,) (u, v pixels) centred on the
    pixel (the exposure is centred on the timestamp); a 1 x 1 identity below ``MIN_MOTION_PX``; smears longer
    than ``MAX_MOTION_PX`` are cut to it (the kernel stays small whatever the input)."""
    m = np.asarray(motion_px, np.float64)
    length = float(np.hypot(*m))
    if not np.isfinite(length) or length < MIN_MOTION_PX:
        return np.ones((1, 1), np.float32)
    if length > MAX_MOTION_PX:
        m, length = m * (MAX_MOTION_PX / length), MAX_MOTION_PX
    r = int(np.ceil(length / 2.0)) + 1
    k = np.zeros((2 * r + 1, 2 * r + 1), np.float64)
    t = np.linspace(-0.5, 0.5, max(int(np.ceil(length * samples_per_px)), 2) + 1)
    x, y = r + t * m[0], r + t * m[1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), w)  # bilinear splat of the segment's samples
    return (k / k.sum()).astype(np.float32)


def ijg_table(quality: int) -> np.ndarray:
    """(64,) the IJG luminance quantisation table at ``quality`` 1..100 (natural order)."""
    q = int(np.clip(quality, 1, 100))
    scale = 5000.0 / q if q < 50 else 200.0 - 2.0 * q
    return np.clip(np.floor((IJG_LUMA * scale + 50.0) / 100.0), 1, 255)


def jpeg_quality_from_table(luma_table: np.ndarray) -> int:
    """The IJG quality 1..100 whose luminance table (64,) natural order is nearest (in log steps) to ``luma_table``."""
    return _jpeg_quality_of_table(tuple(float(x) for x in np.asarray(luma_table, np.float64).ravel()))


@lru_cache(maxsize=64)
def _jpeg_quality_of_table(table: tuple[float, ...]) -> int:
    """:func:`jpeg_quality_from_table` of a table's values (kept: a dataset's images share a few tables)."""
    t = np.log(np.maximum(np.asarray(table, np.float64), 1.0))
    errs = [float(np.abs(np.log(ijg_table(q)) - t).sum()) for q in range(1, 101)]
    return int(np.argmin(errs)) + 1


def jpeg_quality_from_file(path: str | Path) -> int | None:
    """The JPEG quality of an image file from its luminance quantisation table (None: not a JPEG)."""
    from PIL import Image

    with Image.open(path) as im:
        tables = getattr(im, "quantization", None)
        if im.format != "JPEG" or not tables:
            return None
        return jpeg_quality_from_table(np.array(tables[0], np.float64))


def jpeg_round_trip(image_rgb: np.ndarray, touched: np.ndarray, quality: int) -> np.ndarray:
    """``image_rgb`` (H, W, 3) uint8 with the 16 x 16 JPEG blocks (4:2:0 MCUs, on the image's own grid) that
    ``touched`` (H, W) bool reaches re-encoded at ``quality``, so an inserted object gets the compression
    artefacts of the photo around it; every other pixel is unchanged."""
    import cv2

    if not touched.any():
        return image_rgb
    H, W = touched.shape
    ys, xs = np.nonzero(touched)
    y0, x0 = (ys.min() // 16) * 16, (xs.min() // 16) * 16
    y1, x1 = min(-(-(ys.max() + 1) // 16) * 16, H), min(-(-(xs.max() + 1) // 16) * 16, W)
    crop = np.ascontiguousarray(image_rgb[y0:y1, x0:x1, ::-1])
    ok, buf = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    t = touched[y0:y1, x0:x1]
    hb, wb = -(-t.shape[0] // 16), -(-t.shape[1] // 16)
    padded = np.zeros((hb * 16, wb * 16), bool)
    padded[: t.shape[0], : t.shape[1]] = t
    blocks = padded.reshape(hb, 16, wb, 16).any(axis=(1, 3))
    replace = np.repeat(np.repeat(blocks, 16, 0), 16, 1)[: t.shape[0], : t.shape[1]]
    out = image_rgb.copy()
    out[y0:y1, x0:x1][replace] = decoded[replace]
    return out


def jpeg_noise_survival(quality: int, sigma_ldr: float) -> float:
    """Fraction (0..1] of white Gaussian noise std ``sigma_ldr`` (LDR units) left after a JPEG round trip at
    ``quality``: the photo's noise was measured after its own compression, so noise added to an inserted
    object that is then re-encoded (:func:`jpeg_round_trip`) must be larger by 1 / this.  Measured once per
    (quality, sigma on a 1/255 grid) on a seeded 128 x 128 mid-grey patch."""
    return _jpeg_noise_survival(int(np.clip(quality, 1, 100)), max(int(round(float(sigma_ldr) * 255.0 * 4)), 1))


@lru_cache(maxsize=512)
def _jpeg_noise_survival(quality: int, sigma_quarter_levels: int) -> float:
    import cv2

    sigma = sigma_quarter_levels / 4.0
    rng = np.random.default_rng(0)
    patch = np.clip(np.round(128.0 + rng.normal(0.0, sigma, (128, 128, 3))), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", patch, [cv2.IMWRITE_JPEG_QUALITY, quality])
    out = cv2.imdecode(buf, cv2.IMREAD_COLOR).astype(np.float64)
    before, after = patch.astype(np.float64).std(), out.std()
    return float(np.clip(after / max(before, 1e-9), 0.25, 1.0))


# ----------------------------------------------------------------------------- neutral axis (tone-dependent cast)
# A camera's neutral axis: the LDR colour it records for neutral (grey) surfaces at each level. The contract's
# response is the same curve for R, G and B, so a neutral rendered surface comes out neutral at every level;
# real cameras are not: on scene-0916 (nuScenes, overcast) near-neutral pixels of the road, the cars and
# the buildings read G 2-3.5 DN above R and B at every level from 8 to 96 (an additive offset, not a
# multiplicative light colour: their ratio G/R falls from 1.24 at level 12 to 1.03 at level 80), none at
# 128-192 (the camera's white balance point): dark real grey cars have CIELAB a* -1 to -2, rendered ones 0
# (benchmarks/diag_colour_cast.py). The estimate below measures that offset per level band in the image
# itself; :func:`apply_neutral_axis` adds it to the object's pixels (weighted by its alpha).
NEUTRAL_BIN_EDGES = (0.0, 8.0, 16.0, 32.0, 64.0, 96.0, 128.0, 192.0, 256.0)  # LDR level bands (mean of R, G, B)
NEUTRAL_SPREAD = (0.06, 4.0)  # near-neutral: max - min channel <= a x level + b (DN)
NEUTRAL_MIN_PX = 100  # a band with fewer near-neutral pixels (after subsampling) has no offset
NEUTRAL_PRIOR_PX = 400  # a band's offset is shrunk towards 0 by n / (n + this)
NEUTRAL_MAX_DN = 8.0  # offsets are clipped to +- this (a larger one is a tinted scene, not the camera)
# Only the red-green part (CIELAB a*) is the camera's: the blue-yellow part (b*) of near-neutral pixels is the
# road's own tint (scene-0916's asphalt reads b* +2.4..+2.9 at L 20-50 where its real cars read b* 0, as the
# rendered ones do; both real read a* -1..-1.3 there). The offset is G - R, carried along the sRGB direction
# that moves a* alone (L* and b* kept; linearised at grey, the same from sRGB 0.1 to 0.5): G - R of 1 DN moves
# a* by about -0.5 at L 40. ``(-0.5, 0.5, 0)`` instead moved b* by +0.29 per -1 of a* (realism b_mean gap
# +0.60 -> +0.69 with it).
GREEN_AXIS = np.array([-0.770, 0.230, -0.015])  # R, G, B offset (DN) per DN of G - R


@dataclass(frozen=True)
class NeutralAxis:
    """The camera's neutral axis in one image: per level band, the LDR offset (DN) of each channel from the
    mean of the three on near-neutral pixels.

    Attributes:
        levels: (B,) the mean LDR level (0..255) of the near-neutral pixels of each band that has enough.
        offsets_dn: (B, 3) R, G, B offset (DN) from the pixel's mean level, shrunk and clipped.
        n_px: (len(NEUTRAL_BIN_EDGES) - 1,) near-neutral pixels counted per band (subsampled), all bands.
    """

    levels: np.ndarray
    offsets_dn: np.ndarray
    n_px: np.ndarray

    def offset_at(self, level: np.ndarray) -> np.ndarray:
        """(N, 3) the offset (DN) at LDR levels (N,) (linear between band levels, constant beyond the ends)."""
        lv = np.asarray(level, dtype=np.float64).reshape(-1)
        return np.stack([np.interp(lv, self.levels, self.offsets_dn[:, c]) for c in range(3)], axis=-1)


def neutral_axis(image_rgb: np.ndarray, step: int = 4) -> NeutralAxis:
    """The neutral axis of an (H, W, 3) uint8 image (every ``step``-th pixel each way): per level band of
    :data:`NEUTRAL_BIN_EDGES` with enough near-neutral pixels (:data:`NEUTRAL_SPREAD`), the median offset of
    each channel from the pixel's mean, its green-magenta part only (:data:`GREEN_AXIS`), shrunk towards 0
    (no cast) with few pixels; bands with too few are left out (the nearest band's offset holds there)."""
    x = np.asarray(image_rgb)[::step, ::step].reshape(-1, 3).astype(np.float32)
    m = x.mean(axis=1)
    a, b = NEUTRAL_SPREAD
    keep = (x.max(axis=1) - x.min(axis=1)) <= a * m + b
    x, m = x[keep], m[keep]
    edges = np.asarray(NEUTRAL_BIN_EDGES)
    n_bins = len(edges) - 1
    levels, offsets, counts = [], [], np.zeros(n_bins, np.int64)
    band = np.clip(np.digitize(m, edges) - 1, 0, n_bins - 1)
    for i in range(n_bins):
        sel = band == i
        n = int(sel.sum())
        counts[i] = n
        if n < NEUTRAL_MIN_PX:
            continue
        off = np.median(x[sel] - m[sel, None], axis=0)
        green = float(off[1] - off[0]) * n / (n + NEUTRAL_PRIOR_PX)
        levels.append(float(m[sel].mean()))
        offsets.append(np.clip(green * GREEN_AXIS, -NEUTRAL_MAX_DN, NEUTRAL_MAX_DN))
    if not levels:
        return NeutralAxis(np.array([128.0]), np.zeros((1, 3)), counts)
    return NeutralAxis(np.array(levels), np.array(offsets), counts)


def apply_neutral_axis(image_rgb: np.ndarray, alpha: np.ndarray, axis: NeutralAxis) -> np.ndarray:
    """``image_rgb`` (H, W, 3) uint8 with the neutral axis's offset at each pixel's level added where ``alpha``
    (H, W) > 0, weighted by it (the object's pixels; the rest stays byte-identical)."""
    out = np.asarray(image_rgb).copy()
    ys, xs = np.nonzero(np.asarray(alpha) > 0)
    if not len(ys):
        return out
    px = out[ys, xs].astype(np.float64)
    off = axis.offset_at(px.mean(axis=1)) * np.asarray(alpha, dtype=np.float64)[ys, xs, None]
    out[ys, xs] = np.clip(np.round(px + off), 0, 255).astype(np.uint8)
    return out
