"""Clipped pixels as censored values in L1's evidence (issue #16): the sky's ratio to the model and the
ground's lit level must follow the image's exposure, not fall when more of it clips."""

from __future__ import annotations

import numpy as np

from streetaug.augment.core import SATURATION_RADIANCE, hdr_to_ldr_uint8, ldr_uint8_to_hdr
from streetaug.augment.lighting.evidence import ground_evidence, prepare_image
from streetaug.augment.lighting.image_dome import sky_log_gain
from streetaug.augment.lighting.sky_prior import censored_sky_log_gain

UP = np.array([0.0, -1.0, 0.0])  # a level camera


def _K(w=640, h=360, fov_deg=70.0):
    f = 0.5 * w / np.tan(np.radians(fov_deg) / 2)
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])


def _sky(n=400, seed=0):
    """(n, 3) sky radiance spread over a stop around 0.6 (image units)."""
    rng = np.random.default_rng(seed)
    return 0.6 * np.exp(rng.uniform(-0.35, 0.35, size=(n, 1))) * np.array([[0.9, 1.0, 1.15]])


def _clip(rad):
    """(radiance with clipped channels at the saturation level, clipped channels)."""
    clipped = rad >= SATURATION_RADIANCE
    return np.where(clipped, SATURATION_RADIANCE, rad), clipped


def test_sky_gain_is_the_median_ratio_while_less_than_half_clips():
    model = np.full((400, 3), 0.5)
    truth = np.log(np.median(_sky(), axis=0) / 0.5)
    rad, clipped = _clip(_sky() * 1.2)  # the brightest third of the blue channel clipped, a tenth of green
    assert 0.2 < clipped[:, 2].mean() < 0.5 and 0.05 < clipped[:, 1].mean()
    gain = sky_log_gain(rad, clipped, model)
    np.testing.assert_allclose(gain, truth + np.log(1.2), atol=1e-9)  # exact: a censored median
    # the unclipped pixels alone (the old estimate) are the sky's darker part
    dark = np.log(rad[~clipped[:, 2], 2].mean() / 0.5)
    assert dark < gain[2] - 0.05


def test_an_all_clipped_sky_is_at_least_the_model_and_its_saturation():
    """All clipped: the gain is at least the clip bound in every channel, and the expected ratio given that
    bound under the prior of unclipped skies (:mod:`.sky_prior`), one offset shared by the channels."""
    sky = _sky() * 4.0
    rad, clipped = _clip(sky)
    assert clipped.all()
    for level in (2.0, 0.3):  # a model above the saturation level, below it
        model = np.full((400, 3), level)
        bound = np.log(SATURATION_RADIANCE / level)
        gain = sky_log_gain(rad, clipped, model)
        assert np.all(gain >= bound - 1e-12)
        np.testing.assert_allclose(gain, censored_sky_log_gain(bound[None], clipped[:1])[0], atol=1e-9)
    assert sky_log_gain(rad[:5], clipped[:5], model[:5]) is None  # too few pixels


def _road_image(w=640, h=360):
    """A level camera's view: sky above, a grey road below with sunlit and shadowed stripes (4:1), the sunlit
    part bright enough that +1 EV clips part of it."""
    rng = np.random.default_rng(1)
    img = np.full((h, w, 3), 235, np.uint8)
    blocks = lambda sigma: np.kron(rng.normal(0, sigma, size=(h // 8, w // 8)), np.ones((8, 8)))  # noqa: E731
    lit = np.clip(178 + blocks(16), 0, 254)  # patchy (8 px blocks: the downscaling keeps it)
    shade = np.clip(88 + blocks(6), 0, 254)
    cols = (np.arange(w) // 40) % 3 == 0
    road = np.where(cols[None, :], shade, lit)
    img[h // 2:] = np.repeat(road[h // 2:, :, None], 3, axis=2).astype(np.uint8)
    return img


def test_ground_lit_level_follows_the_exposure_when_its_bright_part_clips():
    img, K = _road_image(), _K()
    brighter = hdr_to_ldr_uint8(ldr_uint8_to_hdr(img) * 2.0)
    g0 = ground_evidence(prepare_image(img, K, UP), UP, 1.5)
    g1 = ground_evidence(prepare_image(brighter, K, UP), UP, 1.5)
    assert g0["bimodal"] and g1["bimodal"]
    work1 = prepare_image(brighter, K, UP)
    clipped_lit = (work1.ldr.max(-1) >= 0.97)[work1.ldr.shape[0] // 2 + 2:].mean()
    assert 0.1 < clipped_lit < 0.3  # the test can fail: part of the lit road clips at +1 EV
    assert abs(g1["lit"] / g0["lit"] - 2.0) < 0.1
    assert abs(g1["shadow"] / g0["shadow"] - 2.0) < 0.1
