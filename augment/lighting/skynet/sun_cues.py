"""Explicit physical cues to the sun's direction in one LDR image: the sun disc, and the clear-sky pattern.

Frames: image rays are unit vectors in the camera frame (OpenCV) or in a **heading frame** (z up, see
:mod:`.dome`); every direction returned is a unit vector towards the sun.  Images are uint8 RGB with the
contract's camera response; radiance is recovered with :func:`streetaug.augment.core.ldr_uint8_to_hdr` (up to an
unknown exposure and white balance, which every fit here is invariant to).

* :func:`detect_sun_disc` — the sun in view: a round clipped blob above the horizon, bounded by glare
  (not by occluders) that is brighter than the open sky beyond it; the centre of its largest inscribed
  disc back-projected through K.
* :func:`clear_sky_log_rgb` — the project's Preetham clear sky (:mod:`..sky`), vectorised over many
  candidate suns at once (the same formulas and coefficients as ``sky._clear_sky_shape``).
* :func:`sky_fit_loglik` — the sun out of view: fit that sky to the visible unsaturated sky pixels in
  log space, with a free offset per channel and elevation band (exposure, white balance, haze: any
  vertical profile) and the turbidity profiled out and a robust (Cauchy) loss against clouds; returns a
  log-likelihood over candidate sun directions.
* :func:`clipped_region_at`, :func:`glare_extent_deg` — the clipped region under a direction and how far it reaches (a sun placed in it is
  known only to within that).
* :func:`in_view_sky_loglik` — no disc found: directions that project onto bright but unclipped
  pixels of the image cannot hold the sun.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...core import PinholeCamera, ldr_uint8_to_hdr, luminance, scale_intrinsics
from .. import sky as _sky
from ..evidence import sky_mask

DISC_WIDTH_PX = 400  # the disc detector works on the image resized to this width
SATURATED = 0.97  # LDR (max channel) at or above which a pixel counts as clipped
DISC_MIN_RADIUS_DEG = 1.0  # smaller clipped blobs: lamps, glints, sky between leaves, a sun behind cloud
DISC_MAX_RADIUS_DEG = 12.0  # a clipped blob with a larger inscribed disc is a blown-out sky, not the sun
DISC_MIN_FALLOFF = 0.08  # glare ring minus the sky beyond it (LDR luminance)
DISC_MIN_ELEVATION_DEG = -1.0  # the disc centre is above this elevation
DISC_MIN_BORDER_R = 0.25  # the disc centre is at least this many radii inside the image border
FIT_TURBIDITIES = (2.0, 3.0, 5.0, 8.0)
FIT_MIN_ELEVATION_DEG = 3.0  # sky pixels below this (haze, horizon glare) are not fitted
FIT_MAX_PIXELS = 300
FIT_MIN_BLUE_RED = 0.75  # clear sky is bluer than red (linear); facades, clouds, haze are not fitted
FIT_CAUCHY_SCALE = 0.15  # log-radiance residual scale of the robust loss (clouds are outliers)
FIT_HAZE_SCALE_DEG = 8.0  # band_deg=None: horizon haze ~ exp(-elevation / this), strength fitted per channel
FIT_BAND_DEG = 3.0  # the nuisance is a free log offset per channel and elevation band of this width
FIT_N_EFF = 30.0  # independent pixels' worth of evidence in a fully covered, perfectly fitted sky
FIT_LOSS_FLOOR = 0.2  # the evidence is divided by (floor + best loss): a poorly fitting sky says less
FIT_FULL_COVERAGE = 0.25  # fraction of the image's pixels fitted for the full evidence (fewer: proportionally less)


# ----------------------------------------------------------------------------- sun in view


@dataclass(frozen=True)
class SunDisc:
    """A sun seen in the image.

    Attributes:
        direction_cam: (3,) unit vector towards the sun, camera frame.
        pixel_xy: (2,) its centroid in the input image's pixels (x right, y down, centres at integers).
        radius_deg: angular radius of the largest disc inscribed in the clipped blob.
        uncertainty_deg: half-angle of the 68 % cone around ``direction_cam``.
        halo: mean LDR luminance of the ring around the blob (glare), 0..1.
        clipped: the core touches the image border (its centre may be biased inwards).
    """

    direction_cam: np.ndarray
    pixel_xy: np.ndarray
    radius_deg: float
    uncertainty_deg: float
    halo: float
    clipped: bool


def detect_sun_disc(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray) -> SunDisc | None:
    """The sun in view, or None.

    Candidates are 8-connected blobs of clipped pixels (max channel >= ``SATURATED``, every channel
    >= 0.9 on average) above the horizon.  A sun's glare may merge with bright clouds or haze, so each
    blob is summarised by its largest inscribed disc (distance transform): centre = centroid of the
    pixels at >= 0.7 x the largest distance, radius r.  That core is a sun if

    * ``DISC_MIN_RADIUS_DEG`` <= r <= ``DISC_MAX_RADIUS_DEG`` (smaller: lamps, glints; larger: a
      blown-out sky);
    * the blob is round around it: in at least 6 of 8 sectors the clipped region ends within
      1.6 r + 0.5 deg (a band of horizon glow or a patch of sky extends far on several sides), and the
      unclipped pixels just outside it (up to 1.5 r + 0.5 deg) are bright (at most 10 % below LDR
      luminance 0.5: glare, not the edge of a tree or a building);
    * it glows: the ring [1.2 r + 0.3 deg, 2 r + 1 deg] is brighter than the open sky beyond it
      ([2 r + 4 deg, 2 r + 16 deg], sky pixels), on average by ``DISC_MIN_FALLOFF`` and in at least
      3/4 of its sectors;
    * the disc's centre is at least ``DISC_MIN_BORDER_R`` r inside the image border: a clipped blob whose
      inscribed disc (the border does not bound it) is centred on the border is the glare of a sun beyond
      it as often as a sun.

    Among suns the one with the largest r wins.

    Args:
        image_rgb: (H, W, 3) uint8 RGB (contract response).
        K: (3, 3) intrinsics of ``image_rgb`` (pixel centres at integers).
        up_cam: (3,) unit gravity up, camera frame.
    """
    H0, W0 = image_rgb.shape[:2]
    s = min(1.0, DISC_WIDTH_PX / W0)
    w, h = max(int(round(W0 * s)), 8), max(int(round(H0 * s)), 8)
    small = cv2.resize(np.ascontiguousarray(image_rgb), (w, h), interpolation=cv2.INTER_AREA) if s < 1 else image_rgb
    sx, sy = w / W0, h / H0
    Ks = scale_intrinsics(K, sx, sy)
    ldr = small.astype(np.float64) / 255.0
    hot = ((ldr.max(axis=-1) >= SATURATED) & (ldr.min(axis=-1) >= 0.8)).astype(np.uint8)
    if not hot.any():
        return None
    rays = PinholeCamera(Ks, w, h).rays()
    up = np.asarray(up_cam, dtype=np.float64) / np.linalg.norm(up_cam)
    lum = luminance(ldr)
    sky = sky_mask(ldr, np.arcsin(np.clip(rays @ up, -1.0, 1.0)), min_elevation_deg=0.0, min_lum=0.2,
                   bright_percentile=30.0, max_grad=0.2)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(hot, connectivity=8)
    # distance to the nearest unclipped pixel; OpenCV does not count the image border as one, so a sun
    # cut by the border keeps its full inscribed disc (centred as near the true centre as the image allows)
    dist = cv2.distanceTransform(hot, cv2.DIST_L2, 5)
    px_rad = 1.0 / np.sqrt(Ks[0, 0] * Ks[1, 1])  # angular size of a pixel near the centre (rad)
    best = None
    for lab in np.argsort(-stats[1:, cv2.CC_STAT_AREA])[:8] + 1:
        m = labels == lab
        if ldr[m].min(axis=-1).mean() < 0.9:  # a sun clips every channel
            continue
        r_px = float(dist[m].max())
        core = m & (dist >= 0.7 * r_px)
        ys, xs = np.nonzero(core)
        if min(xs.mean(), ys.mean(), w - 1 - xs.mean(), h - 1 - ys.mean()) < DISC_MIN_BORDER_R * r_px:
            continue  # the disc's centre is at the border: the glare of a sun beyond it, as often as a sun
        d = rays[core].sum(axis=0)
        d /= np.linalg.norm(d)
        r = r_px * px_rad * float(d[2]) ** 2  # pixels shrink (in angle) away from the centre
        if np.degrees(np.arcsin(np.clip(d @ up, -1, 1))) < DISC_MIN_ELEVATION_DEG:
            continue
        if not DISC_MIN_RADIUS_DEG <= np.degrees(r) <= DISC_MAX_RADIUS_DEG:
            continue
        halo = _glare_halo(rays, hot, lum, sky, m, d, r)
        if halo is None:
            continue
        clipped = bool(xs.min() == 0 or ys.min() == 0 or xs.max() == w - 1 or ys.max() == h - 1)
        if best is None or r > best[0]:
            best = (r, d, halo, clipped, core)
    if best is None:
        return None
    r, d, halo, clipped, core = best
    unc = max(1.0, 0.3 * np.degrees(r)) + (np.degrees(r) if clipped else 0.0)  # a cut core: centre biased inwards
    ys, xs = np.nonzero(core)
    pix = np.array([(xs.mean() + 0.5) / sx - 0.5, (ys.mean() + 0.5) / sy - 0.5])
    return SunDisc(d, pix, float(np.degrees(r)), float(unc), halo, clipped)


def _glare_halo(rays: np.ndarray, hot: np.ndarray, lum: np.ndarray, sky: np.ndarray, blob: np.ndarray,
                d: np.ndarray, r: float) -> float | None:
    """The mean LDR luminance of the glare ring around a clipped ``blob`` (h, w) bool whose inscribed disc has
    the centre ``d`` (3,) (camera frame) and radius ``r`` (rad), if the blob passes the roundness, bounded-by-glare
    and glow tests of :func:`detect_sun_disc`; else None. ``rays`` (h, w, 3), ``hot`` / ``sky`` (h, w) masks,
    ``lum`` (h, w) LDR luminance."""
    ang = np.arccos(np.clip(rays @ d, -1.0, 1.0))
    # round around the core: the clipped region ends near the disc in most directions
    sector_m = _ring_sectors(rays[blob], d)
    extent = np.array([ang[blob][sector_m == k].max() if np.any(sector_m == k) else 0.0 for k in range(8)])
    if np.sum(extent <= 1.6 * r + np.radians(0.5)) < 6:
        return None
    # bounded by glare, not by occluders (a patch of sky between trees or buildings)
    ring0 = (ang >= r) & (ang < 1.5 * r + np.radians(0.5)) & (hot == 0)
    if ring0.sum() < 4 or np.mean(lum[ring0] < 0.5) > 0.1:
        return None
    ring1 = (ang >= 1.2 * r + np.radians(0.3)) & (ang < 2.0 * r + np.radians(1.0))
    ring3 = (ang >= 2.0 * r + np.radians(4.0)) & (ang < 2.0 * r + np.radians(16.0)) & sky
    if ring1.sum() < 4 or ring3.sum() < 10:
        return None
    halo = float(lum[ring1].mean())
    beyond = float(np.median(lum[ring3]))
    sector = _ring_sectors(rays[ring1], d)
    lit = np.array([lum[ring1][sector == k].mean() >= beyond + 0.5 * DISC_MIN_FALLOFF
                    for k in range(8) if np.any(sector == k)])
    if halo - beyond < DISC_MIN_FALLOFF or len(lit) < 4 or lit.mean() < 0.75:
        return None
    return halo


def _ring_sectors(rays: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Sector index 0..7 (N,) of unit rays (N, 3) around the axis ``d`` (3,)."""
    a = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(d, a)
    phi = np.arctan2(rays @ b, rays @ a)
    return np.floor((phi + np.pi) / (2 * np.pi) * 8).astype(np.int64) % 8


