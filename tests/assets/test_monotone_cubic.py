"""car_body.MonotoneCubic: the numpy PCHIP the body profiles use instead of scipy.interpolate (issue #19 start-up)."""

import subprocess
import sys

import numpy as np
import pytest

from streetaug.augment.assets.car_body import BODY_SPECS, MonotoneCubic


def _cases():
    rng = np.random.default_rng(7)
    for make in BODY_SPECS.values():
        spec = make()
        for pts in (spec.top, spec.bottom):
            x, y = np.array(pts).T
            yield x, y, np.linspace(x[0] - 0.3, x[-1] + 0.3, 2001)
    for i in range(120):
        n = int(rng.integers(2, 12))
        x = np.cumsum(rng.uniform(0.01, 1.0, n))
        y = rng.normal(size=n)
        if i % 3 == 0:
            y = np.round(y)  # flat pieces and sign changes: zero slopes
        yield x, y, np.concatenate([np.linspace(x[0] - 1.0, x[-1] + 1.0, 501), x])


def test_same_floats_as_scipy_pchip():
    interpolate = pytest.importorskip("scipy.interpolate")
    for x, y, t in _cases():
        np.testing.assert_array_equal(MonotoneCubic(x, y)(t), interpolate.PchipInterpolator(x, y)(t))


def test_interpolates_the_knots_and_keeps_monotone_pieces():
    x = np.array([0.0, 0.5, 0.6, 2.0, 3.0])
    y = np.array([0.0, 0.1, 1.0, 1.0, 0.2])  # rises, flat, falls: no overshoot anywhere
    f = MonotoneCubic(x, y)
    np.testing.assert_allclose(f(x), y, atol=1e-15)
    for a, b in zip(x[:-1], x[1:]):
        v = f(np.linspace(a, b, 200))
        lo, hi = sorted((f(a), f(b)))
        assert v.min() >= lo - 1e-12 and v.max() <= hi + 1e-12
    assert f(np.array([[0.55]])).shape == (1, 1)


def test_rejects_bad_knots():
    with pytest.raises(ValueError, match="strictly increasing"):
        MonotoneCubic([0.0, 0.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="K >= 2"):
        MonotoneCubic([0.0], [1.0])


def test_car_body_does_not_import_scipy_interpolate():
    code = ("import sys, streetaug.augment.assets.car_body; "
            "print('scipy.interpolate' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
