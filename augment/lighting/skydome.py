"""The sky dome of a sample: the sky model (parametric or learned) corrected towards the pixels seen at infinity.

World-convention equirect maps (z up, see :mod:`.volume`), on the reference camera's radiometric scale, sun
excluded. Observed sky pixels (and non-sky pixels beyond the volume: distant scenery) replace the model where
seen; elsewhere the model is multiplied by the observed/model ratio as a function of elevation (per camera
around its own azimuth when several cameras see sky), blended smoothly into the observations' neighbourhood.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..core import camera_dir_to_lonlat, check_shape, hdr_to_ldr, ldr_to_hdr, luminance, sample_equirect
from .fill import UNSEEN_KEEP, shrink_unseen
from .observe import ViewObservation
from .sky import sky_radiance
from .sky_prior import censored_sky_log_gain
from .volume import world_envmap_directions

SKY_GAIN_KAPPA = 2.0  # several cameras: von Mises weight of a camera's sky correction over azimuth (~60 deg wide)
BAND_SIGMA_DEG = 4.0  # elevation bands of the seen far pixels: Gaussian width over elevation
BAND_PRIOR_CELLS = 32.0  # a band's seen mean colour is shrunk towards the global anchor with this many dome cells


def model_sky_world(sun_dir_vol: np.ndarray, turbidity: float, cloud_cover: float, ground_albedo: float, scale: float,
                    height: int = 64, width: int = 256) -> np.ndarray:
    """The parametric sky (+ Lambertian ground below the horizon) as a world-convention map (H, W, 3), sun excluded."""
    d = world_envmap_directions(height, width).reshape(-1, 3)
    rad = sky_radiance(d, sun_dir_vol, turbidity, cloud_cover, ground_albedo) * scale
    return rad.reshape(height, width, 3).astype(np.float32)


def camera_envmap_to_world(envmap_cam: np.ndarray, R_vol_from_cam: np.ndarray, height: int, width: int) -> np.ndarray:
    """A camera-frame equirect map (h, w, 3) resampled (bilinear) into a world-convention map (height, width, 3)."""
    d_vol = world_envmap_directions(height, width).reshape(-1, 3)
    lon, lat = camera_dir_to_lonlat(d_vol @ np.asarray(R_vol_from_cam, np.float64))  # rows: R^T d
    return sample_equirect(envmap_cam, lon, lat).reshape(height, width, 3).astype(np.float32)


def _row_log_gains(log_ratio: np.ndarray, rows: np.ndarray, H: int) -> np.ndarray:
    """(H, 3) log sky correction per dome row: the median log ratio of the rows with >= 5 sky pixels (upper
    half), interpolated between them; beyond the observed rows (towards the zenith, say) the overall median,
    not the last row's: one row of an image's top edge (a glare, a bright cloud) does not speak for the sky
    above it."""
    overall = np.median(log_ratio, axis=0)
    have = np.flatnonzero(np.bincount(rows, minlength=H) >= 5)
    have = have[have < H // 2]
    if not len(have):
        return np.broadcast_to(overall, (H, 3)).copy()
    med = np.array([np.median(log_ratio[rows == r], axis=0) for r in have])
    return np.stack([np.interp(np.arange(H), have, med[:, c], left=overall[c], right=overall[c]) for c in range(3)],
                    axis=1)


def _sky_log_gain(log_ratio: np.ndarray, rows: np.ndarray, lon: np.ndarray, view: np.ndarray, n_views: int,
                  H: int, W: int) -> np.ndarray:
    """(H, W, 3) log correction of the model from the observed sky pixels' log ratios (N, 3) at dome rows (N,),
    longitudes (N,) rad, seen by camera ``view`` (N,): per row; with >= 2 cameras' skies, each camera corrects
    the sky around its own azimuth (the sky near the sun, or one camera's haze, is not every direction's)."""
    log_gain = np.zeros((H, W, 3))
    per_view = [v for v in range(n_views) if (view == v).sum() >= 20]
    if len(per_view) < 2:
        log_gain[:] = _row_log_gains(log_ratio, rows, H)[:, None, :]
        return log_gain
    col_lon = (np.arange(W) + 0.5) / W * 2 * np.pi - np.pi
    weights = []
    for v in per_view:
        m = view == v
        centre = np.arctan2(np.sin(lon[m]).sum(), np.cos(lon[m]).sum())
        weights.append(m.sum() * np.exp(SKY_GAIN_KAPPA * (np.cos(col_lon - centre) - 1.0)))
        log_gain += _row_log_gains(log_ratio[m], rows[m], H)[:, None, :] * weights[-1][None, :, None]
    log_gain /= np.sum(weights, axis=0)[None, :, None]
    return log_gain


def band_anchor_rgb(observed: np.ndarray, mean_obs: np.ndarray, anchor_rgb: np.ndarray,
                    sigma_deg: float = BAND_SIGMA_DEG, prior_cells: float = BAND_PRIOR_CELLS) -> np.ndarray:
    """(H, 3) the mean colour (as radiance) of the dome's observed far cells per elevation band: what lies beyond
    the volume at that elevation (sky between the trees, distant scenery), the best constant guess of the unseen
    cells of the same band. Per row, the LDR mean of the observed cells ``observed`` (H, W) with values
    ``mean_obs`` (H, W, 3), Gaussian-weighted over rows (``sigma_deg``), shrunk towards ``anchor_rgb`` (3,) with
    ``prior_cells`` cells' weight (a band seen in a few cells is a noisy guess)."""
    H = observed.shape[0]
    ldr = np.clip(hdr_to_ldr(np.maximum(mean_obs, 0.0)), 0.0, 1.0)
    count = observed.sum(axis=1).astype(np.float64)
    sums = (ldr * observed[..., None]).sum(axis=1)
    sig = sigma_deg / 180.0 * H
    pad = int(3 * sig) + 1
    k = np.exp(-0.5 * (np.arange(-pad, pad + 1) / sig) ** 2)
    count_b = np.convolve(count, k, mode="same")
    sums_b = np.stack([np.convolve(sums[:, c], k, mode="same") for c in range(3)], axis=1)
    prior = np.clip(hdr_to_ldr(np.asarray(anchor_rgb, np.float64)), 0.0, 1.0)
    band = (sums_b + prior_cells * prior) / (count_b + prior_cells)[:, None]
    return np.maximum(ldr_to_hdr(band), 1e-9)