# ----------------------------------------------------------------------------- clear sky


def _sun_geometry(dirs_h: np.ndarray, sun_dirs_h: np.ndarray):
    """(cos theta (N, 1), gamma (N, M) float32, cos^2 gamma (N, M) float32, sun zenith angle (M,)); suns below
    ``sky.MIN_SHAPE_ELEVATION_DEG`` are raised to it (as ``sky._sky_components`` does)."""
    sun = np.asarray(sun_dirs_h, dtype=np.float64)
    min_z = np.sin(np.radians(_sky.MIN_SHAPE_ELEVATION_DEG))
    horiz = sun[:, :2] / np.maximum(np.linalg.norm(sun[:, :2], axis=1, keepdims=True), 1e-9)
    z = np.maximum(sun[:, 2], min_z)
    sun = np.concatenate([horiz * np.sqrt(1.0 - z * z)[:, None], z[:, None]], axis=1)
    theta_s = np.arccos(np.clip(sun[:, 2], -1.0, 1.0))
    cos_t = np.maximum(np.clip(dirs_h[:, 2], 0.0, 1.0), 1e-3)[:, None]
    cos_g = np.clip(dirs_h @ sun.T, -1.0, 1.0).astype(np.float32)
    return cos_t, np.arccos(cos_g), cos_g * cos_g, theta_s


