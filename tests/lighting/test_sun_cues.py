"""Single-image sun cues (skynet/sun_cues.py) and their use in predict_sky: sun disc, clear-sky fit, no-sun cases."""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.core import PinholeCamera, hdr_to_ldr, intrinsics_from_fov, luminance
from streetaug.augment.lighting import sky as S
from streetaug.augment.lighting.skynet.dome import angle_deg, camera_from_angles, dome_directions, heading_from_camera
from streetaug.augment.lighting.skynet.sun_cues import (
    clear_sky_log_rgb,
    detect_sun_disc,
    clipped_region_at,
    glare_centre_cam,
    glare_extent_deg,
    in_view_sky_loglik,
    sky_fit_loglik,
)

W, H, FOV = 640, 360, 70.0


def _sun(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _render(sun_world, yaw_deg=0.0, pitch_deg=0.0, turbidity=3.0, cloud_cover=0.0, glare=True, gains=(1.0, 1.0, 1.0),
            occluders=False, fog=(0.0, 0.0, 0.0)):
    """uint8 view (H, W, 3), K, up_cam, sun_cam of the project's analytic sky over a grey ground (z-up world).

    The sun: a disc (0.27 deg) carrying 70 % of its irradiance and an aureole ``exp(-angle / 2 deg)`` carrying
    30 %; auto-exposed (geometric mean luminance -> 0.18) through the contract response.  ``fog`` (3,): the sky
    is brightened by ``1 + fog x exp(-elevation / 12 deg)`` per channel (a vertical profile Preetham lacks).
    """
    K = intrinsics_from_fov(W, H, FOV)
    R = camera_from_angles(np.radians(yaw_deg), np.radians(pitch_deg), 0.0)
    d = PinholeCamera(K, W, H).rays().reshape(-1, 3) @ R.T
    rad = S.sky_radiance(d, sun_world, turbidity, cloud_cover)
    if glare and sun_world[2] > 0 and cloud_cover < 0.5:
        e = S.sun_irradiance(sun_world, turbidity, cloud_cover)
        ang = np.arccos(np.clip(d @ sun_world, -1.0, 1.0))
        half = np.radians(0.27)
        disc = (ang <= half)[:, None] * (0.7 * e / (2 * np.pi * (1 - np.cos(half))))
        w = np.radians(2.0)
        rad = rad + disc + (np.exp(-ang / w) / (2 * np.pi * w * w))[:, None] * 0.3 * e
    el = np.arcsin(np.clip(d[:, 2], 0.0, 1.0))[:, None]
    rad = rad * (1.0 + np.asarray(fog) * np.exp(-el / np.radians(12.0)))
    rad = (rad * np.asarray(gains)).reshape(H, W, 3)
    if occluders:  # dark "buildings" rising from the horizon in the left and right thirds
        u = np.arange(W)[None, :]
        v = np.arange(H)[:, None]
        tall = ((u < W // 3) & (v > H * 0.15)) | ((u > 2 * W // 3) & (v > H * 0.3))
        rad[tall] = 0.02 * np.median(rad)
    k = 0.18 / np.exp(np.mean(np.log(np.maximum(luminance(rad), 1e-9))))
    image = np.clip(np.round(hdr_to_ldr(rad * k) * 255), 0, 255).astype(np.uint8)
    return image, K, R.T @ np.array([0.0, 0.0, 1.0]), R.T @ sun_world


# ----------------------------------------------------------------------------- the sky model


@pytest.mark.parametrize("T", [2.0, 5.0, 9.0])
def test_clear_sky_is_the_sky_modules_preetham_sky(T):
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(200, 3))
    dirs[:, 2] = np.abs(dirs[:, 2])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    suns = np.array([_sun(10, 5), _sun(-120, 45), _sun(70, 80)])
    got = clear_sky_log_rgb(dirs, suns, T)
    assert got.shape == (200, 3, 3)
    for j, s in enumerate(suns):
        ref = np.log(np.maximum(S._clear_sky_shape(dirs, s, T), 1e-12))
        np.testing.assert_allclose(got[:, j], ref, atol=1e-4)


# ----------------------------------------------------------------------------- sun in view


@pytest.mark.parametrize("yaw, pitch, sun_az, sun_el", [(0, 20, 10, 25), (30, 10, 2, 18), (-40, 35, -15, 50)])
def test_detector_finds_a_sun_disc_within_a_degree(yaw, pitch, sun_az, sun_el):
    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), yaw, pitch)
    uv = K @ sun_cam
    assert sun_cam[2] > 0 and 0 <= uv[0] / uv[2] < W and 0 <= uv[1] / uv[2] < H  # really in view
    disc = detect_sun_disc(image, K, up)
    assert disc is not None
    assert angle_deg(disc.direction_cam, sun_cam) < 1.0
    assert np.hypot(*(disc.pixel_xy - uv[:2] / uv[2])) < 0.02 * W
    assert disc.uncertainty_deg >= angle_deg(disc.direction_cam, sun_cam)


