"""The sky dome's unseen directions below the highest seen far pixel: filled from the seen far pixels of the same
elevation band (sky between the trees), not from the mean colour of everything seen (road, canopy)."""

from __future__ import annotations

import numpy as np

from streetaug.augment.core import hdr_to_ldr, luminance
from streetaug.augment.lighting.observe import ViewObservation
from streetaug.augment.lighting.skydome import band_anchor_rgb, build_sky_dome
from streetaug.augment.lighting.volume import world_envmap_directions


def _obs(dirs: np.ndarray, rgb: np.ndarray, sky: np.ndarray) -> ViewObservation:
    n = len(dirs)
    return ViewObservation("CAM", np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros((0, 3)), np.zeros(0, bool),
                           dirs, rgb.astype(np.float32), sky, np.zeros(n, bool), np.zeros(3))


def _dirs(az_rad: np.ndarray, el_rad: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(el_rad) * np.cos(az_rad), np.cos(el_rad) * np.sin(az_rad), np.sin(el_rad)], 1)


def test_unseen_sky_band_takes_the_seen_sky_of_its_elevation():
    """Bright sky seen at 5-20 deg through a 40 deg wide gap, a dark anchor (the scene's mean colour): the unseen
    azimuths of that band are filled close to the seen sky, far brighter than the anchor-only fill."""
    H, W = 64, 256
    model = np.full((H, W, 3), 0.5, np.float32)
    rng = np.random.default_rng(1)
    az, el = rng.uniform(-0.35, 0.35, 3000), np.radians(rng.uniform(5.0, 20.0, 3000))
    sky_rgb = np.full((3000, 3), 3.0)  # bright overcast sky on this scale
    anchor = np.full(3, 0.05)  # the dark seen mean colour (road, canopy)
    dome, _ = build_sky_dome(model, [_obs(_dirs(az, el), sky_rgb, np.ones(3000, bool))], anchor_rgb=anchor)
    d = world_envmap_directions(H, W)
    lon = np.arctan2(d[..., 1], d[..., 0])
    elev = np.degrees(np.arcsin(d[..., 2]))
    unseen_band = (np.abs(lon) > 2.0) & (elev > 8.0) & (elev < 17.0)
    ldr = hdr_to_ldr(luminance(dome[unseen_band]))
    assert np.median(ldr) > 0.8 * float(hdr_to_ldr(luminance(sky_rgb[0])))
    assert np.median(ldr) > 2.0 * float(hdr_to_ldr(luminance(anchor)))


def test_band_anchor_falls_back_to_the_anchor_where_nothing_was_seen():
    H, W = 64, 256
    observed = np.zeros((H, W), bool)
    observed[20:24, :100] = True  # ~11-22 deg elevation, 100 cells a row
    mean_obs = np.full((H, W, 3), 0.3)
    anchor = np.full(3, 0.1)
    band = band_anchor_rgb(observed, mean_obs, anchor)
    assert np.allclose(band[22], 0.3, rtol=0.15)  # a well-seen band: its own mean
    assert np.allclose(band[55], anchor, rtol=1e-6)  # far below anything seen: the anchor
    few = np.zeros((H, W), bool)
    few[22, :3] = True  # three cells: mostly the anchor
    assert luminance(band_anchor_rgb(few, mean_obs, anchor)[22]) < 0.5 * luminance(band[22])


def test_a_clipped_sky_band_is_filled_as_brightly_as_one_seen_at_the_clip_level():
    """The band of sky seen through the gap clipped (a brighter exposure: each pixel only "at least the clip
    level"), dark canopy seen up to 30 deg elsewhere: the band's unseen azimuths are filled at least as brightly
    as when the same pixels are measured at the clip level (a clipped cell is seen; its band's colour is the
    sky's), not shrunk to the canopy's anchor (before: LDR 0.30 against 0.58)."""
    from streetaug.augment.core import SATURATION_RADIANCE

    H, W = 64, 256
    model = np.full((H, W, 3), 0.5, np.float32)
    rng = np.random.default_rng(1)
    az, el = rng.uniform(-0.35, 0.35, 3000), np.radians(rng.uniform(5.0, 20.0, 3000))
    sky_rgb = np.broadcast_to(np.asarray(SATURATION_RADIANCE, np.float64), (3000, 3))
    az_t, el_t = rng.uniform(2.5, 3.5, 3000), np.radians(rng.uniform(0.0, 30.0, 3000))
    dirs = np.concatenate([_dirs(az, el), _dirs(az_t, el_t)])
    rgb = np.concatenate([sky_rgb, np.full((3000, 3), 0.03)]).astype(np.float32)
    sky = np.r_[np.ones(3000, bool), np.zeros(3000, bool)]
    d = world_envmap_directions(H, W)
    lon = np.arctan2(d[..., 1], d[..., 0])
    elev = np.degrees(np.arcsin(d[..., 2]))
    unseen_band = (np.abs(lon) > 0.8) & (np.abs(lon) < 2.2) & (elev > 8.0) & (elev < 17.0)
    fills = []
    for clipped in (sky, np.zeros(6000, bool)):
        obs = ViewObservation("CAM", np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros((0, 3)),
                              np.zeros(0, bool), dirs, rgb, sky, clipped, np.zeros(3))
        dome, _ = build_sky_dome(model, [obs], anchor_rgb=np.full(3, 0.03))
        fills.append(float(np.median(hdr_to_ldr(luminance(dome[unseen_band])))))
    assert fills[0] >= 0.98 * fills[1], fills