def blend_observed(corrected: np.ndarray, observed: np.ndarray, mean_obs: np.ndarray, blur_deg: float) -> np.ndarray:
    """The observations pasted into the corrected model, blended into their neighbourhood (normalised
    convolution of the log ratio, Gaussian of ``blur_deg``, wrapping in longitude)."""
    W = corrected.shape[1]
    log_res = np.where(observed[..., None], np.log(np.maximum(mean_obs, 1e-9) / corrected), 0.0)
    sig = blur_deg / 360.0 * W
    wmap = observed.astype(np.float64)
    pad = int(3 * sig) + 1
    wp = np.pad(wmap, ((0, 0), (pad, pad)), mode="wrap")
    rp = np.pad(log_res * wmap[..., None], ((0, 0), (pad, pad), (0, 0)), mode="wrap")
    wb = cv2.GaussianBlur(wp, (0, 0), sig)[:, pad:-pad]
    rb = cv2.GaussianBlur(rp, (0, 0), sig)[:, pad:-pad]
    conf = np.clip(wb / 0.5, 0.0, 1.0)
    smooth = rb / np.maximum(wb, 1e-9)[..., None] * conf[..., None]
    return np.where(observed[..., None], mean_obs, corrected * np.exp(smooth))


def build_sky_dome(model_world: np.ndarray, observations: list[ViewObservation],
                   blur_deg: float = 12.0, anchor_rgb: np.ndarray | None = None,
                   keep: float = UNSEEN_KEEP) -> tuple[np.ndarray, dict]:
    """Sky dome (H, W, 3) float32 (world convention, sun excluded): the model corrected by observed pixels at infinity.

    Args:
        model_world: (H, W, 3) sky model (+ ground below the horizon) on the reference scale.
        observations: their ``far_*`` pixels are used.
        anchor_rgb: (3,) the seen mean colour's radiance: unseen directions below the highest seen far pixel are
            shrunk towards it (:func:`.fill.shrink_unseen`, keeping ``keep``); None: no shrinking.
    Returns:
        (dome, stats) with the global sky correction (per channel) and the observed fraction of the dome.
    """
    check_shape(model_world, ("H", "W", 3), "model_world")
    H, W = model_world.shape[:2]
    model = np.maximum(model_world.astype(np.float64), 1e-9)
    dirs = np.concatenate([o.far_dirs for o in observations]) if observations else np.zeros((0, 3))
    rgb = np.concatenate([o.far_radiance for o in observations]) if observations else np.zeros((0, 3))
    is_sky = np.concatenate([o.far_is_sky for o in observations]) if observations else np.zeros(0, bool)
    sat = np.concatenate([o.far_saturated for o in observations]) if observations else np.zeros(0, bool)
    stats = {"observed_fraction": 0.0, "sky_gain_rgb": [1.0, 1.0, 1.0], "observed_pixels": int(len(dirs))}
    if len(dirs) == 0:
        return model_world.astype(np.float32), stats
    lon = np.arctan2(dirs[:, 1], dirs[:, 0])
    lat = np.arcsin(np.clip(dirs[:, 2], -1, 1))
    col = np.clip(((lon / (2 * np.pi) + 0.5) * W).astype(np.int64), 0, W - 1)
    row = np.clip(((0.5 - lat / np.pi) * H).astype(np.int64), 0, H - 1)
    pix = row * W + col
    ok = ~sat
    count = np.bincount(pix[ok], minlength=H * W).astype(np.float64)
    sums = np.stack([np.bincount(pix[ok], rgb[ok, c], minlength=H * W) for c in range(3)], axis=1)
    observed = (count > 0).reshape(H, W)
    mean_obs = (sums / np.maximum(count, 1)[:, None]).reshape(H, W, 3)
    # clipped pixels: the sky is at least that bright there
    floor = np.zeros(H * W)
    if sat.any():
        np.maximum.at(floor, pix[sat], luminance(rgb[sat]))
    floor = floor.reshape(H, W)
    # sky model corrected by the observed/model ratio as a function of elevation (median per dome row over
    # the observed sky pixels, constant beyond the observed rows): the camera's sky (haze, white balance,
    # clouds) differs from the clear-sky model mostly with elevation
    upper = (np.arange(H) + 0.5 < H / 2)[:, None] & np.ones((1, W), bool)
    sel = is_sky & (dirs[:, 2] > 0.02)
    log_gain = np.zeros((H, W, 3))
    gain = np.ones(3)
    if sel.sum() >= 20:
        log_ratio = np.log(np.maximum(rgb[sel], 1e-9) / model.reshape(-1, 3)[pix[sel]])
        # a clipped channel only says "at least": its expected ratio given that bound under the prior of unclipped
        # skies (.sky_prior; the model itself only where the bound and the prior both say so); a clipped pixel's
        # other channels are measurements (the clipped ones hold the pixel's largest value, the saturation level)
        rgb_sel = rgb[sel]
        clipped_ch = sat[sel][:, None] & (rgb_sel >= rgb_sel.max(axis=1, keepdims=True) * (1.0 - 1e-6))
        log_ratio = censored_sky_log_gain(log_ratio, clipped_ch)
        gain = np.exp(np.median(log_ratio, axis=0))
        view = np.concatenate([np.full(len(o.far_dirs), i) for i, o in enumerate(observations)])[sel]
        log_gain = _sky_log_gain(log_ratio, row[sel], lon[sel], view, len(observations), H, W)
    log_gain = np.clip(log_gain, np.log(0.1), np.log(10.0))
    corrected = model * np.where(upper[..., None], np.exp(log_gain), 1.0)
    if anchor_rgb is not None:  # below the highest seen direction, what no camera saw: towards the seen mean
        elev = np.arcsin(np.clip(world_envmap_directions(H, W)[..., 2], -1.0, 1.0))
        # the top of what was seen: a high percentile, not the single highest pixel (noise must not move it)
        top = float(np.percentile(lat[~sat], 99.0)) if (~sat).any() else -np.pi / 2
        # a cell a clipped pixel fell in was seen: at least the clip level (the floor below), not unseen
        below = ((elev <= top) & ~(floor > 0))[..., None]
        # the clipped cells are seen too: at least the clip level there (censored: the corrected model's if brighter)
        clipped_cell = (floor > 0) & ~observed
        censored = np.maximum(corrected, (floor / np.maximum(luminance(corrected), 1e-12))[..., None] * corrected)
        band = band_anchor_rgb(observed | clipped_cell, np.where(clipped_cell[..., None], censored, mean_obs),
                               anchor_rgb)[:, None, :]
        corrected = np.where(below, shrink_unseen(corrected, band, keep), corrected)
    dome = blend_observed(corrected, observed, mean_obs, blur_deg)
    lum = np.maximum(luminance(dome), 1e-12)
    dome = dome * np.maximum(1.0, floor / lum)[..., None]
    stats.update(observed_fraction=float(observed.mean()), sky_gain_rgb=gain.tolist())
    return dome.astype(np.float32), stats