def test_detector_is_invariant_to_white_balance_and_finds_nothing_without_a_sun():
    sun = _sun(10, 25)
    image, K, up, sun_cam = _render(sun, 0, 20, gains=(1.2, 1.0, 0.8))
    disc = detect_sun_disc(image, K, up)
    assert disc is not None and angle_deg(disc.direction_cam, sun_cam) < 1.0
    # the same sky with the sun behind the camera: nothing
    image, K, up, _ = _render(_sun(180, 25), 0, 20)
    assert detect_sun_disc(image, K, up) is None


@pytest.mark.parametrize("cloud_cover, occluders", [(1.0, True), (1.0, False), (0.0, True)])
def test_detector_ignores_blown_out_sky_and_sky_between_buildings(cloud_cover, occluders):
    """Over-exposed sky (every pixel above the horizon clipped in places) must not look like a sun."""
    image, K, up, _ = _render(_sun(200, 40), 0, 5, cloud_cover=cloud_cover, occluders=occluders)
    bright = np.clip(image.astype(np.int32) * 2, 0, 255).astype(np.uint8)  # +1 EV: large clipped regions
    assert (bright.max(axis=-1) >= 250).mean() > 0.1
    assert detect_sun_disc(image, K, up) is None
    assert detect_sun_disc(bright, K, up) is None


@pytest.mark.parametrize("sun_az, sun_el", [(43, 15), (46, 25)])
def test_detector_ignores_the_glare_of_a_sun_just_beyond_the_border(sun_az, sun_el):
    """A sun a few degrees beyond the image's left edge clips a blob there whose inscribed disc (not bounded
    by the border) is centred on the border: that is not a sun in view (its centre would be off by more
    than the reported cone)."""
    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), 0, 10)
    uv = K @ sun_cam
    assert uv[2] > 0 and uv[0] / uv[2] < 0  # beyond the left edge
    hot = image.max(axis=-1) >= 250
    assert hot[:, 0].any()  # its glare clips pixels at the border
    assert detect_sun_disc(image, K, up) is None


# ----------------------------------------------------------------------------- sun out of view


def _fit(image, K, up, candidates_h):
    R = heading_from_camera(up)
    rays_h = PinholeCamera(K, image.shape[1], image.shape[0]).rays() @ R.T
    mask = rays_h[..., 2] > np.sin(np.radians(2.0))  # all of the sky (the test image has no occluders)
    return sky_fit_loglik(image, rays_h, mask, candidates_h)


