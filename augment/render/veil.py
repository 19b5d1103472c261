"""The photo's veil: the light that haze and the lens's veiling glare add in front of everything, rising with
distance, measured from the image and its depth map, and applied to an inserted object.

Through air a camera records ``I = J t(d) + A (1 - t(d))`` at distance d (Koschmieder: scene radiance J,
transmission t, airlight A), plus the lens's veiling glare, a near-uniform offset; both lift the blacks and
lower the contrast of what is 10-40 m away.  The veil is measured with the dark channel prior (He et al. 2009):
at any distance some things are nearly black (tyres, the ground under cars, foliage), so there the image
records only the veil.  Per depth bin, the :data:`FLOOR_PERCENTILE` percentile of the dark channel (the
minimum over RGB and a patch, linear) of the pixels at that depth is an upper bound on the veil at that
depth (a bin without dark things only bounds it from above); the veil can only grow with distance, so the
bins are made non-decreasing by a running minimum from the far end.  Only a bin whose dark things are markedly
darker than its typical pixel (its floor at most :data:`EVIDENCE_RATIO` of its median luminance) measures the
veil; the veil is capped at the largest floor of such bins (a flat grey road or wall bounds it but does not show
it: without any such bin there is no veil), and at :data:`MAX_VEIL_FRACTION` of the image's median luminance
(a scene with nothing dark is not a fog).

The airlight colour is the mean colour of the brightest dark-channel pixels (He et al.: the haze-opaque sky);
the veil of colour channel c at depth d is ``A_c (1 - t(d))`` with ``1 - t(d) = floor(d) / min_c A_c``.

Radiances are linear (the contract's inverse camera response at exposure ``ev``); depth is camera-z in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..core import ldr_uint8_to_hdr, luminance

DEPTH_EDGES_M = (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 70.0, np.inf)
REDUCE_PX = 4  # the dark channel is taken on 4 x 4 blocks (min-pooled: the minimum commutes with the response)
PATCH_BLOCKS = 3  # ... and eroded over 3 x 3 blocks (a 12-px patch at full resolution)
FLOOR_PERCENTILE = 1.0
MIN_BIN_BLOCKS = 150  # a depth bin with fewer blocks gives no bound
AIRLIGHT_FRACTION = 0.001  # the brightest 0.1 % of the dark channel give the airlight colour
MAX_VEIL_FRACTION = 0.15
EVIDENCE_RATIO = 0.5  # a bin measures the veil when its dark floor is at most this share of its median luminance


@dataclass(frozen=True)
class Veil:
    """The veil of one image.

    Attributes:
        depth_m: (B,) bin centres (metres; the last finite edge x 1.5 for the open last bin).
        floor: (B,) non-decreasing dark-channel level of the veil at those depths (linear radiance).
        airlight_rgb: (3,) linear airlight colour (its minimum channel >= every floor).
    """

    depth_m: np.ndarray
    floor: np.ndarray
    airlight_rgb: np.ndarray

    @classmethod
    def none(cls) -> "Veil":
        """No veil (applying it changes nothing)."""
        return cls(np.array([0.0]), np.array([0.0]), np.ones(3))

    def haze_at(self, depth_m: np.ndarray) -> np.ndarray:
        """(...) ``1 - t``: the veil's share at camera-z ``depth_m`` (...), linear between bin centres, 0 at
        non-finite depth."""
        d = np.asarray(depth_m, np.float64)
        level = np.interp(np.where(np.isfinite(d), d, 0.0), self.depth_m, self.floor)
        return np.where(np.isfinite(d), level / max(float(self.airlight_rgb.min()), 1e-12), 0.0)

    def apply(self, radiance_premult: np.ndarray, coverage: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """(h, w, 3) premultiplied object radiance seen through the veil: ``L t + A (1 - t) coverage``.

        Evaluated only at the object's pixels (coverage or radiance not 0; elsewhere the result is 0): a near
        object's pixel box can be the whole frame, whose float64 temporaries were ~130 MB.

        Args:
            radiance_premult: (h, w, 3) linear radiance x coverage; coverage: (h, w) 0..1;
            depth_m: (h, w) the object's camera-z (inf where none).
        """
        rad = np.asarray(radiance_premult)
        cov = np.asarray(coverage)
        out = np.zeros(rad.shape, np.float32)
        on = (cov > 0) | (rad != 0).any(axis=-1)
        if not on.any():
            return out
        haze = self.haze_at(np.asarray(depth_m)[on])[:, None]
        c = cov[on].astype(np.float64)[:, None]
        out[on] = (rad[on] * (1.0 - haze) + self.airlight_rgb * haze * c).astype(np.float32)
        return out

    def shadow_ratio(self, ratio_rgb: np.ndarray, image_rgb: np.ndarray, depth_m: np.ndarray,
                     ev: float = 0.0) -> np.ndarray:
        """(h, w, 3) shadow ratio acting on the whole pixel such that only the scene behind the veil is shadowed:
        ``I' = (I - V) S + V``, i.e. ``S' = S + (1 - S) min(V / I, 1)``, V the veil at the scene's ``depth_m``.

        Args:
            ratio_rgb: (h, w, 3) shadow ratio S (1 = unchanged); image_rgb: (h, w, 3) uint8 the scene;
            depth_m: (h, w) its camera-z (inf: sky, no veil is kept).
        """
        S = np.asarray(ratio_rgb)
        if not np.any(S < 1.0):
            return ratio_rgb
        on = (S != 1.0).any(axis=-1)  # only where there is a shadow (elsewhere S' = S = 1)
        s = S[on].astype(np.float64)
        V = self.haze_at(np.asarray(depth_m)[on])[:, None] * self.airlight_rgb
        I = ldr_uint8_to_hdr(np.asarray(image_rgb)[on], ev).astype(np.float64)
        share = np.clip(V / np.maximum(I, 1e-9), 0.0, 1.0)
        out = S.astype(np.float32)  # a copy
        out[on] = (s + (1.0 - s) * share).astype(np.float32)
        return out


def dark_channel_blocks(image_rgb: np.ndarray) -> np.ndarray:
    """(H // 4, W // 4) uint8 dark channel: min over RGB, 4 x 4 blocks and a 3 x 3-block patch."""
    H, W = image_rgb.shape[:2]
    h, w = H // REDUCE_PX, W // REDUCE_PX
    m = np.minimum(np.minimum(image_rgb[..., 0], image_rgb[..., 1]), image_rgb[..., 2])
    m = cv2.erode(m, np.ones((REDUCE_PX, REDUCE_PX), np.uint8), anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)
    m = np.ascontiguousarray(m[: h * REDUCE_PX : REDUCE_PX, : w * REDUCE_PX : REDUCE_PX])  # each block's minimum
    return cv2.erode(m, np.ones((PATCH_BLOCKS, PATCH_BLOCKS), np.uint8), borderType=cv2.BORDER_REPLICATE)


def estimate_veil(image_rgb: np.ndarray, depth_m: np.ndarray, ev: float = 0.0) -> Veil:
    """The :class:`Veil` of an (H, W, 3) uint8 image with its (H, W) camera-z depth (inf = sky / unknown)."""
    H, W = image_rgb.shape[:2]
    if H < 4 * REDUCE_PX or W < 4 * REDUCE_PX:
        return Veil.none()
    dark_u8 = dark_channel_blocks(image_rgb)
    h, w = dark_u8.shape
    dark = ldr_uint8_to_hdr(dark_u8, ev)
    c = REDUCE_PX // 2
    depth = np.asarray(depth_m, np.float32)[c : h * REDUCE_PX : REDUCE_PX, c : w * REDUCE_PX : REDUCE_PX]
    edges = np.asarray(DEPTH_EDGES_M)
    centres = 0.5 * (edges[:-1] + np.minimum(edges[1:], 1.5 * edges[-2]))
    lin = ldr_uint8_to_hdr(image_rgb[c::REDUCE_PX, c::REDUCE_PX][:h, :w], ev)
    lum = luminance(lin)
    bound = np.full(len(centres), np.inf)
    evidence = np.zeros(len(centres), dtype=bool)
    for k in range(len(centres)):
        sel = (depth >= edges[k]) & (depth < edges[k + 1])
        if sel.sum() >= MIN_BIN_BLOCKS:
            bound[k] = np.percentile(dark[sel], FLOOR_PERCENTILE)
            evidence[k] = bound[k] <= EVIDENCE_RATIO * float(np.median(lum[sel]))
    if not evidence.any():
        return Veil.none()
    floor = np.minimum.accumulate(bound[::-1])[::-1]  # non-decreasing with depth
    floor = np.where(np.isfinite(floor), floor, floor[np.isfinite(floor)].max())
    floor = np.minimum(floor, min(float(floor[evidence].max()), MAX_VEIL_FRACTION * float(np.median(lum))))
    top = dark_u8 >= np.quantile(dark_u8, 1.0 - AIRLIGHT_FRACTION)
    airlight = lin[top].mean(axis=0).astype(np.float64)
    airlight = np.maximum(airlight, max(float(floor.max()), 1e-6))
    return Veil(centres, floor, airlight)
