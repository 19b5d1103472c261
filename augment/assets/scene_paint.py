"""The paint mix of a sample's own cars: inserted cars drawn with the colours the real cars around them have.

A regional colour-popularity table (:mod:`.car_paint`) says what new cars a region buys, not what stands in one
street under one sky: scene-0916 (Singapore, overcast) shows mostly silver and grey cars where the Asia table
draws 48 % white. This module measures the annotated cars of a sample in its images and turns them into a
weighting of the palette's shades, with the regional table as the prior (and the fallback without cars):

1. :func:`paint_band_rgb`: the pixels of a car's paint band, points on the camera-facing vertical faces of its
   box between 30 % and 55 % of its height (doors, wings, the boot lid's edge: below the windows, above the
   tyres) over the middle 70 % of each face, leaving out pixels a nearer box covers; linear radiance through
   the contract's inverse camera response.
2. :func:`band_ratio`: the band's median radiance (3,) over the image's reference level (the median luminance
   of its lower half: ground, kerbs, walls, lit by the same sky); a paint of albedo rho shows about
   ``REFLECTED_RATIO + LIT_RATIO rho`` (:func:`predicted_band_ratio`).
3. :func:`scene_paint_weights`: the shade mix that explains the measured cars best (likelihood per car and shade:
   :func:`car_shade_likelihood`, log-normal in luminance and normal in chromaticity around each shade's
   predicted ratio), with :data:`PRIOR_CARS` cars' worth of the region's table as a Dirichlet prior; EM from a
   start where the region's family shares count only to the power :data:`FAMILY_PRIOR_POWER` (the table itself
   would outvote the measurement, its 48 % white turning a silver car white).

Convention: box frame as nuScenes (x front, y left, z up, origin at the box centre); ``wlh`` = (width along y,
length along x, height along z) in metres; ``T_cam_from_box`` (4, 4) maps box points to the OpenCV camera
frame (x right, y down, z forward); pixel centres at integer coordinates.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..core import box_rect_px, check_shape, ldr_uint8_to_hdr, luminance, project_points
from .car_paint import paint_family, paint_palette, paint_region_for_location

BAND_HEIGHT = (0.30, 0.55)  # paint band, fractions of the box height from its bottom
BAND_SPAN = (0.15, 0.85)  # fractions of each face's horizontal extent
MIN_BAND_PX = 12  # fewer unoccluded band pixels: the car is not measured
MAX_DISTANCE_M = 45.0
# What a paint band shows, as a ratio to the image's reference level (:func:`band_ratio`): the clear coat's
# reflection of the sky and street plus the base coat's diffuse light, ``REFLECTED_RATIO + LIT_RATIO x albedo``.
# Measured on procedural cars rendered into scene-0916 (overcast; ``benchmarks/diag_scene_paint.py``, 80 cars,
# 4 families): black (albedo 0.007) 0.19, grey (0.16) 0.50, silver (0.49) 1.01, white (0.84) 1.87 (medians, 92
# cars); the line through them; rank correlation of ratio and albedo 0.86.
REFLECTED_RATIO = 0.18
LIT_RATIO = 2.0
SIGMA_LOG_LUMINANCE = 0.3  # spread (log) of a paint's band ratio over cars and views (interquartile ~x1.6-1.8)
SIGMA_CHROMATICITY = 0.03  # spread of the ratio's chromaticity (r, g of rgb / sum): white balance, reflections
FAMILY_PRIOR_POWER = 0.25  # a car's prior: the region's family shares to this power (0: every family alike)
PRIOR_CARS = 4.0  # the regional table counts as this many observed cars
EM_ITERATIONS = 30


def _band_points_box(T_cam_from_box: np.ndarray, wlh: np.ndarray, n_along: int = 12, n_up: int = 5) -> np.ndarray:
    """(M, 3) box-frame points on the paint band of the box's vertical faces that face the camera."""
    w, l, h = (float(x) for x in wlh)
    cam_in_box = np.linalg.inv(T_cam_from_box)[:3, 3]
    su = np.linspace(BAND_SPAN[0], BAND_SPAN[1], n_along) - 0.5
    sz = (np.linspace(BAND_HEIGHT[0], BAND_HEIGHT[1], n_up) - 0.5) * h
    U, Z = np.meshgrid(su, sz)
    U, Z = U.ravel(), Z.ravel()
    faces = []
    for axis, half, across in ((0, 0.5 * l, w), (1, 0.5 * w, l)):
        for sign in (1.0, -1.0):
            if sign * cam_in_box[axis] <= half:  # the camera is not in front of this face
                continue
            p = np.zeros((len(U), 3))
            p[:, axis] = sign * half
            p[:, 1 - axis] = U * across
            p[:, 2] = Z
            faces.append(p)
    return np.concatenate(faces) if faces else np.zeros((0, 3))


