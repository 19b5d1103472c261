"""L1's map from the pixels the cameras see (augment/lighting/image_dome.py), on synthetic images."""

from __future__ import annotations

import numpy as np

from streetaug.augment.core import (SATURATION_LDR, camera_dir_to_lonlat, hdr_to_ldr, ldr_to_hdr, lonlat_to_camera_dir,
                                    luminance)
from streetaug.augment.lighting.evidence import prepare_image
from streetaug.augment.lighting.image_dome import band_log_gains, image_corrected_envmap, seen_pixels
from streetaug.augment.lighting.light import DistantLight

H_MAP, W_MAP = 128, 256
UP = np.array([0.0, -1.0, 0.0])  # a level camera


def _K(w=640, h=360, fov_deg=70.0):
    f = 0.5 * w / np.tan(np.radians(fov_deg) / 2)
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])


def _image(w=640, h=360, seed=0):
    """Rows: bright sky (top third), a dark facade band, a mid-grey road (bottom third), with some texture."""
    rng = np.random.default_rng(seed)
    img = np.empty((h, w, 3), np.uint8)
    img[: h // 3] = (200, 210, 225)
    img[h // 3 : 2 * h // 3] = (70, 60, 50)
    img[2 * h // 3 :] = (120, 120, 118)
    noise = rng.integers(-12, 13, size=(h, w, 1))
    return np.clip(img.astype(int) + noise, 0, 254).astype(np.uint8)


def _model(value=0.5):
    return np.full((H_MAP, W_MAP, 3), value, np.float32)


def _psnr(a, b):
    return float(10 * np.log10(1.0 / np.mean((a - b) ** 2)))


def test_the_map_reproduces_the_image_from_the_camera_centre():
    img, K = _image(), _K()
    work = prepare_image(img, K, UP)
    env, stats = image_corrected_envmap(_model(), seen_pixels(work), UP)
    rays = work.rays_cam.reshape(-1, 3)
    pred = hdr_to_ldr(DistantLight(env).radiance(np.zeros_like(rays), rays)).reshape(work.ldr.shape)
    before = hdr_to_ldr(DistantLight(_model()).radiance(np.zeros_like(rays), rays)).reshape(work.ldr.shape)
    assert _psnr(pred, work.ldr) > 25.0  # the map on the image's scale where seen
    assert _psnr(before, work.ldr) < 15.0  # the uncorrected model is far off (the test can fail)
    assert 0.02 < stats["seen_fraction"] < 0.3


def _behind(env, elev_deg):
    """Radiance of a map straight behind the camera at an elevation (deg)."""
    return DistantLight(env).radiance(
        np.zeros((1, 3)), lonlat_to_camera_dir(np.array([np.pi]), np.radians(np.array([elev_deg]))))[0]


def test_unseen_directions_follow_the_seen_elevation_bands():
    img, K = _image(), _K()
    work = prepare_image(img, K, UP)
    env, _ = image_corrected_envmap(_model(), seen_pixels(work), UP, keep=1.0, ground_keep=1.0,
                                    symmetry_weight=0.0)  # the bands alone, no shrinking
    behind = lambda elev_deg: _behind(env, elev_deg)  # noqa: E731
    facade = ldr_to_hdr(np.array([70, 60, 50]) / 255.0)
    road = ldr_to_hdr(np.array([120, 120, 118]) / 255.0)
    sky = ldr_to_hdr(np.array([200, 210, 225]) / 255.0)
    # the facade band and the road continue behind the camera; the zenith is the seen sky
    assert np.allclose(behind(0.0), facade, rtol=0.35)
    assert np.allclose(behind(-40.0), road, rtol=0.25)
    assert np.allclose(behind(80.0), sky, rtol=0.25)
    assert behind(80.0)[2] > 3 * behind(0.0)[2]


def test_unseen_directions_below_the_sky_shrink_towards_the_seen_mean_colour():
    img, K = _image(), _K()
    work = prepare_image(img, K, UP)
    env0, _ = image_corrected_envmap(_model(), seen_pixels(work), UP, keep=0.0, ground_keep=0.0, symmetry_weight=0.0)
    env_half, _ = image_corrected_envmap(_model(), seen_pixels(work), UP, keep=0.5, ground_keep=0.5,
                                         symmetry_weight=0.0)
    env1, _ = image_corrected_envmap(_model(), seen_pixels(work), UP, keep=1.0, ground_keep=1.0, symmetry_weight=0.0)
    mean_colour = ldr_to_hdr(img.reshape(-1, 3).mean(axis=0) / 255.0)
    assert np.allclose(_behind(env0, 0.0), mean_colour, rtol=0.1)  # keep 0: the seen mean colour
    assert np.allclose(_behind(env0, -40.0), mean_colour, rtol=0.1)
    geo = np.sqrt(_behind(env0, 0.0) * _behind(env1, 0.0))  # keep 0.5: halfway in log
    assert np.allclose(_behind(env_half, 0.0), geo, rtol=0.05)
    # the zenith (above every seen elevation) is the sky's, whatever keep
    assert np.allclose(_behind(env0, 80.0), _behind(env1, 80.0), rtol=1e-4)
    # what was seen (away from the image's border, where the map's bilinear lookup mixes in unseen cells) is
    # unchanged
    rays = work.rays_cam[20:-20, 20:-20].reshape(-1, 3)[::97]
    assert np.allclose(DistantLight(env0).radiance(np.zeros_like(rays), rays),
                       DistantLight(env1).radiance(np.zeros_like(rays), rays), rtol=0.05, atol=1e-3)


def test_clipped_pixels_are_lower_bounds():
    img, K = _image(), _K()
    img[: 360 // 3, 200:440] = 255  # clipped sky
    work = prepare_image(img, K, UP)
    env, stats = image_corrected_envmap(_model(0.01), seen_pixels(work), UP)
    assert stats["clipped_pixels"] > 0
    lon, lat = camera_dir_to_lonlat(np.array([[0.0, -0.3, 1.0]]))  # 17 deg up ahead: inside the clipped patch
    v = DistantLight(env).radiance(np.zeros((1, 3)), lonlat_to_camera_dir(lon, lat))[0]
    # at least the saturation level (bilinear lookups at the patch edge mix in a little of its neighbours)
    assert luminance(v) >= 0.9 * luminance(ldr_to_hdr(np.full(3, SATURATION_LDR)))
    assert luminance(v) > 50 * 0.01  # far above the model it replaced


def test_two_cameras_fill_one_map_on_the_reference_scale():
    img, K = _image(), _K()
    back = np.clip(img.astype(int) // 2, 0, 255).astype(np.uint8)  # the rear camera sees the same, darker
    work_f = prepare_image(img, K, UP)
    work_b = prepare_image(back, K, UP)
    R_front_from_back = np.diag([-1.0, 1.0, -1.0])  # 180 deg about the up axis
    ratio_b = float(np.median(ldr_to_hdr(back / 255.0) / np.maximum(ldr_to_hdr(img / 255.0), 1e-6)))
    env, stats = image_corrected_envmap(
        _model(), [seen_pixels(work_f), seen_pixels(work_b, R_front_from_back, 1.0 / ratio_b)], UP)
    one, _ = image_corrected_envmap(_model(), seen_pixels(work_f), UP)
    d = lonlat_to_camera_dir(np.array([np.pi]), np.array([0.0]))  # behind, horizon: the rear camera's centre
    v = DistantLight(env).radiance(np.zeros((1, 3)), d)[0]
    facade = ldr_to_hdr(np.array([70, 60, 50]) / 255.0)
    assert np.allclose(v, facade, rtol=0.2)  # the rear camera's pixels, back on the front camera's scale
    assert stats["seen_fraction"] > 1.8 * image_corrected_envmap(_model(), seen_pixels(work_f), UP)[1]["seen_fraction"]
    assert not np.allclose(env, one)


def test_band_gains_interpolate_and_extrapolate():
    elev = np.array([-10.0, -10.0, -10.0, 10.0, 10.0, 10.0])
    log_ratio = np.log(np.array([[2.0] * 3] * 3 + [[0.5] * 3] * 3))
    g = band_log_gains(log_ratio, elev, np.array([-60.0, -10.0, 0.0, 10.0, 80.0]), np.log(np.full(3, 4.0)))
    assert np.allclose(np.exp(g[0]), 2.0) and np.allclose(np.exp(g[1]), 2.0)  # below: the lowest band
    assert 0.5 < np.exp(g[2, 0]) < 2.0  # between bands: interpolated
    assert np.allclose(np.exp(g[4]), 4.0)  # above the highest band: the sky's ratio


def _road_image(w=640, h=360, seed=1):
    """Bright sky (top third), a dark facade band, a reddish road (bottom third): the road unlike the mean."""
    img = _image(w, h, seed)
    img[2 * h // 3 :] = np.clip(np.array([150, 95, 80]) + (img[2 * h // 3 :].astype(int) - 120), 0, 254)
    return img


def test_the_street_symmetry_puts_the_road_colour_behind_the_camera():
    img, K = _road_image(), _K()
    work = prepare_image(img, K, UP)
    px = seen_pixels(work)
    plain, _ = image_corrected_envmap(_model(), px, UP, ground_keep=0.0, symmetry_weight=0.0)
    full, _ = image_corrected_envmap(_model(), px, UP, ground_keep=0.0, symmetry_weight=1.0)
    half, _ = image_corrected_envmap(_model(), px, UP, ground_keep=0.0, symmetry_weight=0.5)
    road = ldr_to_hdr(np.array([150, 95, 80]) / 255.0)
    mean_colour = ldr_to_hdr(img.reshape(-1, 3).mean(axis=0) / 255.0)
    # 20 deg below the horizon behind the camera: the mirror image of the road seen ahead (smoothed over
    # SYMMETRY_BLUR_DEG, so a little of the facade band above it mixes in)
    assert np.allclose(_behind(plain, -20.0), mean_colour, rtol=0.1)  # without the symmetry: the mean colour
    assert np.allclose(_behind(full, -20.0), road, rtol=0.2)
    assert _behind(full, -20.0)[0] / _behind(full, -20.0)[2] > 3.0  # red: road, not the grey mean
    log_gap = lambda env: np.abs(np.log(_behind(env, -20.0) / road)).mean()  # noqa: E731
    assert log_gap(half) < 0.7 * log_gap(plain)  # halfway in log
    # behind at the facade band's elevation: darker than the road below it and the sky above it
    lum = lambda env, e: float(luminance(_behind(env, e)))  # noqa: E731
    assert lum(full, 0.0) < 0.8 * lum(full, -20.0) and lum(full, 0.0) < 0.5 * lum(full, 15.0)
    assert lum(full, 0.0) < 0.6 * lum(plain, 0.0)  # the plain map: the mean colour there
    # to the side (90 deg, no mirror image seen) the symmetry changes nothing
    side = lonlat_to_camera_dir(np.array([np.pi / 2]), np.radians(np.array([-20.0])))
    assert np.allclose(DistantLight(full).radiance(np.zeros((1, 3)), side),
                       DistantLight(plain).radiance(np.zeros((1, 3)), side), rtol=1e-3)
    # what was seen is unchanged (the map's seen cells are the image's)
    rays = work.rays_cam[20:-20, 20:-20].reshape(-1, 3)[::97]
    assert np.allclose(DistantLight(full).radiance(np.zeros_like(rays), rays),
                       DistantLight(plain).radiance(np.zeros_like(rays), rays), rtol=1e-4, atol=1e-6)


def test_the_street_axis_sets_the_mirror():
    """A camera looking across the street (forward = its x axis): ahead <-> behind the camera is left <-> right
    of the street, still mirrored; straight along the street (the camera's +-x) no mirror image was seen."""
    img, K = _road_image(), _K()
    px = seen_pixels(prepare_image(img, K, UP))
    across, _ = image_corrected_envmap(_model(), px, UP, ground_keep=0.0, symmetry_weight=1.0,
                                       forward_cam=np.array([1.0, 0.0, 0.0]))
    plain, _ = image_corrected_envmap(_model(), px, UP, ground_keep=0.0, symmetry_weight=0.0)
    road = ldr_to_hdr(np.array([150, 95, 80]) / 255.0)
    assert np.allclose(_behind(across, -20.0), road, rtol=0.2)
    side = lonlat_to_camera_dir(np.array([np.pi / 2]), np.radians(np.array([-20.0])))
    assert np.allclose(DistantLight(across).radiance(np.zeros((1, 3)), side),
                       DistantLight(plain).radiance(np.zeros((1, 3)), side), rtol=1e-3)
