"""L1's environment from the pixels the camera sees: the sky model corrected towards the image, at infinity.

L1 is distant light only, and its map used to be the sky model alone above the horizon (and an assumed-albedo
ground below it): rendered from the camera's own centre, it showed a bright sky where the image has facades
and trees, so that a user lighting a scene with it (or the renderer shading an object) got several times too
much light from the sides. :func:`image_corrected_envmap` keeps the model's *shape* where the camera saw
nothing and takes the image's radiance everywhere it saw something:

* every pixel of the prepared image (:func:`.evidence.prepare_image`, 480 px wide) is a sample of the distant light in its ray's
  direction (the camera-frame equirect convention); seen cells of the map take the mean radiance of their
  pixels (a clipped pixel only says "at least this bright");
* unseen cells take the model times the image/model ratio of the seen cells of the same *elevation band*
  (gravity up; the street's symmetry: what stands on one side at an elevation stands on the other),
  interpolated between bands; above the highest band seen, the ratio of the seen sky (the zenith is sky),
  below the lowest, the lowest band's ratio (the road continues);
* below the highest elevation seen, the unseen cells are then shrunk towards the seen mean colour
  (:func:`.fill.shrink_unseen`: the band statistics of one street are a noisy guess of another direction's);
* the two are blended over ``BLEND_DEG`` around what was seen (normalised convolution of the log ratio).

Radiance is on the image's scale (contract response, EV 0), like the model it corrects. The sun (a separate
directional light) is unchanged.
"""

from __future__ import annotations

import numpy as np

from dataclasses import dataclass

from functools import lru_cache

from ..core import SATURATION_LDR, camera_envmap_directions, check_shape, ldr_to_hdr, luminance
from .evidence import PreparedImage
from .fill import UNSEEN_KEEP, mean_colour_radiance, shrink_unseen
from .skydome import blend_observed

BAND_DEG = 4.0  # elevation bands of the row correction
MIN_BAND_CELLS = 3  # a band needs this many seen map cells to carry a ratio
BLEND_DEG = 8.0
MAX_LOG_GAIN = np.log(20.0)
MIN_SKY_PIXELS = 20
# where the response saturates: a clipped pixel's channels are "at least" this (core.clipped_to_lower_bound)
_SATURATION_RADIANCE = ldr_to_hdr(np.full(3, SATURATION_LDR))


@lru_cache(maxsize=4)
def _map_directions(H: int, W: int) -> np.ndarray:
    """(H, W, 3) read-only unit directions of a camera-frame equirect map's cells (cached)."""
    d = camera_envmap_directions(H, W)
    d.flags.writeable = False
    return d


def map_cells(rays: np.ndarray, H: int, W: int) -> np.ndarray:
    """(N,) flat index (row * W + col) of the camera-frame equirect cell holding each unit ray (N, 3)."""
    lon = np.arctan2(rays[:, 0], rays[:, 2])
    lat = np.arcsin(np.clip(-rays[:, 1], -1.0, 1.0))
    col = np.clip(((lon / (2 * np.pi) + 0.5) * W).astype(np.int64), 0, W - 1)
    row = np.clip(((0.5 - lat / np.pi) * H).astype(np.int64), 0, H - 1)
    return row * W + col


@dataclass(frozen=True)
class SeenPixels:
    """One image's pixels as samples of the distant light, in the map's frame and radiometric scale.

    Attributes:
        rays: (N, 3) unit directions (the map's camera frame).
        radiance: (N, 3) float64 linear radiance (the map's image units).
        clipped: (N,) bool, the pixel is clipped (its radiance is a lower bound).
        sky: (N,) bool, the pixel is sky.
    """

    rays: np.ndarray
    radiance: np.ndarray
    clipped: np.ndarray
    sky: np.ndarray


def seen_pixels(work: PreparedImage, R_map_from_cam: np.ndarray | None = None, gain: float = 1.0,
                sky: np.ndarray | None = None) -> SeenPixels:
    """A prepared image's pixels turned into the map's frame (``R_map_from_cam``, default identity) and scale
    (radiance x ``gain``: the map camera's image units per this camera's); ``sky`` (h, w) defaults to
    ``work.sky`` (:func:`.evidence.image_sky_mask`)."""
    rays = work.rays_cam.reshape(-1, 3)
    if R_map_from_cam is not None:
        rays = rays @ np.asarray(R_map_from_cam, np.float64).T
    clipped = work.clipped.reshape(-1)
    is_sky = (work.sky if sky is None else np.asarray(sky, bool)).reshape(-1)
    rad = work.hdr.reshape(-1, 3) * float(gain)  # a copy: the clipped pixels are lowered in place
    rad[clipped] = np.minimum(rad[clipped], _SATURATION_RADIANCE * float(gain))  # clipped: a lower bound
    return SeenPixels(rays, rad, clipped, is_sky)