def paint_band_rgb(image: np.ndarray, K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray,
                   nearer_rects: Sequence[np.ndarray] = ()) -> np.ndarray:
    """Linear radiance (N, 3) of the pixels on a car's paint band (see the module docstring), each pixel once.

    Args:
        image: (H, W, 3) uint8 sRGB-like camera image (the contract's response is inverted).
        K: (3, 3) intrinsics. T_cam_from_box: (4, 4) camera <- box centre. wlh: (3,) box size, metres.
        nearer_rects: (4,) x0, y0, x1, y1 pixel rectangles of nearer objects: band pixels inside them are dropped.

    Returns:
        (N, 3) float64, N = 0 when no band point lands in the image unoccluded.
    """
    check_shape(T_cam_from_box, (4, 4), "T_cam_from_box")
    H, W = image.shape[:2]
    pts = _band_points_box(np.asarray(T_cam_from_box, float), np.asarray(wlh, float))
    if not len(pts):
        return np.zeros((0, 3))
    cam = pts @ T_cam_from_box[:3, :3].T + T_cam_from_box[:3, 3]
    uv, z = project_points(K, cam)
    ok = (z > 0.5) & np.all(np.isfinite(uv), axis=1)
    uv = np.round(uv[ok]).astype(int)
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    uv = uv[ok]
    for r in nearer_rects:
        if np.all(np.isfinite(r)):
            inside = (uv[:, 0] >= r[0]) & (uv[:, 0] <= r[2]) & (uv[:, 1] >= r[1]) & (uv[:, 1] <= r[3])
            uv = uv[~inside]
    if not len(uv):
        return np.zeros((0, 3))
    uv = np.unique(uv, axis=0)
    return ldr_uint8_to_hdr(image[uv[:, 1], uv[:, 0]][None])[0].astype(np.float64)


