"""The image predictor's input: a low-res view, its heading-frame pixel rays, LDR quantisation.

Shared by inference (:mod:`.predict`) and training (:mod:`streetaug.augment.training`). Pixel centres at
integer coordinates; rays are unit vectors in the camera's heading frame (z up, see :mod:`.dome`).
"""

from __future__ import annotations

import cv2
import numpy as np

from ...core import PinholeCamera, hdr_to_ldr, scale_intrinsics

VIEW_SIZE = (96, 160)  # (h, w) of the image predictor's input


def quantize_ldr(hdr: np.ndarray) -> np.ndarray:
    """Linear HDR -> LDR float32 in [0, 1] through the contract's response, rounded to 8 bits."""
    return (np.round(hdr_to_ldr(hdr) * 255.0) / 255.0).astype(np.float32)


def view_rays(K: np.ndarray, R_heading_from_cam: np.ndarray, height: int, width: int) -> np.ndarray:
    """(3, height, width) float32 unit heading-frame rays of the pixel centres of an image with intrinsics K."""
    rays = PinholeCamera(K, width, height).rays().reshape(-1, 3) @ np.asarray(R_heading_from_cam).T
    return np.ascontiguousarray(rays.reshape(height, width, 3).transpose(2, 0, 1), dtype=np.float32)


def resize_view(image_rgb: np.ndarray, K: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Image resized to (height, width) (area filter) and its intrinsics (pixel centres at integers)."""
    H0, W0 = image_rgb.shape[:2]
    small = cv2.resize(np.ascontiguousarray(image_rgb), (width, height), interpolation=cv2.INTER_AREA)
    return small, scale_intrinsics(K, width / W0, height / H0)