@pytest.mark.parametrize("sun_az, sun_el", [(60, 30), (-75, 20), (150, 40)])
def test_sky_fit_recovers_the_azimuth_of_a_sun_out_of_view(sun_az, sun_el):
    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), 0.0, 0.0, turbidity=3.0, gains=(1.1, 1.0, 0.85))
    assert sun_cam[2] < 0 or abs((K @ sun_cam)[0] / (K @ sun_cam)[2] - W / 2) > W / 2  # out of view
    cand = dome_directions(24, 96).reshape(-1, 3)
    loglik, info = _fit(image, K, up, cand)
    assert info["fit_pixels"] > 1000 and loglik.max() == 0.0
    R = heading_from_camera(up)
    best = cand[int(np.argmax(loglik))]
    sun_h = R @ sun_cam
    az_err = np.degrees(abs(np.angle(np.exp(1j * (np.arctan2(best[1], best[0]) - np.arctan2(sun_h[1], sun_h[0]))))))
    assert az_err < 10.0, (az_err, best, sun_h)
    assert angle_deg(best, sun_h) < 20.0
    # evidence: directions far from the sun are clearly less likely
    far = cand @ sun_h < np.cos(np.radians(60.0))
    assert loglik[far].max() < -3.0


@pytest.mark.parametrize("sun_az, sun_el", [(70, 25), (-110, 35)])
def test_sky_fit_ignores_the_vertical_profile_of_the_sky(sun_az, sun_el):
    """Fog brightening the lower sky (differently per channel) is absorbed by the per-band nuisance: the
    fitted azimuth stays within 10 deg, and the likelihood barely changes from the clear image's."""
    sun = _sun(sun_az, sun_el)
    clear, K, up, sun_cam = _render(sun, 0.0, 10.0, gains=(1.1, 1.0, 0.85))
    foggy, *_ = _render(sun, 0.0, 10.0, gains=(1.1, 1.0, 0.85), fog=(3.0, 2.5, 1.5))
    assert np.abs(foggy.astype(int) - clear.astype(int)).mean() > 10  # the fog really changes the image
    cand = dome_directions(24, 96).reshape(-1, 3)
    sun_h = heading_from_camera(up) @ sun_cam
    lls = []
    for image in (clear, foggy):
        loglik, info = _fit(image, K, up, cand)
        assert info["fit_pixels"] > 1000
        best = cand[int(np.argmax(loglik))]
        az_err = np.degrees(abs(np.angle(np.exp(1j * (np.arctan2(best[1], best[0]) - np.arctan2(sun_h[1], sun_h[0]))))))
        assert az_err < 10.0, (az_err, best, sun_h)
        lls.append(loglik)
    top = lls[0] > -3.0  # the clear image's plausible suns stay plausible in fog, the implausible ones implausible
    assert lls[1][top].max() == 0.0 or np.mean(lls[1][top] > -6.0) > 0.5
    assert lls[1][lls[0] < -20.0].max() < -5.0


def test_glare_extent_is_the_radius_of_the_clipped_region_under_the_direction():
    K = intrinsics_from_fov(160, 96, 70.0)
    image = np.full((96, 160, 3), 120, np.uint8)
    yy, xx = np.mgrid[:96, :160]
    image[(xx - 40) ** 2 + (yy - 30) ** 2 <= 4] = 255  # a compact blob (radius ~2 px ~ 1 deg)
    image[60:66, :] = 255  # a band of clipped horizon glow across the whole image
    rays = PinholeCamera(K, 160, 96).rays()
    def extent(d):
        region = clipped_region_at(image, K, d)
        return None if region is None else glare_extent_deg(region, K, d)

    blob = extent(rays[30, 40])
    band = extent(rays[62, 80])
    assert blob is not None and blob < 3.0
    assert band is not None and band > 30.0  # the band spans ~70 deg: the sun could be anywhere along it
    assert clipped_region_at(image, K, rays[10, 120]) is None  # unclipped sky
    assert clipped_region_at(image, K, -rays[30, 40]) is None  # behind the camera


