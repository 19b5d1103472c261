"""Relative exposure of a sample's cameras, from the LiDAR points two cameras both see.

nuScenes cameras each run their own auto-exposure: the same surface can be several times brighter in
one camera than in its neighbour (real sample, scene-0061: CAM_FRONT_LEFT records the truck and the
building that CAM_FRONT also sees ~7x brighter in linear radiance). Lighting shared by a sample's cameras
is on the reference camera's scale, so each camera's ratio converts it to that camera's image units.

A pair of cameras is calibrated by the LiDAR points visible in both (nearest LiDAR return at their
pixel in both images, neither pixel clipped nor black): the ratio is the median of their linear
luminance ratios. Ratios chain along overlapping neighbours (the nuScenes ring FRONT - FRONT_LEFT -
BACK_LEFT - BACK - ...), over the pairs with most shared points. A camera with no chain to the
reference keeps ratio 1, and the report says so.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ...datasets.sample import CameraView
from ..core import hdr_to_ldr, ldr_uint8_to_hdr, luminance, project_points, transform_points

MIN_SHARED_POINTS = 40  # fewer shared points than this do not calibrate a pair
Z_BUFFER_CELL_PX = 8  # visibility test: nearest LiDAR return within cells of this size
Z_BUFFER_SLACK = 1.03  # a point is visible when within 3 % of the nearest return of its cell
LDR_VALID = (8, 247)  # pixels outside (black, clipped) carry no ratio


def visible_lidar_pixels(view: CameraView, points_global: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) of LiDAR points (N, 3, global) in ``view`` and whether each is visible there.

    Visible: in front of the camera, inside the image, and the nearest LiDAR return of its
    ``Z_BUFFER_CELL_PX`` cell (within ``Z_BUFFER_SLACK``), i.e. not hidden behind another surface.
    """
    H, W = np.asarray(view.image).shape[:2]
    points_cam = transform_points(view.T_cam_from_global, points_global)
    uv, depth = project_points(view.K, points_cam)
    inside = (depth > 0.5) & np.all(np.isfinite(uv), axis=1)
    inside &= (uv[:, 0] >= 0) & (uv[:, 0] < W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] < H - 1)
    cells_x = W // Z_BUFFER_CELL_PX + 1
    cell = np.zeros(len(uv), np.int64)
    cell[inside] = (uv[inside, 1] // Z_BUFFER_CELL_PX).astype(np.int64) * cells_x + (
        uv[inside, 0] // Z_BUFFER_CELL_PX).astype(np.int64)
    nearest = np.full((H // Z_BUFFER_CELL_PX + 1) * cells_x, np.inf)
    np.minimum.at(nearest, cell[inside], depth[inside])
    visible = inside & (depth <= nearest[cell] * Z_BUFFER_SLACK)
    return uv, visible


def lidar_luminance(view: CameraView, points_global: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear luminance (N,) of ``view``'s pixel (nearest) under each LiDAR point, and whether it is usable:
    the point is visible there (:func:`visible_lidar_pixels`) and its pixel neither black nor clipped."""
    uv, visible = visible_lidar_pixels(view, points_global)
    lum = np.zeros(len(uv))
    idx = np.flatnonzero(visible)
    px = np.round(uv[idx]).astype(np.int64)
    ldr = np.asarray(view.image)[px[:, 1], px[:, 0]]
    lum[idx] = luminance(ldr_uint8_to_hdr(ldr[None])[0])
    usable = np.zeros(len(uv), bool)
    usable[idx] = (ldr.max(axis=1) <= LDR_VALID[1]) & (ldr.min(axis=1) >= LDR_VALID[0])
    return lum, usable & (lum > 0)


def pair_ratio(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[float, int]:
    """Exposure of camera b relative to camera a (b's image units per a's) from their :func:`lidar_luminance`,
    and the number of shared points it rests on."""
    ok = a[1] & b[1]
    n = int(np.count_nonzero(ok))
    if n < MIN_SHARED_POINTS:
        return 1.0, n
    return float(np.exp(np.median(np.log(b[0][ok]) - np.log(a[0][ok])))), n


def exposure_ratios(views: Sequence[CameraView], points_global: np.ndarray | None) -> tuple[dict[str, float], dict]:
    """Channel -> image units per reference (``views[0]``) unit, and a report of how each was found.

    Without LiDAR every ratio is 1 (one exposure assumed).
    """
    channels = [v.channel for v in views]
    ratios = {c: 1.0 for c in channels}
    if points_global is None or len(views) < 2 or len(points_global) == 0:
        return ratios, {"method": "assumed equal (no LiDAR)" if points_global is None else "single view"}
    samples = [lidar_luminance(v, points_global) for v in views]  # each camera once
    pairs = {(i, j): pair_ratio(samples[i], samples[j]) for i in range(len(views)) for j in range(i + 1, len(views))}
    # Grow from the reference along the best-supported pair first (a maximum spanning tree).
    known = {0: 1.0}
    how = {channels[0]: "reference"}
    while True:
        best = None
        for (i, j), (ratio, n) in pairs.items():
            if n >= MIN_SHARED_POINTS and ((i in known) != (j in known)) and (best is None or n > best[2]):
                best = (i, j, n, ratio)
        if best is None:
            break
        i, j, n, ratio = best
        if i in known:
            known[j] = known[i] * ratio
            how[channels[j]] = f"{n} LiDAR points shared with {channels[i]}"
        else:
            known[i] = known[j] / ratio
            how[channels[i]] = f"{n} LiDAR points shared with {channels[j]}"
    for k, value in known.items():
        ratios[channels[k]] = float(value)
    for c in channels:
        how.setdefault(c, "no overlap with a calibrated camera: reference exposure assumed")
    return ratios, {"method": "shared LiDAR points", "per_camera": how,
                    "pairs": {f"{channels[i]}/{channels[j]}": {"ratio": r, "points": n}
                              for (i, j), (r, n) in pairs.items()}}


def auto_exposure_ev(radiance: np.ndarray, target_mean_ldr: float, ev_range: tuple[float, float] = (-16.0, 16.0),
                     steps: int = 40) -> float:
    """EV at which ``radiance`` (linear, any shape (..., 3)) records with mean LDR value ``target_mean_ldr``.

    A model of a camera's auto-exposure for an image it has not taken (a novel view): nuScenes cameras
    meter each frame to a similar mean level, so a camera whose exposure is unknown is taken to record at
    the mean LDR level of the rig's other cameras. Bisection on the contract's response (monotone in EV);
    an all-black radiance returns the upper end of ``ev_range``.
    """
    if not 0.0 < target_mean_ldr < 1.0:
        raise ValueError(f"target_mean_ldr must be in (0, 1), got {target_mean_ldr}")
    lo, hi = ev_range
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if float(hdr_to_ldr(radiance, mid).mean()) < target_mean_ldr:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