def clear_sky_log_rgb(dirs_h: np.ndarray, sun_dirs_h: np.ndarray, turbidity: float, geometry=None) -> np.ndarray:
    """Log of the relative Preetham clear-sky RGB (N, M, 3) float32 for N sky directions and M candidate suns.

    Same model as :func:`..sky._clear_sky_shape` (Perez distribution of Y, x, y with Preetham's
    turbidity coefficients, zenith chromaticity polynomials, xyY -> linear sRGB), vectorised over the
    suns.  Only relative values matter (each sun's zenith normalisation is a constant per channel).

    Args:
        dirs_h: (N, 3) unit directions (z up), above the horizon.
        sun_dirs_h: (M, 3) unit sun directions (z up); suns below 1 deg are evaluated at 1 deg.
        turbidity: Preetham turbidity in [1.7, 12].
        geometry: ``_sun_geometry(dirs_h, sun_dirs_h)`` if already computed (shared across turbidities).
    """
    T = float(turbidity)
    cos_t, gamma, cos_g2, theta_s = geometry or _sun_geometry(dirs_h, sun_dirs_h)
    tvec = np.array([T * T, T, 1.0])
    svec = np.stack([theta_s**3, theta_s**2, theta_s, np.ones_like(theta_s)])  # (4, M)
    x_z = tvec @ _sky._ZENITH_X @ svec
    y_z = tvec @ _sky._ZENITH_Y @ svec
    out = []
    for zenith_value, table in ((np.ones_like(theta_s), _sky._PEREZ_Y), (x_z, _sky._PEREZ_X), (y_z, _sky._PEREZ_YC)):
        A, B, C, D, E = table[:, 0] * T + table[:, 1]
        f0 = _sky._perez(np.ones_like(theta_s), theta_s, (A, B, C, D, E))  # (M,) at the zenith
        # _sky._perez written out with cos(gamma) computed once (N x M is the costly part)
        horizon = (1.0 + A * np.exp(B / cos_t)).astype(np.float32)  # (N, 1)
        perez = horizon * (1.0 + C * np.exp(np.float32(D) * gamma) + np.float32(E) * cos_g2)
        out.append(perez * (zenith_value / f0)[None].astype(np.float32))
    Y, x, y = out
    y = np.maximum(y, 1e-6)
    X, Z = x / y * Y, (1.0 - x - y) / y * Y
    floor = 1e-4 * np.maximum(Y, 1e-9)
    M = _sky._XYZ_TO_SRGB.astype(np.float32)
    return np.stack([np.log(np.maximum(M[c, 0] * X + M[c, 1] * Y + M[c, 2] * Z, floor)) for c in range(3)], axis=-1)