@pytest.mark.parametrize("sun_az, sun_el", [(10, 20), (-15, 12), (5, 8)])
def test_glare_centre_is_near_a_sun_whose_glare_is_too_large_for_a_disc(sun_az, sun_el):
    """Over-exposed by 1.5x, the sun's glare clips a region of 15-35 deg radius (no disc is detected); from a
    direction near its edge the region's centre is within 3.5 deg of the sun."""
    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), 0, 10)
    image = np.clip(image.astype(np.float64) * 1.5, 0, 255).astype(np.uint8)
    assert detect_sun_disc(image, K, up) is None
    assert 15.0 < glare_extent_deg(clipped_region_at(image, K, sun_cam), K, sun_cam) < 35.0
    edge = sun_cam + np.array([0.12, -0.05, 0.0])
    edge /= np.linalg.norm(edge)
    region = clipped_region_at(image, K, edge)
    assert region is not None  # still in the clipped region, ~7 deg off
    centre = glare_centre_cam(region, K)
    assert angle_deg(centre, sun_cam) < 3.5
    assert clipped_region_at(image, K, -edge) is None  # behind the camera


def test_sky_fit_without_sky_says_nothing():
    image, K, up, _ = _render(_sun(60, 30), 0.0, -30.0)  # looking down: ground only
    loglik, info = _fit(image, K, up, dome_directions(8, 32).reshape(-1, 3))
    assert info["fit_pixels"] < 60 and np.all(loglik == 0.0)


def test_in_view_penalty_only_hits_bright_unclipped_pixels_in_front():
    K = intrinsics_from_fov(160, 96, 70.0)
    R = heading_from_camera(np.array([0.0, -1.0, 0.0]))
    no_sun = np.zeros((96, 160), bool)
    no_sun[:, :80] = True  # left half: bright unclipped sky
    left_ahead = R @ (np.array([-0.3, -0.2, 1.0]) / np.linalg.norm([-0.3, -0.2, 1.0]))
    right_ahead = R @ (np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0]))
    behind = R @ np.array([0.0, -0.5, -1.0]) / np.linalg.norm([0.0, -0.5, -1.0])
    pen = in_view_sky_loglik(np.stack([left_ahead, right_ahead, behind]), R, K, no_sun, 5.0)
    np.testing.assert_array_equal(pen, [-5.0, 0.0, 0.0])


# ----------------------------------------------------------------------------- predict_sky with the cues


def test_predict_reports_a_sun_in_view_precisely(models):
    from streetaug.augment.lighting.skynet.predict import predict_sky

    image, K, up, sun_cam = _render(_sun(10, 25), 0, 20)
    pred = predict_sky(image, K, up, models=models)
    assert pred.confident and "sun disc" in pred.reason, pred.reason
    err = angle_deg(pred.sun_dir_cam, sun_cam)
    assert err < 1.0 and pred.uncertainty_deg < 5.0
    assert pred.sun_visibility >= 0.7
    assert pred.timing_s["total"] < 1.0


@pytest.mark.parametrize("sun_az, sun_el", [(60, 30), (-75, 20)])
def test_predict_finds_a_sun_out_of_view_from_the_clear_sky(models, sun_az, sun_el):
    """The network alone misses these by ~70 deg; with the clear-sky fit the error is small and inside the cone."""
    from streetaug.augment.lighting.skynet.predict import predict_sky

    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), 0, 0, gains=(1.1, 1.0, 0.85))
    pred = predict_sky(image, K, up, models=models)
    err = angle_deg(pred.direction_cam, sun_cam)
    assert err < 15.0 and err <= pred.uncertainty_deg <= 30.0, (err, pred.uncertainty_deg, pred.reason)
    assert "clear-sky fit" in pred.reason and "sun disc" not in pred.reason