def band_log_gains(log_ratio_cells: np.ndarray, cell_elev_deg: np.ndarray, all_elev_deg: np.ndarray,
                   sky_log_gain: np.ndarray | None) -> np.ndarray:
    """(M, 3) log correction at elevations ``all_elev_deg`` (M,) from the seen cells' log ratios (S, 3).

    Per band of ``BAND_DEG``: the log of the mean ratio of its seen cells (bands with >= ``MIN_BAND_CELLS``),
    linearly interpolated between band centres; above the highest band ``sky_log_gain`` (the seen sky's ratio)
    when given, else the highest band's; below the lowest band the lowest band's.
    """
    edges = np.arange(-90.0, 90.0 + BAND_DEG, BAND_DEG)
    band = np.clip(np.digitize(cell_elev_deg, edges) - 1, 0, len(edges) - 2)
    counts = np.bincount(band, minlength=len(edges) - 1)
    have = np.flatnonzero(counts >= MIN_BAND_CELLS)
    if not len(have):
        return np.zeros((len(all_elev_deg), 3))
    ratio = np.exp(log_ratio_cells)
    mean = np.stack([np.bincount(band, ratio[:, c], minlength=len(edges) - 1)[have] / counts[have] for c in range(3)], 1)
    centres = 0.5 * (edges[have] + edges[have + 1])
    log_mean = np.log(np.maximum(mean, 1e-9))
    top = log_mean[-1] if sky_log_gain is None else sky_log_gain
    return np.stack([np.interp(all_elev_deg, centres, log_mean[:, c], left=log_mean[0, c], right=top[c])
                     for c in range(3)], axis=1)


def image_corrected_envmap(model_envmap: np.ndarray, pixels: SeenPixels | list[SeenPixels],
                           up_cam: np.ndarray, keep: float = UNSEEN_KEEP) -> tuple[np.ndarray, dict]:
    """The model map (H, W, 3) (camera-frame equirect, image scale, sun excluded) corrected by the image.

    Args:
        model_envmap: (H, W, 3) the sky model (+ its ground) L1 fitted, camera-frame convention.
        pixels: the images' pixels in the map's frame and scale (:func:`seen_pixels`; several cameras of one
            instant give one map); the sky pixels' image/model ratio continues above the highest seen band (the
            zenith is sky).
        up_cam: (3,) unit gravity up, the map's camera frame.
        keep: unseen cells below the highest seen elevation keep this much of the corrected model's
            log-radiance, the rest is the seen mean colour (:func:`.fill.shrink_unseen`).
    Returns:
        (envmap (H, W, 3) float32, stats: seen fraction of the sphere, band count, mean gain).
    """
    check_shape(model_envmap, ("H", "W", 3), "model_envmap")
    H, W = model_envmap.shape[:2]
    model = np.maximum(model_envmap.astype(np.float64), 1e-9)
    pixels = [pixels] if isinstance(pixels, SeenPixels) else list(pixels)
    rays = np.concatenate([p.rays for p in pixels])
    rad = np.concatenate([p.radiance for p in pixels])
    clipped = np.concatenate([p.clipped for p in pixels])
    cell = map_cells(rays, H, W)
    ok = ~clipped
    # a cell's mean over all its pixels, clipped ones at their recorded value: exact where nothing clipped, a
    # lower bound where something did (a fully clipped cell keeps the model if that is brighter)
    count = np.bincount(cell, minlength=H * W).astype(np.float64)
    sums = np.stack([np.bincount(cell, rad[:, c], minlength=H * W) for c in range(3)], axis=1)
    seen = (count > 0).reshape(H, W)
    mean_obs = (sums / np.maximum(count, 1)[:, None]).reshape(H, W, 3)
    n_clipped = np.bincount(cell[clipped], minlength=H * W)
    all_clipped = ((n_clipped == count) & (count > 0)).reshape(H, W)
    floor = np.where(all_clipped, luminance(mean_obs), 0.0)
    up = np.asarray(up_cam, np.float64) / np.linalg.norm(up_cam)
    elev = np.degrees(np.arcsin(np.clip(_map_directions(H, W) @ up, -1.0, 1.0)))
    stats = {"seen_fraction": float(seen.mean()), "bands": 0, "pixels": int(len(rays)), "clipped_pixels": int(clipped.sum())}
    if not seen.any():
        return model_envmap.astype(np.float32), stats
    unclipped = seen & ~all_clipped
    log_ratio = np.log(np.maximum(mean_obs[unclipped], 1e-9) / model[unclipped])
    is_sky = np.concatenate([p.sky for p in pixels]) & ok
    sky_gain = None
    if is_sky.sum() >= MIN_SKY_PIXELS:
        sky_model = model.reshape(-1, 3)[cell[is_sky]].mean(axis=0)
        sky_gain = np.log(np.maximum(rad[is_sky].mean(axis=0), 1e-9) / sky_model)
    gains = band_log_gains(log_ratio, elev[unclipped], elev.reshape(-1), sky_gain)
    gains = np.clip(gains, -MAX_LOG_GAIN, MAX_LOG_GAIN).reshape(H, W, 3)
    corrected = model * np.exp(gains)
    # below the highest elevation seen, what no camera saw is shrunk towards the seen mean colour (.fill); the
    # sky above it stays the corrected model
    below_sky = (elev <= np.percentile(elev[unclipped], 99.0))[..., None]  # robust top of what was seen
    corrected = np.where(below_sky, shrink_unseen(corrected, mean_colour_radiance(rad), keep), corrected)
    out = blend_observed(corrected, unclipped, mean_obs, BLEND_DEG)
    lum = np.maximum(luminance(out), 1e-12)
    out = out * np.maximum(1.0, floor / lum)[..., None]
    edges = np.arange(-90.0, 90.0 + BAND_DEG, BAND_DEG)
    stats.update(bands=int(len(np.unique(np.digitize(elev[seen], edges)))),
                 mean_gain_rgb=np.exp(gains.reshape(-1, 3).mean(axis=0)).tolist())
    return out.astype(np.float32), stats