def _nuisance_residual(r0: np.ndarray, onehot: np.ndarray | None, haze: np.ndarray, c: np.float32) -> np.ndarray:
    """The residual (N, M, 3) of log sky pixels minus the clear-sky model ``r0`` (N, M, 3) after removing the
    nuisance, fitted by 3 rounds of Cauchy-reweighted least squares (clouds are outliers): a free offset per
    elevation band (``onehot`` (N, bands) membership), or, without bands, an exposure plus a horizon haze
    ``b >= 0`` times ``haze`` (N, 1, 1); per candidate and channel."""
    wts = np.ones_like(r0)
    for _ in range(3):
        if onehot is not None:  # per band, candidate and channel: the weighted mean residual
            n = len(r0)
            sw = onehot.T @ wts.reshape(n, -1)
            sr = onehot.T @ (wts * r0).reshape(n, -1)
            r = r0 - (onehot @ (sr / np.maximum(sw, 1e-6))).reshape(r0.shape)
        else:
            sw, sh, shh = wts.sum(0), (wts * haze).sum(0), (wts * haze * haze).sum(0)
            sr, shr = (wts * r0).sum(0), (wts * haze * r0).sum(0)
            b = np.maximum((sw * shr - sh * sr) / np.maximum(sw * shh - sh * sh, 1e-6), 0.0)
            r = r0 - ((sr - b * sh) / sw)[None] - b[None] * haze
        wts = 1.0 / (1.0 + (r / c) ** 2)
    return r