@pytest.mark.parametrize("kind", ["overcast", "night"])
def test_overcast_and_night_images_report_no_sun(models, kind):
    from streetaug.augment.lighting.skynet.predict import predict_sky

    if kind == "overcast":
        image, K, up, _ = _render(_sun(30, 40), 0, 5, cloud_cover=1.0, occluders=True)
    else:  # the sun 12 deg below the horizon: a dim night sky, lit windows as small bright dots
        image, K, up, _ = _render(_sun(30, -12), 0, 5, occluders=True)
        image = (image.astype(np.float64) * 0.15).astype(np.uint8)
        for x, y in ((40, 200), (60, 240), (560, 260), (600, 300)):
            image[y:y + 3, x:x + 3] = 255
    pred = predict_sky(image, K, up, models=models)
    assert not pred.confident and pred.sun_dir_cam is None and pred.sun_visibility == 0.0, pred.reason
    assert "sun disc" not in pred.reason


# ----------------------------------------------------------------------------- a clipped patch of overcast sky


def _overcast_patch(az_deg, el_deg, glow_deg, glow_gain, pitch_deg=5.0, radius_deg=2.0, level=0.3):
    """uint8 view (H, W, 3), K, up_cam, patch_cam: a CIE overcast sky (exposed so its median LDR luminance is
    ``level`` before the response) with a clipped round patch of ``radius_deg`` at (az, el) and a narrow glow
    ``1 + glow_gain x exp(-(angle - radius) / glow_deg)`` around it: a bright gap in the cloud, not the sun."""
    K = intrinsics_from_fov(W, H, FOV)
    R = camera_from_angles(0.0, np.radians(pitch_deg), 0.0)
    d = PinholeCamera(K, W, H).rays().reshape(-1, 3) @ R.T
    rad = S.sky_radiance(d, _sun(30, 40), 3.0, 1.0)
    patch = _sun(az_deg, el_deg)
    ang = np.degrees(np.arccos(np.clip(d @ patch, -1.0, 1.0)))
    rad = (rad * (1.0 + glow_gain * np.exp(-np.maximum(ang - radius_deg, 0.0) / glow_deg))[:, None]).reshape(H, W, 3)
    image = np.clip(np.round(hdr_to_ldr(rad * level / np.median(luminance(rad))) * 255), 0, 255).astype(np.uint8)
    image.reshape(-1, 3)[ang <= radius_deg] = 255
    return image, K, R.T @ np.array([0.0, 0.0, 1.0]), R.T @ patch


@pytest.mark.parametrize("glow_deg, glow_gain, level", [(1.0, 0.8, 0.3), (2.0, 0.5, 0.3), (2.0, 0.3, 0.45)])
def test_a_clipped_patch_of_overcast_sky_is_not_the_sun(models, glow_deg, glow_gain, level):
    """The disc detector takes these round clipped patches with a narrow glow ring for suns (as on scene-0916's
    overcast keyframes); the sky 15-35 deg beyond is nearly as bright as next to them, so predict_sky rejects them."""
    from streetaug.augment.lighting.skynet.predict import glare_is_sun, predict_sky

    image, K, up, patch_cam = _overcast_patch(-20, 20, glow_deg, glow_gain, level=level)
    disc = detect_sun_disc(image, K, up)
    assert disc is not None and angle_deg(disc.direction_cam, patch_cam) < 1.0  # the detector alone is fooled
    pred = predict_sky(image, K, up, models=models)
    assert pred.cues["disc_rejected"] and not glare_is_sun(pred.cues["disc_region"]), pred.cues
    assert not pred.confident and pred.sun_dir_cam is None and "sun disc" not in pred.reason, pred.reason
    assert "(its centre)" not in pred.reason  # nor does the fitted sun move into the patch


@pytest.mark.parametrize("sun_az, sun_el, yaw, pitch",
                         [(10, 25, 0, 20), (-20, 15, 0, 10), (0, 35, 0, 25), (15, 8, 0, 0)])
def test_a_sun_in_a_clear_sky_is_still_the_sun(models, sun_az, sun_el, yaw, pitch):
    """A real sun's glare falls off across the sky around it: the disc (or the glare under the fitted sun) is kept."""
    from streetaug.augment.lighting.skynet.predict import glare_is_sun, predict_sky

    image, K, up, sun_cam = _render(_sun(sun_az, sun_el), yaw, pitch)
    pred = predict_sky(image, K, up, models=models)
    features = pred.cues.get("disc_region") or pred.cues.get("region")
    assert features is not None and glare_is_sun(features), pred.cues
    assert pred.confident and angle_deg(pred.sun_dir_cam, sun_cam) < 3.0, pred.reason
    assert not pred.cues.get("disc_rejected")


