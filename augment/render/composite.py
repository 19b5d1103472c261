"""Occlusion by scene depth and the composite ``I_edit = M I_obj + (1 - M) I S`` in linear HDR.

Only pixels where ``M > 0`` or ``S < 1`` are converted and rewritten; every other byte of the
input image is returned unchanged.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..core import hdr_to_ldr_uint8, ldr_uint8_to_hdr

OCCLUSION_SOFT_M = 0.10  # width of the soft depth test at 0 m ...
OCCLUSION_SOFT_PER_M = 0.01  # ... growing 1 cm per metre of depth (LiDAR / completion error grows)


def depth_visibility(object_depth_m: np.ndarray, scene_depth_m: np.ndarray) -> np.ndarray:
    """Soft depth test (h, w) float32 in [0, 1]: 1 where the object is in front of the scene.

    The object stays fully visible while it is no more than 0 m behind the scene surface and fades to
    0 over ``OCCLUSION_SOFT_M + OCCLUSION_SOFT_PER_M * depth`` behind it (so a tyre touching the
    ground it stands on is not cut), then a 3 x 3 box blur softens the boundary by a pixel.
    """
    obj = np.asarray(object_depth_m, dtype=np.float64)
    scene = np.asarray(scene_depth_m, dtype=np.float64)
    scene = np.where(np.isfinite(scene) & (scene > 0), scene, np.inf)
    soft = OCCLUSION_SOFT_M + OCCLUSION_SOFT_PER_M * np.where(np.isfinite(obj), obj, 0.0)
    with np.errstate(invalid="ignore"):
        vis = np.clip((scene - obj) / soft + 1.0, 0.0, 1.0)
    vis = np.where(np.isfinite(obj), np.where(np.isinf(scene), 1.0, vis), 0.0).astype(np.float32)
    if vis.shape[0] >= 2 and vis.shape[1] >= 2 and (vis < 1).any():
        blurred = cv2.blur(vis, (3, 3), borderType=cv2.BORDER_REPLICATE)
        vis = np.where(np.isfinite(obj), blurred, 0.0).astype(np.float32)
    return vis


def composite(image_rgb: np.ndarray, radiance_premult: np.ndarray, mask: np.ndarray, visibility: np.ndarray,
              ratio_rgb: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Composite an object and its shadow into a uint8 image.

    Args:
        image_rgb: (H, W, 3) uint8 input (LDR, the contract's camera response).
        radiance_premult: (H, W, 3) float32 object radiance x coverage (linear HDR).
        mask: (H, W) float32 final alpha M = coverage x visibility.
        visibility: (H, W) float32 depth-test visibility (M I_obj = visibility x radiance_premult).
        ratio_rgb: (H, W, 3) float32 shadow ratio S (1 = unchanged).
        ev: exposure of the camera response.

    Returns:
        (H, W, 3) uint8; pixels with M == 0 and S == 1 are byte-identical to ``image_rgb``.
    """
    out = image_rgb.copy()
    touched = (mask > 0) | (ratio_rgb < 1).any(axis=2)
    if not touched.any():
        return out
    ys, xs = np.nonzero(touched)
    I = ldr_uint8_to_hdr(np.arange(256, dtype=np.uint8), ev).astype(np.float64)[image_rgb[ys, xs]]  # 256-entry table
    M = mask[ys, xs].astype(np.float64)[:, None]
    obj = visibility[ys, xs].astype(np.float64)[:, None] * radiance_premult[ys, xs]
    edit = obj + (1.0 - M) * I * ratio_rgb[ys, xs]
    out[ys, xs] = hdr_to_ldr_uint8(edit, ev)
    return out