def sky_fit_loglik(image_small: np.ndarray, rays_h: np.ndarray, sky_mask: np.ndarray, sun_dirs_h: np.ndarray,
                   turbidities: tuple[float, ...] = FIT_TURBIDITIES, temperature: float = 1.0,
                   max_pixels: int = FIT_MAX_PIXELS, band_deg: float | None = FIT_BAND_DEG) -> tuple[np.ndarray, dict]:
    """Log-likelihood (M,) of candidate suns given the visible clear-sky pattern (0 = best candidate).

    The unsaturated sky pixels (``sky_mask``, LDR 0.03..0.9, above ``FIT_MIN_ELEVATION_DEG``, blue/red
    >= ``FIT_MIN_BLUE_RED``: no brick or beige facades) give ``y = log HDR`` per channel (at most
    ``max_pixels``, evenly subsampled).  For each candidate sun and turbidity the residual
    ``r = y - log(clear sky) - g(elevation)`` is scored with a Cauchy loss ``log(1 + (r / c)^2)``
    (c = ``FIT_CAUCHY_SCALE``) averaged over the pixels.  The nuisance ``g`` (per channel, fitted by
    iteratively re-weighted least squares: clouds are outliers) is, by default, a free offset per
    elevation band of ``band_deg``: it absorbs the unknown exposure and white balance *and* any vertical
    profile (horizon haze, fog, a real sky's brightness-vs-elevation that Preetham gets wrong), so only the
    sky's variation along each band (with azimuth: brighter towards the sun) and its change from band to
    band locate the sun.  ``band_deg=None`` is round 1's nuisance: an exposure ``a`` plus a horizon haze
    ``b >= 0`` times ``exp(-elevation / FIT_HAZE_SCALE_DEG)``.  The turbidity is profiled out (minimum over
    ``turbidities``).  With ``L`` that loss:

        loglik = -FIT_N_EFF * coverage * (L - L_min) / (temperature * (FIT_LOSS_FLOOR + L_min))

    where coverage = min(1, fitted fraction of the image / ``FIT_FULL_COVERAGE``): a small or badly
    fitting sky patch says little (neighbouring pixels are far from independent, and facades or clouds
    taken for sky fit badly).  Zeros (no evidence) if fewer than 60 usable pixels.

    Args:
        image_small: (h, w, 3) uint8 image.
        rays_h: (h, w, 3) unit heading-frame rays of its pixels.
        sky_mask: (h, w) bool sky pixels.
        sun_dirs_h: (M, 3) candidate sun directions (heading frame).
        temperature: divides the log-likelihood (calibration).
        band_deg: width (deg) of the elevation bands of the nuisance offsets; None: exposure + haze.
    """
    ldr = image_small.astype(np.float64) / 255.0
    elev_ok = rays_h[..., 2] > np.sin(np.radians(FIT_MIN_ELEVATION_DEG))
    blue = image_small[..., 2].astype(np.float64) >= FIT_MIN_BLUE_RED ** (1 / 2.2) * image_small[..., 0]
    ok = sky_mask & elev_ok & blue & (ldr.max(axis=-1) < 0.9) & (ldr.min(axis=-1) > 0.03)
    info: dict = {"fit_pixels": int(ok.sum())}
    M = len(sun_dirs_h)
    if ok.sum() < 60:
        return np.zeros(M), info
    idx = np.flatnonzero(ok.ravel())
    if len(idx) > max_pixels:
        idx = idx[np.linspace(0, len(idx) - 1, max_pixels).astype(np.int64)]
    d = rays_h.reshape(-1, 3)[idx].astype(np.float64)
    y = np.log(np.maximum(ldr_uint8_to_hdr(image_small.reshape(-1, 3)[idx][None])[0].astype(np.float64), 1e-5))
    y = y.astype(np.float32)
    elevation = np.arcsin(np.clip(d[:, 2], 0.0, 1.0))
    onehot = None
    if band_deg is not None:
        band = np.floor(np.degrees(elevation) / band_deg).astype(np.int64)
        _, band = np.unique(band, return_inverse=True)
        onehot = np.eye(band.max() + 1, dtype=np.float32)[band]  # (N, bands) membership
    best = np.full(M, np.inf)
    best_t = np.zeros(M)
    c = np.float32(FIT_CAUCHY_SCALE)
    geometry = _sun_geometry(d, sun_dirs_h)
    # band_deg=None: nuisance per channel = exposure (a constant) + horizon haze, (b >= 0) x haze(elevation)
    haze = np.exp(-elevation / np.radians(FIT_HAZE_SCALE_DEG)).astype(np.float32)
    haze = haze[:, None, None]
    for T in turbidities:
        r = _nuisance_residual(y[:, None, :] - clear_sky_log_rgb(d, sun_dirs_h, T, geometry),
                               onehot if band_deg is not None else None, haze, c)
        loss = np.log1p((r / c) ** 2).sum(axis=(0, 2), dtype=np.float64) / len(idx)
        better = loss < best
        best = np.where(better, loss, best)
        best_t = np.where(better, T, best_t)
    coverage = min(1.0, ok.mean() / FIT_FULL_COVERAGE)
    loglik = -FIT_N_EFF * coverage * (best - best.min()) / (max(temperature, 1e-6) * (FIT_LOSS_FLOOR + best.min()))
    info.update(fit_loss=float(best.min()), fit_contrast=float(best.max() - best.min()), coverage=coverage,
                turbidity=float(best_t[int(np.argmin(best))]))
    return loglik, info


