"""The shared image metrics."""

from __future__ import annotations

import math

import numpy as np

from streetaug.augment.evaluation.metrics import env_log_error, psnr_db


def test_psnr_of_a_known_error():
    a = np.zeros((4, 4, 3), np.uint8)
    b = a.copy()
    b[0, 0, 0] = 48  # MSE = 48^2 / 48 = 48
    assert abs(psnr_db(a, b) - 10 * np.log10(255**2 / 48)) < 1e-9
    where = np.zeros((4, 4), bool)
    where[0, 0] = True  # only that pixel: MSE = 48^2 / 3
    assert abs(psnr_db(a, b, where) - 10 * np.log10(255**2 / (48**2 / 3))) < 1e-9
    assert abs(psnr_db(a / 255.0, b / 255.0, peak=1.0) - psnr_db(a, b)) < 1e-9


def test_psnr_identical_and_empty():
    a = np.full((3, 3), 7, np.uint8)
    assert psnr_db(a, a) == float("inf")
    assert math.isnan(psnr_db(a, a + 1, np.zeros((3, 3), bool)))


def test_env_log_error():
    true = np.full((16, 32, 3), 1.0, np.float32)
    assert env_log_error(true, true) == 0.0
    est = true.copy()
    est[..., 0] = np.e * 2 - 1  # log1p: log(2) -> 1 + log(2) in one channel of three, everywhere
    assert abs(env_log_error(est, true) - 1.0 / 3) < 1e-6
    big = np.full((64, 128, 3), 1.0, np.float32)  # resized to the true map's size
    assert env_log_error(big, true) < 1e-9
