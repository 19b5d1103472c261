"""The prior of the sky's image/model ratio, for a clipped sky: its expected level given "at least the clip level".

A clipped sky pixel says only that the sky/model ratio ``g`` (log, per channel) is at least its bound ``b``
(the saturation radiance over the model's). Taking ``max(b, 0)`` (the model unless the bound is brighter)
assumes the model's own scale is right: with 93 % of a sky clipped (the bundled sunny CAM_FRONT at +1 EV) the
sky is kept at the model, 1.24x below what the same sky measured at EV 0. The expected ratio given the bound
under a normal prior ``N(mean, std)`` is the truncated normal's mean ``mean + std * phi(a) / (1 - Phi(a))``,
``a = (b - mean) / std``: the prior's mean when the bound is far below it, just above the bound when the bound is
far above it (the bound is then almost the value).

The channels share the sky: a per-channel truncation alone turns a clipped white sky red (the clip level is
the same radiance in every channel while the model is bluer, so the blue bound is the lowest). So the ratio is
``g_c = mean_c + x`` with one ``x ~ N(0, std)`` shared by the channels (:func:`censored_sky_log_gain`): a pixel
with some channel unclipped measures ``x`` there (its clipped channels take that ``x``, or their bound if
brighter); an all-clipped pixel has ``x >= max_c(b_c - mean_c)`` and takes the truncated mean of ``x``.

The prior (:data:`LOG_GAIN_MEAN`, :data:`LOG_GAIN_STD`): the log ratio of the medians of the sky's radiance and
the L1 model's there, over the CAM_FRONT images at EV 0 whose sky has fewer than half of each channel clipped
(18 of 42: the bundled samples and scene-0916's keyframes; ``benchmarks/fit_sky_gain_prior.py``,
``results/sky_gain_prior.json``). Measured on unclipped skies only: a clipped sky is a brighter one, so the
prior is low for skies that clip (a Tobit fit to both is much higher, 0.6-0.7, but is bimodal data forced into
one normal); the bound corrects for that where it is high.
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr

LOG_GAIN_MEAN = np.array([-0.030, -0.087, -0.149])  # (3,) RGB, log sky/model ratio of unclipped CAM_FRONT skies
LOG_GAIN_STD = np.array([0.370, 0.338, 0.277])  # (3,) its standard deviation over those images


def censored_log_gain(bound: np.ndarray, mean: np.ndarray = LOG_GAIN_MEAN,
                      std: np.ndarray = LOG_GAIN_STD) -> np.ndarray:
    """E[g | g >= bound] (same shape as ``bound`` (..., 3)) for g ~ N(mean, std) per channel (log ratios)."""
    b = np.asarray(bound, np.float64)
    a = (b - mean) / std
    # inverse Mills ratio phi(a) / (1 - Phi(a)), in logs (stable far in the tail, where it tends to a)
    mills = np.exp(-0.5 * a**2 - 0.5 * np.log(2.0 * np.pi) - log_ndtr(-a))
    return np.maximum(mean + std * mills, b)


def censored_sky_log_gain(log_ratio: np.ndarray, clipped: np.ndarray, mean: np.ndarray = LOG_GAIN_MEAN,
                          std: np.ndarray = LOG_GAIN_STD) -> np.ndarray:
    """(N, 3) the sky/model log ratios ``log_ratio`` (N, 3) with the ``clipped`` (N, 3) bool channels (lower
    bounds there) replaced by their expected values under the shared-offset prior (see module doc): unclipped
    channels unchanged; a clipped channel of a partly clipped row ``max(bound, mean_c + x)`` with ``x`` the
    unclipped channels' mean offset; an all-clipped row ``mean_c + E[x | x >= max_c(bound_c - mean_c)]``."""
    lr = np.asarray(log_ratio, np.float64)
    clipped = np.asarray(clipped, bool)
    offset = lr - mean
    n_free = (~clipped).sum(axis=1)
    x_seen = np.where(clipped, 0.0, offset).sum(axis=1) / np.maximum(n_free, 1)
    x_bound = np.where(clipped, offset, -np.inf).max(axis=1)
    s = float(np.mean(std))
    x_all = censored_log_gain(x_bound[:, None], np.zeros(1), np.full(1, s))[:, 0] if len(lr) else x_bound
    x = np.where(n_free > 0, x_seen, x_all)
    return np.where(clipped, np.maximum(mean + x[:, None], lr), lr)
