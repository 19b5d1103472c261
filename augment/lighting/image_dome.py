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
  (:func:`.fill.shrink_unseen`: the band statistics of one street are a noisy guess of another direction's),
  keeping ``keep`` of the corrected model above the horizon and ``GROUND_KEEP`` below it;
* the street's mirror symmetry (:func:`street_mirror`): an unseen cell whose mirror image across the street's
  planes (ahead <-> behind, left <-> right, gravity up, the ego's forward axis) was seen moves
  ``SYMMETRY_WEIGHT`` of the way (log space) towards the smoothed seen radiance there: the road behind is
  road-coloured, the facades behind facade-coloured, per elevation;
* the two are blended over ``BLEND_DEG`` around what was seen (normalised convolution of the log ratio).

Radiance is on the image's scale (contract response, EV 0), like the model it corrects. The sun (a separate
directional light) is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from ..core import (SATURATION_RADIANCE, camera_dir_to_lonlat, camera_envmap_directions, check_shape, lonlat_to_uv,
                    luminance)
from .evidence import SATURATED_LDR, PreparedImage
from .fill import UNSEEN_KEEP, mean_colour_radiance, shrink_unseen
from .sky_prior import censored_sky_log_gain
from .skydome import blend_observed

BAND_DEG = 4.0  # elevation bands of the row correction
MIN_BAND_CELLS = 3  # a band needs this many seen map cells to carry a ratio
BLEND_DEG = 8.0
MAX_LOG_GAIN = np.log(20.0)
MIN_SKY_PIXELS = 20
# the street's mirror symmetry (what stands ahead stands behind, what stands left stands right): an unseen cell
# whose mirror image was seen moves this far (log space) from the band statistics towards the seen radiance
# there, smoothed over SYMMETRY_BLUR_DEG; fitted by benchmarks/bench_unseen_l1.py --fit (keyframe split of the
# dev scene: results/unseen_l1_fit.json)
SYMMETRY_WEIGHT = 0.5
SYMMETRY_BLUR_DEG = 8.0
MIRROR_SCALE = 2  # the mirror is worked out on a map this many times coarser (it is smoothed over the blur anyway)
# the unseen ground (below the horizon): this much of the corrected model's log-radiance, the rest the seen mean
# colour (the model's ground, an assumed albedo under the fitted sky, scaled per band, does not carry to other
# directions); fitted with the symmetry by benchmarks/bench_unseen_l1.py --fit
GROUND_KEEP = 0.0


@lru_cache(maxsize=4)
def _map_directions(H: int, W: int) -> np.ndarray:
    """(H, W, 3) read-only unit directions of a camera-frame equirect map's cells (cached)."""
    d = camera_envmap_directions(H, W)
    d.flags.writeable = False
    return d


def map_cells(rays: np.ndarray, H: int, W: int) -> np.ndarray:
    """(N,) flat index (row * W + col) of the camera-frame equirect cell holding each unit ray (N, 3)."""
    u, v = lonlat_to_uv(*camera_dir_to_lonlat(rays), H, W)
    col = np.clip(u.astype(np.int64), 0, W - 1)
    row = np.clip(v.astype(np.int64), 0, H - 1)
    return row * W + col


@dataclass(frozen=True)
class SeenPixels:
    """One image's pixels as samples of the distant light, in the map's frame and radiometric scale.

    Attributes:
        rays: (N, 3) unit directions (the map's camera frame).
        radiance: (N, 3) float64 linear radiance (the map's image units).
        clipped: (N,) bool, the pixel is clipped (its radiance is a lower bound).
        sky: (N,) bool, the pixel is sky.
        clipped_rgb: (N, 3) bool, the channel is clipped (its radiance is the saturation level, a lower bound;
            the pixel's other channels are measurements).
    """

    rays: np.ndarray
    radiance: np.ndarray
    clipped: np.ndarray
    sky: np.ndarray
    clipped_rgb: np.ndarray


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
    # clipped: a lower bound (core.clipped_to_lower_bound, in place on the copy)
    rad[clipped] = np.minimum(rad[clipped], SATURATION_RADIANCE * float(gain))
    clipped_rgb = (work.ldr >= SATURATED_LDR).reshape(-1, 3)
    return SeenPixels(rays, rad, clipped, is_sky, clipped_rgb)


def sky_log_gain(radiance: np.ndarray, clipped_rgb: np.ndarray, model: np.ndarray) -> np.ndarray | None:
    """(3,) log image/model ratio of the sky: per channel the log ratio of the medians of the sky pixels'
    radiance (N, 3) and the model's there (N, 3); None with fewer than ``MIN_SKY_PIXELS`` pixels.

    A clipped channel (``clipped_rgb`` (N, 3)) holds the saturation level, above every unclipped value of its
    channel: its median is exact while fewer than half of the channel is clipped (a censored median; the
    unclipped pixels alone are the sky's darker part, its edges and haze). Past half, the median is only a
    lower bound: the sky is at least that bright, and takes the expected gain given that bound under the prior
    of unclipped skies (:func:`.sky_prior.censored_sky_log_gain`: the channels share the sky's offset from the
    prior). So the sky of a brighter exposure is never darker than that of a darker one (an all-clipped sky
    used to take the ratio of the highest unclipped band: trees and facades).
    """
    if len(radiance) < MIN_SKY_PIXELS:
        return None
    med = np.median(radiance, axis=0)
    gain = np.log(np.maximum(med, 1e-9) / np.maximum(np.median(model, axis=0), 1e-9))
    censored = clipped_rgb.mean(axis=0) >= 0.5
    return censored_sky_log_gain(gain[None], censored[None])[0]


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


def _wrapped_blur(x: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur (sigma in map columns) of an (H, W[, C]) map, wrapping in longitude."""
    pad = int(3 * sigma_px) + 1
    widths = ((0, 0), (pad, pad)) + ((0, 0),) * (x.ndim - 2)
    return cv2.GaussianBlur(np.pad(x, widths, mode="wrap"), (0, 0), sigma_px)[:, pad:-pad]


def street_mirror(log_seen: np.ndarray, seen: np.ndarray, up: np.ndarray, forward: np.ndarray,
                  blur_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The seen log radiance (H, W, 3) of a camera-frame map carried to the cells whose mirror images across
    the street's planes were seen: across the plane through up and the lateral axis (ahead <-> behind), through
    up and ``forward`` (left <-> right) and both (gravity ``up`` and the street's horizontal ``forward`` (3,),
    map frame).

    The seen cells (``seen`` (H, W) bool) are smoothed first (normalised convolution, Gaussian of ``blur_deg``):
    a mirror image says what kind of thing stands there, not where its edges are. Returns (log radiance
    (H, W, 3), confidence (H, W) in [0, 1]: how much of each cell's mirror images was seen).
    """
    H, W = seen.shape
    h, w = H // MIRROR_SCALE, W // MIRROR_SCALE  # smooth by construction: worked out at a coarser resolution
    sig = blur_deg / 360.0 * w
    seen_low = cv2.resize(seen.astype(np.float64), (w, h), interpolation=cv2.INTER_AREA)
    log_low = cv2.resize(np.where(seen[..., None], log_seen, 0.0), (w, h), interpolation=cv2.INTER_AREA)
    weight = _wrapped_blur(seen_low, sig)
    smooth = _wrapped_blur(log_low, sig) / np.maximum(weight, 1e-9)[..., None]
    conf_cells = np.clip(weight / 0.5, 0.0, 1.0).reshape(-1)
    smooth = smooth.reshape(-1, 3)
    lateral = np.cross(up, forward)
    d = _map_directions(h, w).reshape(-1, 3)
    along, across = d @ forward, d @ lateral
    num, den = np.zeros((h * w, 3)), np.zeros(h * w)
    for a, b in ((2.0, 0.0), (0.0, 2.0), (2.0, 2.0)):
        cell = map_cells(d - a * along[:, None] * forward - b * across[:, None] * lateral, h, w)
        c = conf_cells[cell]
        num += c[:, None] * smooth[cell]
        den += c
    low = np.concatenate([num / np.maximum(den, 1e-9)[:, None], np.clip(den, 0.0, 1.0)[:, None]], 1).reshape(h, w, 4)
    # back to the map's resolution (bilinear, wrapping in longitude)
    k = MIRROR_SCALE
    up_res = cv2.resize(np.pad(low, ((0, 0), (1, 1), (0, 0)), mode="wrap"), ((w + 2) * k, H),
                        interpolation=cv2.INTER_LINEAR)[:, k : k + W]
    return up_res[..., :3], up_res[..., 3]


def horizontal_forward(forward_cam: np.ndarray | None, up: np.ndarray) -> np.ndarray:
    """Unit (3,) horizontal street direction: ``forward_cam`` (default the camera's optical axis +z) with its
    component along the unit ``up`` removed."""
    f = np.array([0.0, 0.0, 1.0]) if forward_cam is None else np.asarray(forward_cam, np.float64)
    f = f - (f @ up) * up
    n = float(np.linalg.norm(f))
    if n < 1e-6:  # looking straight up or down: any horizontal direction
        f = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
        n = float(np.linalg.norm(f))
    return f / n


def image_corrected_envmap(model_envmap: np.ndarray, pixels: SeenPixels | list[SeenPixels],
                           up_cam: np.ndarray, keep: float = UNSEEN_KEEP, *,
                           forward_cam: np.ndarray | None = None, ground_keep: float | None = None,
                           symmetry_weight: float | None = None) -> tuple[np.ndarray, dict]:
    """The model map (H, W, 3) (camera-frame equirect, image scale, sun excluded) corrected by the image.

    Args:
        model_envmap: (H, W, 3) the sky model (+ its ground) L1 fitted, camera-frame convention.
        pixels: the images' pixels in the map's frame and scale (:func:`seen_pixels`; several cameras of one
            instant give one map); the sky pixels' image/model ratio continues above the highest seen band (the
            zenith is sky).
        up_cam: (3,) unit gravity up, the map's camera frame.
        keep: unseen cells between the horizon and the highest seen elevation keep this much of the corrected
            model's log-radiance, the rest is the seen mean colour (:func:`.fill.shrink_unseen`).
        forward_cam: (3,) the street's direction in the map's frame (the ego's forward axis), None: the map
            camera's optical axis; the mirror symmetry's planes (:func:`street_mirror`).
        ground_keep: ``keep`` of the unseen cells below the horizon; None: ``GROUND_KEEP``.
        symmetry_weight: how far unseen cells whose street mirror images were seen move towards them (log space,
            times the mirror's confidence); None: ``SYMMETRY_WEIGHT`` (0: the band statistics alone).
    Returns:
        (envmap (H, W, 3) float32, stats: seen fraction of the sphere, band count, mean gain, the fraction of the
        unseen cells whose mirror images were mostly seen).
    """
    check_shape(model_envmap, ("H", "W", 3), "model_envmap")
    H, W = model_envmap.shape[:2]
    model = np.maximum(model_envmap.astype(np.float64), 1e-9)
    pixels = [pixels] if isinstance(pixels, SeenPixels) else list(pixels)
    rays = np.concatenate([p.rays for p in pixels])
    rad = np.concatenate([p.radiance for p in pixels])
    clipped = np.concatenate([p.clipped for p in pixels])
    cell = map_cells(rays, H, W)
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
    is_sky = np.concatenate([p.sky for p in pixels])
    clipped_rgb = np.concatenate([p.clipped_rgb for p in pixels])
    sky_gain = sky_log_gain(rad[is_sky], clipped_rgb[is_sky], model.reshape(-1, 3)[cell[is_sky]])
    gains = band_log_gains(log_ratio, elev[unclipped], elev.reshape(-1), sky_gain)
    gains = np.clip(gains, -MAX_LOG_GAIN, MAX_LOG_GAIN).reshape(H, W, 3)
    corrected = model * np.exp(gains)
    # below the highest elevation seen, what no camera saw is shrunk towards the seen mean colour (.fill), the
    # ground below the horizon by GROUND_KEEP; the sky above it stays the corrected model
    top = np.percentile(elev[unclipped], 99.0)  # robust top of what was seen
    ground_keep = GROUND_KEEP if ground_keep is None else ground_keep
    keep_map = np.where(elev <= top, np.where(elev < 0.0, ground_keep, keep), 1.0)[..., None]
    corrected = shrink_unseen(corrected, mean_colour_radiance(rad), keep_map)
    symmetry_weight = SYMMETRY_WEIGHT if symmetry_weight is None else symmetry_weight
    if symmetry_weight > 0.0:  # unseen cells whose mirror images were seen: towards what was seen there
        log_mirror, conf = street_mirror(np.log(np.maximum(mean_obs, 1e-9)), unclipped, up,
                                         horizontal_forward(forward_cam, up), SYMMETRY_BLUR_DEG)
        t = (symmetry_weight * conf)[..., None]
        stats["mirrored_fraction"] = float((conf[~seen] >= 0.5).mean()) if (~seen).any() else 0.0
        corrected = np.exp((1.0 - t) * np.log(corrected) + t * log_mirror)
    out = blend_observed(corrected, unclipped, mean_obs, BLEND_DEG)
    lum = np.maximum(luminance(out), 1e-12)
    out = out * np.maximum(1.0, floor / lum)[..., None]
    edges = np.arange(-90.0, 90.0 + BAND_DEG, BAND_DEG)
    stats.update(bands=int(len(np.unique(np.digitize(elev[seen], edges)))),
                 mean_gain_rgb=np.exp(gains.reshape(-1, 3).mean(axis=0)).tolist())
    return out.astype(np.float32), stats
