"""A clipped sky's level (issue #16, +1 EV at the kerb): a clipped channel says only "at least the clip level";
it takes its expected sky/model ratio under the prior of unclipped skies (one offset shared by the channels),
not the model's own scale (``max(bound, 0)``: at +1 EV the bundled sunny sky stayed x1.57 of EV 0's, not x2)."""

from __future__ import annotations

import numpy as np

from streetaug.augment.core import SATURATION_RADIANCE
from streetaug.augment.lighting.image_dome import sky_log_gain
from streetaug.augment.lighting.observe import ViewObservation
from streetaug.augment.lighting.sky_prior import LOG_GAIN_MEAN, LOG_GAIN_STD, censored_log_gain, censored_sky_log_gain
from streetaug.augment.lighting.skydome import build_sky_dome


def test_truncated_mean_matches_sampling_and_its_limits():
    rng = np.random.default_rng(0)
    draws = rng.normal(LOG_GAIN_MEAN, LOG_GAIN_STD, size=(400_000, 3))
    for bound in (-0.5, 0.0, 0.4):
        mc = np.array([draws[draws[:, c] >= bound, c].mean() for c in range(3)])
        np.testing.assert_allclose(censored_log_gain(np.full(3, bound)), mc, atol=5e-3)
    np.testing.assert_allclose(censored_log_gain(np.full(3, -5.0)), LOG_GAIN_MEAN, atol=1e-9)  # bound says nothing
    far = censored_log_gain(np.full(3, 6.0))
    assert np.all(far >= 6.0) and np.all(far < 6.05)  # far above the prior: just above the bound
    assert np.all(np.isfinite(censored_log_gain(np.full(3, 60.0))))


def test_partly_clipped_pixels_follow_their_unclipped_channels():
    lr = np.array([[0.195, 0.242, 0.0], [0.195, 0.242, 0.5]])
    clipped = np.array([[False, False, True], [False, False, True]])
    out = censored_sky_log_gain(lr, clipped)
    np.testing.assert_array_equal(out[:, :2], lr[:, :2])  # measurements are kept
    x = np.mean(lr[0, :2] - LOG_GAIN_MEAN[:2])
    assert abs(out[0, 2] - (LOG_GAIN_MEAN[2] + x)) < 1e-12  # the shared offset, above the low bound
    assert out[1, 2] == 0.5  # a bound above it holds


def test_an_all_clipped_sky_keeps_the_priors_colour_and_is_brighter_than_its_bound():
    # the clip level below the model in every channel, lowest in blue (a bluish model, a white clipped sky)
    lr = np.array([[0.0, -0.194, -0.528]])
    out = censored_sky_log_gain(lr, np.ones((1, 3), bool))[0]
    offset = out - LOG_GAIN_MEAN
    np.testing.assert_allclose(offset, offset[0], atol=1e-12)  # one offset: the white clip does not redden it
    assert np.all(out > lr[0]) and offset[0] > 0.0


def test_a_sky_clipped_just_below_the_model_is_brighter_than_the_model():
    """Every sky pixel clipped at a level just below the model's (the bundled sunny sky at +1 EV): the dome's sky
    gain (and the L1 gain) is the prior's expectation above that bound: brighter than the model, the channels
    in the prior's colour; the old rule kept the model (gain 1)."""
    H, W = 64, 256
    model = np.full((H, W, 3), 1.05 * np.asarray(SATURATION_RADIANCE).max(), np.float32)
    rng = np.random.default_rng(1)
    az, el = rng.uniform(-0.6, 0.6, 4000), np.radians(rng.uniform(10.0, 40.0, 4000))
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    rgb = np.broadcast_to(np.asarray(SATURATION_RADIANCE, np.float64), (4000, 3)).astype(np.float32)
    sky = np.ones(4000, bool)
    obs = ViewObservation("CAM", np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros((0, 3)),
                          np.zeros(0, bool), dirs, rgb, sky, sky.copy(), np.zeros(3))
    _, stats = build_sky_dome(model, [obs])
    gain = np.log(stats["sky_gain_rgb"])
    assert np.all(gain > 0.05), gain
    np.testing.assert_allclose(gain - LOG_GAIN_MEAN, (gain - LOG_GAIN_MEAN)[0], atol=1e-6)
    l1 = sky_log_gain(rgb.astype(np.float64), np.ones((4000, 3), bool), model.reshape(-1, 3)[:4000].astype(np.float64))
    np.testing.assert_allclose(l1, gain, atol=1e-6)