def in_view_sky_loglik(sun_dirs_h: np.ndarray, R_heading_from_cam: np.ndarray, K_small: np.ndarray,
                       no_sun: np.ndarray, penalty: float = 4.0) -> np.ndarray:
    """(M,) ``-penalty`` for candidate suns that project onto ``no_sun`` pixels of the image, else 0.

    Args:
        sun_dirs_h: (M, 3) candidate directions (heading frame).
        R_heading_from_cam: (3, 3).
        K_small: (3, 3) intrinsics of the ``no_sun`` mask's image.
        no_sun: (h, w) bool pixels that cannot be on the sun (e.g. bright but unclipped sky: the sun
            would clip them; dark pixels may hide it behind an occluder and should stay False).
    """
    h, w = no_sun.shape
    d_cam = np.asarray(sun_dirs_h, dtype=np.float64) @ np.asarray(R_heading_from_cam)  # rows: R^T d
    front = d_cam[:, 2] > 1e-3
    uv = d_cam @ np.asarray(K_small).T
    u = np.round(uv[:, 0] / np.where(front, uv[:, 2], 1.0)).astype(np.int64)
    v = np.round(uv[:, 1] / np.where(front, uv[:, 2], 1.0)).astype(np.int64)
    inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    hit = np.zeros(len(d_cam), bool)
    hit[inside] = no_sun[v[inside], u[inside]]
    return np.where(hit, -penalty, 0.0)