def image_reference_level(image: np.ndarray) -> float:
    """The median linear luminance of the image's lower half (the level paint bands are measured against)."""
    lower = image[image.shape[0] // 2:: 4, :: 4]
    return float(np.median(luminance(ldr_uint8_to_hdr(lower))))


def band_ratio(band_rgb: np.ndarray, reference: float) -> np.ndarray | None:
    """The paint band's median radiance (3,) over the image's reference level (:func:`image_reference_level`),
    from its pixels (:func:`paint_band_rgb`); None with fewer than :data:`MIN_BAND_PX` pixels."""
    if len(band_rgb) < MIN_BAND_PX or not reference > 0:
        return None
    return np.median(band_rgb, axis=0) / reference


def predicted_band_ratio(albedo_rgb: np.ndarray) -> np.ndarray:
    """(..., 3) the band ratio a paint of linear albedo ``albedo_rgb`` (..., 3) shows (see the module docstring)."""
    return REFLECTED_RATIO + LIT_RATIO * np.asarray(albedo_rgb, float)


def _chromaticity(rgb: np.ndarray) -> np.ndarray:
    rgb = np.maximum(np.asarray(rgb, float), 1e-6)
    return (rgb / rgb.sum(axis=-1, keepdims=True))[..., :2]


def _shade_prior(region: str) -> tuple[np.ndarray, np.ndarray]:
    """(region's shade weights (S,) summing to 1, the per-car prior (S,): :data:`FAMILY_PRIOR_POWER` of the
    family shares times the shade's share within its family)."""
    palette = paint_palette(region)
    prior = np.array([p[3] for p in palette])
    prior = prior / prior.sum()
    families = [paint_family(p[0]) for p in palette]
    family_total = {f: sum(w for w, g in zip(prior, families) if g == f) for f in set(families)}
    per_car = np.array([w / family_total[f] * family_total[f] ** FAMILY_PRIOR_POWER if family_total[f] > 0 else 0.0
                        for w, f in zip(prior, families)])
    return prior, per_car / per_car.sum()


def car_shade_likelihood(ratio: np.ndarray, region: str = "global") -> np.ndarray | None:
    """(S,) likelihood of a car's band ratio (3,) (:func:`band_ratio`) under each shade of ``paint_palette(region)``:
    log-normal in luminance (:data:`SIGMA_LOG_LUMINANCE`) and normal in chromaticity (:data:`SIGMA_CHROMATICITY`)
    around the shade's :func:`predicted_band_ratio`; None for a ratio that is not finite and positive."""
    a = np.asarray(ratio, float)
    if not (np.all(np.isfinite(a)) and a.max() > 0):
        return None
    shade = predicted_band_ratio(np.array([p[1] for p in paint_palette(region)]))
    dy = np.log(np.maximum(luminance(shade), 1e-4)) - np.log(max(float(luminance(a)), 1e-4))
    dc = np.linalg.norm(_chromaticity(shade) - _chromaticity(a), axis=1)
    return np.exp(-0.5 * (dy / SIGMA_LOG_LUMINANCE) ** 2 - 0.5 * (dc / SIGMA_CHROMATICITY) ** 2)


def car_shade_posterior(ratio: np.ndarray, region: str = "global") -> np.ndarray | None:
    """One car's posterior (S,) over the shades of ``paint_palette(region)`` given its band ratio (3,) alone: the
    per-car prior (:func:`_shade_prior`) times :func:`car_shade_likelihood`; None for a colour no shade explains."""
    like = car_shade_likelihood(ratio, region)
    if like is None:
        return None
    post = _shade_prior(region)[1] * like
    return post / post.sum() if post.sum() > 1e-300 else None


def scene_paint_weights(ratios: Sequence[np.ndarray], region: str = "global") -> np.ndarray:
    """Weights (S,) of the shades of ``paint_palette(region)`` given the band ratios (3,) of real cars
    (:func:`band_ratio`): the mix that explains them best, with :data:`PRIOR_CARS` cars' worth of the region's
    table as a Dirichlet prior (MAP mixture weights by :data:`EM_ITERATIONS` EM steps from the per-car prior of
    :func:`_shade_prior`). Summing each car's own posterior instead spread every mix towards the prior: on
    scene-0916 the inserted cars' band ratios stayed brighter than the real cars' (75th percentile 1.35 vs 0.85).
    No cars: the region's weights.
    """
    prior, weights = _shade_prior(region)
    likes = [car_shade_likelihood(r, region) for r in ratios if r is not None]
    likes = [lk for lk in likes if lk is not None and lk.max() > 1e-300]
    if not likes:
        return prior
    L = np.array(likes)  # (cars, shades)
    for _ in range(EM_ITERATIONS):
        resp = L * weights
        resp /= np.maximum(resp.sum(axis=1, keepdims=True), 1e-300)
        weights = (PRIOR_CARS * prior + resp.sum(axis=0)) / (PRIOR_CARS + len(L))
    return weights / weights.sum()


def sample_car_ratios(sample, channels: Sequence[str] | None = None, category_prefix: str = "vehicle.car"
                       ) -> list[np.ndarray]:
    """Band ratios (3,) (:func:`band_ratio`) of the annotated cars of a sample, each car once (the camera that sees most
    of its band), measured in ``channels`` (None: every camera).

    ``sample`` is duck-typed (no import of the datasets layer): ``sample.cameras[channel]`` with ``image``
    (H, W, 3) uint8, ``K`` (3, 3) and ``T_cam_from_global`` (4, 4); ``sample.boxes`` with ``T_global_from_box``,
    ``wlh``, ``category`` and ``token``. Cars farther than :data:`MAX_DISTANCE_M` are left out.
    """
    best: dict[str, tuple[int, np.ndarray]] = {}
    boxes = list(sample.boxes)
    if not any(b.category.startswith(category_prefix) for b in boxes):
        return []
    for channel in (channels if channels is not None else list(sample.cameras)):
        view = sample.cameras[channel]
        T_cam_from_global = np.asarray(view.T_cam_from_global, float)
        K = np.asarray(view.K, float)
        poses = [T_cam_from_global @ b.T_global_from_box for b in boxes]
        dist = np.array([np.linalg.norm(T[:3, 3]) if T[2, 3] > 1.0 else np.inf for T in poses])
        cars = [i for i, b in enumerate(boxes) if b.category.startswith(category_prefix) and dist[i] <= MAX_DISTANCE_M]
        if not cars:
            continue
        image = view.image
        reference = image_reference_level(image)
        rects = [box_rect_px(K, T, b.wlh) if np.isfinite(d) else None for T, b, d in zip(poses, boxes, dist)]
        for i in cars:
            nearer = [rects[j] for j in range(len(boxes))
                      if j != i and rects[j] is not None and dist[j] < dist[i] - 0.5]
            band = paint_band_rgb(image, K, poses[i], boxes[i].wlh, nearer)
            ratio = band_ratio(band, reference)
            key = boxes[i].token or f"{channel}:{i}"
            if ratio is not None and len(band) > best.get(key, (0, None))[0]:
                best[key] = (len(band), ratio)
    return [a for _, a in best.values()]


def scene_paint_mix(sample, channels: Sequence[str] | None = None) -> tuple[float, ...] | None:
    """The shade weights (:func:`scene_paint_weights`, the palette of ``sample.location``'s region) of a sample's
    annotated cars seen by ``channels`` (None: every camera), rounded to 4 decimals (a hashable cache key for
    :func:`~.select.select_assets`' ``paint_weights``), or None when no car could be measured (callers then
    draw from the region's table). A camera whose image cannot be read is left out."""
    readable = []
    for channel in (channels if channels is not None else list(sample.cameras)):
        try:
            sample.cameras[channel].image
        except (OSError, ValueError):
            continue
        readable.append(channel)
    ratios = sample_car_ratios(sample, readable)
    if not ratios:
        return None
    w = np.round(scene_paint_weights(ratios, paint_region_for_location(getattr(sample, "location", None))), 4)
    return tuple(float(x) for x in w / w.sum())


__all__ = ["band_ratio", "car_shade_likelihood", "car_shade_posterior", "image_reference_level", "paint_band_rgb", "predicted_band_ratio",
           "sample_car_ratios", "scene_paint_mix", "scene_paint_weights"]