def test_glare_rule_tells_a_suns_glare_from_a_clipped_patch_of_overcast_sky():
    """The glare path (no disc: the fitted sun lands in a clipped region): an over-exposed sun's glare region
    glows against the sky beyond it, a clipped 8 deg patch of overcast sky does not, nor does a patch with
    no sky around it (leaves)."""
    from streetaug.augment.lighting.evidence import sky_mask
    from streetaug.augment.lighting.skynet.predict import glare_is_sun
    from streetaug.augment.lighting.skynet.sun_cues import glare_region_features

    def features(image, K, up, d_cam):
        rays = PinholeCamera(K, W, H).rays()
        sky = sky_mask(image / 255.0, np.arcsin(np.clip(rays @ up, -1, 1)), min_elevation_deg=2.0, min_lum=0.25,
                       bright_percentile=10.0, max_grad=0.15)
        region = clipped_region_at(image, K, d_cam)
        assert region is not None
        return glare_region_features(image, K, region, glare_centre_cam(region, K), up, sky)

    image, K, up, sun_cam = _render(_sun(10, 20), 0, 10)
    image = np.clip(image.astype(np.float64) * 1.5, 0, 255).astype(np.uint8)  # the glare of test above
    assert detect_sun_disc(image, K, up) is None
    assert glare_is_sun(features(image, K, up, sun_cam))
    image, K, up, patch_cam = _overcast_patch(-20, 20, 1.0, 0.2, radius_deg=8.0)
    f = features(image, K, up, patch_cam)
    assert f["extent_deg"] > 6.0 and not glare_is_sun(f), f
    leaves = image.copy()
    ang = np.degrees(np.arccos(np.clip(PinholeCamera(K, W, H).rays() @ patch_cam, -1, 1)))
    leaves[(ang > 8.0) & (ang < 40.0)] = 40  # dark foliage all around the clipped patch
    assert not glare_is_sun(features(leaves, K, up, patch_cam))


def test_without_sky_in_view_the_network_direction_stands_and_no_sun_is_reported(models):
    """A view whose sky is hidden (foliage over all but the road): no clear-sky fit moves the network's direction
    (there is no sky to fit), and the sun is not reported (nothing confirms it); the same view with its sky gets
    the fit (the test above)."""
    from streetaug.augment.lighting.skynet.predict import FIT_MIN_SKY_FRACTION, predict_sky

    image, K, up, _ = _render(_sun(60, 30), 0, 0, gains=(1.1, 1.0, 0.85))
    rng = np.random.default_rng(3)
    hidden = image.copy()
    rows = int(0.62 * hidden.shape[0])  # everything above the road: dark, textured leaves
    leaves = rng.integers(0, 40, size=(rows, hidden.shape[1], 1)) + np.array([25, 45, 20])
    hidden[:rows] = np.clip(leaves, 0, 255).astype(np.uint8)
    pred = predict_sky(hidden, K, up, models=models)
    assert pred.cues["sky_fraction"] < FIT_MIN_SKY_FRACTION and not pred.cues["clear_sky_fit"]
    alone = predict_sky(hidden, K, up, models=models, use_cues=False)
    assert angle_deg(pred.direction_cam, alone.direction_cam) < 1e-4  # arccos of a rounded unit dot: ~1e-6 deg
    assert pred.sun_dir_cam is None and not pred.confident and "too little sky" in pred.reason
    with_sky = predict_sky(image, K, up, models=models)
    assert with_sky.cues["clear_sky_fit"] and with_sky.cues["sky_fraction"] >= FIT_MIN_SKY_FRACTION