def clipped_region_at(image_small: np.ndarray, K_small: np.ndarray, d_cam: np.ndarray) -> np.ndarray | None:
    """(h, w) bool: the 8-connected clipped region (max channel >= ``SATURATED``) of ``image_small`` (h, w, 3)
    uint8 (intrinsics ``K_small``) at the projected pixel of the camera-frame direction ``d_cam`` (3,) (or within
    one pixel of it); None if it is behind the camera, out of the image or not on a clipped pixel."""
    d = np.asarray(d_cam, dtype=np.float64)
    if d[2] <= 1e-3:
        return None
    h, w = image_small.shape[:2]
    uv = np.asarray(K_small) @ d
    u, v = int(round(uv[0] / uv[2])), int(round(uv[1] / uv[2]))
    if not (0 <= u < w and 0 <= v < h):
        return None
    hot = (image_small.max(axis=-1) >= SATURATED * 255).astype(np.uint8)
    _, labels = cv2.connectedComponents(hot, connectivity=8)
    patch = labels[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2]
    ids = np.unique(patch[patch > 0])
    return np.isin(labels, ids) if len(ids) else None


def glare_extent_deg(region: np.ndarray, K_small: np.ndarray, d_cam: np.ndarray) -> float:
    """Angular radius (deg) of the clipped ``region`` (h, w) bool (:func:`clipped_region_at` of ``d_cam``).

    The largest angle between the camera-frame direction ``d_cam`` (3,) and the rays of the region's pixels
    (intrinsics ``K_small``).  A sun placed inside a clipped glare is only known to within that region: a
    compact blob pins it, a long band of horizon glow does not.
    """
    h, w = region.shape
    d = np.asarray(d_cam, dtype=np.float64)
    rays = PinholeCamera(K_small, w, h).rays()[region]
    return float(np.degrees(np.arccos(np.clip(rays @ (d / np.linalg.norm(d)), -1.0, 1.0)).max()))


def glare_centre_cam(region: np.ndarray, K_small: np.ndarray) -> np.ndarray:
    """Unit camera-frame direction (3,) of the centre of the clipped ``region`` (h, w) bool (intrinsics
    ``K_small``; :func:`clipped_region_at`).

    The centre of the region's largest inscribed disc (distance transform; the image border does not bound
    it), as :func:`detect_sun_disc` takes it: the mean ray of the pixels at >= 0.7 x the largest distance.
    A sun in view whose glare clips a region too large or too ragged to pass as a disc sits near its
    middle (the glare falls off with the angle from the sun), nearer than a sky fit places it.
    """
    h, w = region.shape
    dist = cv2.distanceTransform(region.astype(np.uint8), cv2.DIST_L2, 5)
    core = dist >= 0.7 * dist.max()
    c = PinholeCamera(K_small, w, h).rays()[core].sum(axis=0)
    return c / np.linalg.norm(c)


