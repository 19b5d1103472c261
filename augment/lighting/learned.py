"""L1 from the image alone: the learned image -> sky-vector model (:mod:`.skynet`), refined on the visible sky.

Used by the front door (:mod:`.api`) whenever the ephemeris cannot place the sun (no location, no timestamp, a
bare image). The sun is reported (``sun_source="image"``) only when the predictor is confident (visibility
and a tight direction cone); otherwise a diffuse sky, said so. The ground below the horizon is the image's
road (its median radiance); radiance is on the image's scale (contract response, EV 0). The network (and
torch) is imported when an estimate runs, not with this module: the ephemeris levels never need it.
"""

from __future__ import annotations

import time

import numpy as np

from .evidence import ground_evidence, image_sky_mask, prepare_image
from .types import ENVMAP_HEIGHT, ENVMAP_WIDTH, LightingEstimate, json_clean

MIN_SKY_PIXELS = 20  # fewer visible sky pixels: the predicted sky is not refined


def learned_sky_estimate(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray,
                         camera_height_m: float) -> LightingEstimate:
    """L1 of one image from the learned sky model.

    Args:
        image_rgb: (H, W, 3) uint8 RGB (contract response).
        K: (3, 3) intrinsics of ``image_rgb`` (pixel centres at integers).
        up_cam: (3,) unit gravity up, camera frame ((0, -1, 0) for a level camera).
        camera_height_m: camera height above the ground (for the road evidence).
    """
    from .skynet.predict import estimate_sky_light  # deferred: imports torch (~0.7 s)

    t0 = time.perf_counter()
    up_cam = np.asarray(up_cam, dtype=np.float64)
    work = prepare_image(image_rgb, np.asarray(K, dtype=np.float64), up_cam)
    ground = ground_evidence(work, up_cam, camera_height_m)
    mask = image_sky_mask(work)
    refine = mask.sum() >= MIN_SKY_PIXELS
    small = np.clip(np.round(work.ldr * 255.0), 0, 255).astype(np.uint8)
    ground_rgb = None if ground is None else np.full(3, ground["median"])
    light, pred, _ = estimate_sky_light(small, work.K, up_cam, sky_mask=mask if refine else None,
                                        ground_radiance=ground_rgb, height=ENVMAP_HEIGHT, width=ENVMAP_WIDTH)
    total = time.perf_counter() - t0
    source = "image" if pred.confident else "none"
    sun_dir = np.asarray(pred.sun_dir_cam, dtype=np.float64) if pred.confident else None
    reason = (f"L1 without metadata: learned sky predictor ({pred.reason}); "
              + ("sky refined on the visible sky pixels" if refine else "no sky visible: sky not refined"))
    params = {"sun_visibility_raw": float(pred.visibility_raw), "camera_height_m": camera_height_m,
              "up_camera": up_cam.tolist(), "evidence": {"ground": ground, "sky_pixels": int(mask.sum())}}
    return LightingEstimate(light, sun_dir, source, float(pred.sun_visibility) if pred.confident else 0.0, "L1",
                            reason, json_clean(params), {"total": total})