def glare_region_features(image_small: np.ndarray, K_small: np.ndarray, region: np.ndarray, centre_cam: np.ndarray,
                          up_cam: np.ndarray, sky: np.ndarray) -> dict:
    """What a clipped ``region`` (h, w) bool of ``image_small`` (h, w, 3) uint8 (intrinsics ``K_small``) looks like
    around its centre ``centre_cam`` (3,) (:func:`glare_centre_cam`); ``up_cam`` (3,) unit gravity up, ``sky``
    (h, w) bool the image's sky pixels.

    Returns floats: ``extent_deg`` (largest angle from the centre to a region pixel), ``inscribed_deg`` (radius
    of its largest inscribed disc), ``fill`` (its pixels' share of the cone of ``extent_deg``: 1 for a disc, small
    for a ragged or elongated patch), ``border`` (share of its pixels on the image border); around it, the
    unclipped pixels above the horizon in the near ring (``extent`` to ``extent + 8 deg``) and the sky pixels in
    the far ring (``extent + 15 deg`` to ``extent + 35 deg``): ``near_lum`` (median LDR luminance), ``near_p90``
    (its 90th percentile: the glare where occluders fill most of the ring), ``near_dark`` (share darker than LDR
    0.5), ``far_lum`` (median), ``falloff`` = near_lum - far_lum, ``falloff_p90`` = near_p90 - far_lum and
    ``falloff_sky`` (median of the near ring's sky pixels - far_lum), and the same three as log ratios of linear
    radiance (exposure-invariant): ``glow_log_ratio``, ``glow_log_ratio_p90``, ``glow_log_ratio_sky``. A sun's
    glare falls off with the angle from it; an overcast sky's clipped patch sits in an even sky. NaN where a ring
    holds fewer than 8 pixels.
    """
    h, w = region.shape
    rays = PinholeCamera(K_small, w, h).rays()
    c = np.asarray(centre_cam, dtype=np.float64)
    ang = np.degrees(np.arccos(np.clip(rays @ (c / np.linalg.norm(c)), -1.0, 1.0)))
    extent = float(ang[region].max())
    dist = cv2.distanceTransform(region.astype(np.uint8), cv2.DIST_L2, 5)
    px_deg = np.degrees(1.0 / np.sqrt(K_small[0, 0] * K_small[1, 1]))
    border = np.zeros((h, w), bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    ldr = image_small.astype(np.float64) / 255.0
    lum = luminance(ldr)
    open_ = (ldr.max(axis=-1) < SATURATED) & (rays @ np.asarray(up_cam, dtype=np.float64) > 0.0)
    near = open_ & (ang >= extent) & (ang < extent + 8.0)
    far = open_ & sky & (ang >= extent + 15.0) & (ang < extent + 35.0)
    nan = float("nan")
    stat = lambda x, m, f: float(f(x[m])) if m.sum() >= 8 else nan  # noqa: E731
    p90 = lambda x: np.percentile(x, 90)  # noqa: E731
    near_lum, near_p90, far_lum = stat(lum, near, np.median), stat(lum, near, p90), stat(lum, far, np.median)
    hdr = luminance(ldr_uint8_to_hdr(image_small).astype(np.float64))
    log_far = np.log(max(stat(hdr, far, np.median), 1e-9))
    return {"extent_deg": extent, "inscribed_deg": float(dist.max()) * px_deg,
            "fill": float(region.sum() / max((ang <= extent).sum(), 1)),
            "border": float(region[border].sum() / max(region.sum(), 1)),
            "near_lum": near_lum, "near_p90": near_p90,
            "near_dark": float(np.mean(lum[near] < 0.5)) if near.any() else nan,
            "far_lum": far_lum, "falloff": near_lum - far_lum, "falloff_p90": near_p90 - far_lum,
            "falloff_sky": stat(lum, near & sky, np.median) - far_lum,
            "glow_log_ratio": np.log(max(stat(hdr, near, np.median), 1e-9)) - log_far,
            "glow_log_ratio_p90": np.log(max(stat(hdr, near, p90), 1e-9)) - log_far,
            "glow_log_ratio_sky": np.log(max(stat(hdr, near & sky, np.median), 1e-9)) - log_far}


def sky_features(image_small: np.ndarray, rays_h: np.ndarray, sky: np.ndarray) -> dict:
    """Summary of the sky of ``image_small`` (h, w, 3) uint8: ``sky`` (h, w) bool its sky pixels, ``rays_h``
    (h, w, 3) heading-frame rays.

    Returns floats: ``sky_fraction`` (of the image), ``clipped_fraction`` (clipped pixels above the horizon, of
    the image), ``sky_lum_median`` / ``sky_lum_iqr`` (LDR luminance of the sky pixels), ``sky_blue`` (median of
    (B - R) / (B + R) in linear radiance over the unclipped sky pixels: ~0.3-0.6 for a clear sky, ~0 for grey
    cloud), NaN when there is no sky.
    """
    ldr = image_small.astype(np.float64) / 255.0
    above = rays_h[..., 2] > 0.0
    clipped = ldr.max(axis=-1) >= SATURATED
    out = {"sky_fraction": float(sky.mean()), "clipped_fraction": float((clipped & above).mean())}
    lum = luminance(ldr)[sky]
    open_sky = sky & ~clipped
    if sky.sum() < 8:
        return out | {"sky_lum_median": float("nan"), "sky_lum_iqr": float("nan"), "sky_blue": float("nan")}
    q25, q50, q75 = np.percentile(lum, [25, 50, 75])
    blue = float("nan")
    if open_sky.sum() >= 8:
        hdr = ldr_uint8_to_hdr(image_small[open_sky][None])[0].astype(np.float64)
        blue = float(np.median((hdr[:, 2] - hdr[:, 0]) / np.maximum(hdr[:, 2] + hdr[:, 0], 1e-6)))
    return out | {"sky_lum_median": float(q50), "sky_lum_iqr": float(q75 - q25), "sky_blue": blue}
