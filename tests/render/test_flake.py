"""Metallic-flake lobe: flake = 0 is the old BRDF bit for bit; flakes move diffuse light towards (not onto)
the mirror direction without adding energy; sampling and pdf stay consistent; the Mitsuba mapping."""

import numpy as np
import pytest

from streetaug.augment.assets.asset import Material
from streetaug.augment.evaluation.reference import mitsuba_available, mitsuba_bsdf
from streetaug.augment.render.brdf import (
    BRDFParams,
    brdf_pdf,
    eval_brdf,
    flake_energy,
    reflect,
    sample_brdf,
    specular_albedo,
)

N = 20_000
PAINT = dict(base_color=(0.55, 0.08, 0.06), metallic=0.0, roughness=0.35, specular=0.5, clearcoat=1.0)


def _dirs(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _albedo(v: np.ndarray, params: BRDFParams, n_samples: int = 300_000, seed: int = 0) -> np.ndarray:
    """``int f(v, l) cos dl`` (3,) by uniform hemisphere sampling around n = +z."""
    l = _dirs(np.random.default_rng(seed), n_samples)
    n = np.tile([0.0, 0.0, 1.0], (n_samples, 1))
    f = eval_brdf(n, np.tile(v, (n_samples, 1)), l, params.take(np.zeros(n_samples, int)))
    return (f * l[:, 2:3]).mean(axis=0) * 2 * np.pi


def test_flake_zero_is_bit_identical():
    rng = np.random.default_rng(0)
    n = np.tile([0.0, 0.0, 1.0], (N, 1))
    v, l, u = _dirs(rng, N), _dirs(rng, N), rng.random((N, 3))
    old = BRDFParams.uniform(N, **PAINT)
    zero = BRDFParams(old.base_color, old.metallic, old.roughness, old.specular, old.clearcoat, None, np.zeros(N))
    for p in (zero, BRDFParams.uniform(N, **PAINT, flake=0.0)):
        np.testing.assert_array_equal(eval_brdf(n, v, l, p), eval_brdf(n, v, l, old))
        np.testing.assert_array_equal(sample_brdf(n, v, p, u), sample_brdf(n, v, old, u))
        np.testing.assert_array_equal(brdf_pdf(n, v, l, p), brdf_pdf(n, v, l, old))
        np.testing.assert_array_equal(p.c_lambert, old.c_diff)


def test_flakes_brighten_near_the_mirror_direction_and_darken_far_from_it():
    v = np.array([[np.sin(0.6), 0.0, np.cos(0.6)]])
    n = np.array([[0.0, 0.0, 1.0]])
    mirror = reflect(v, n)
    off = lambda deg: np.array([[-np.sin(0.6 + np.radians(deg)), 0.0, np.cos(0.6 + np.radians(deg))]])  # noqa: E731
    plain = BRDFParams.uniform(1, **PAINT)
    flaked = BRDFParams.uniform(1, **PAINT, flake=0.8)
    lum = lambda f: float((f @ [0.2126, 0.7152, 0.0722])[0])  # noqa: E731
    assert np.allclose(mirror, off(0.0))
    for deg in (8.0, 15.0):  # near but off the mirror direction (outside the 0.05 coat's and the 0.35 base's cores)
        assert lum(eval_brdf(n, v, off(deg), flaked)) > 1.5 * lum(eval_brdf(n, v, off(deg), plain)), deg
    far = np.array([[0.8, 0.0, 0.6]])  # far from it (back on the viewer's side): darker ("flop")
    assert lum(eval_brdf(n, v, far, flaked)) < lum(eval_brdf(n, v, far, plain))


@pytest.mark.parametrize("theta", [0.1, 0.7, 1.2, 1.45])
def test_white_furnace_flakes_add_no_energy(theta):
    """Total reflectance <= 1 (a white, fully flaked, clear-coated paint): the flakes' albedo is the share of
    the diffuse colour they take (neither more nor, through single-scattering loss, less)."""
    v = np.array([np.sin(theta), 0.0, np.cos(theta)])
    for base in ((0.9, 0.9, 0.9), (0.55, 0.08, 0.06)):
        kw = dict(PAINT, base_color=base)
        plain = _albedo(v, BRDFParams.uniform(1, **kw))
        flaked = _albedo(v, BRDFParams.uniform(1, **kw, flake=1.0))
        assert np.all(flaked <= 1.0 + 0.01), flaked
        # No energy added; a little less at grazing views only (the coat reflects more of the light the
        # flakes send near the mirror direction than of the diffuse light's).
        assert np.all(flaked <= plain + 0.01) and np.all(flaked >= 0.92 * plain), (flaked, plain)
    # Flakes alone (no specular, no coat) on white: a white furnace, albedo 1 at every angle.
    white = BRDFParams.uniform(1, base_color=(1.0, 1.0, 1.0), metallic=0.0, specular=0.0, flake=1.0)
    np.testing.assert_allclose(_albedo(v, white), 1.0, atol=0.025)
    assert 0.2 < flake_energy(np.array([v[2]]))[0] < 1.0  # single scattering alone loses some


def test_flake_sampling_matches_its_pdf():
    """E[f cos / pdf] over BRDF samples equals the albedo by uniform sampling (the pdf is the sampler's)."""
    theta = 0.5
    v1 = np.array([np.sin(theta), 0.0, np.cos(theta)])
    params = BRDFParams.uniform(1, **PAINT, flake=0.7)
    rng = np.random.default_rng(3)
    M = 200_000
    n = np.tile([0.0, 0.0, 1.0], (M, 1))
    v = np.tile(v1, (M, 1))
    p = params.take(np.zeros(M, int))
    l = sample_brdf(n, v, p, rng.random((M, 3)))
    pdf = brdf_pdf(n, v, l, p)
    ok = (l[:, 2] > 0) & (pdf > 0)
    est = np.where(ok[:, None], eval_brdf(n, v, l, p) * l[:, 2:3] / np.where(ok, pdf, 1.0)[:, None], 0.0).mean(axis=0)
    np.testing.assert_allclose(est, _albedo(v1, params), rtol=0.04)


def test_mitsuba_mapping_of_flakes():
    plain = Material("paint", np.array(PAINT["base_color"]), roughness=0.35, clearcoat=1.0)
    flaked = Material("paint", np.array(PAINT["base_color"]), roughness=0.35, clearcoat=1.0, flake=0.6)
    assert mitsuba_bsdf(plain)["type"] == "principled"
    d = mitsuba_bsdf(flaked)
    assert d["type"] == "blendbsdf" and d["weight"] == pytest.approx(0.6)
    assert d["bsdf_0"] == mitsuba_bsdf(plain)
    assert d["bsdf_1"]["metallic"] == 1.0 and d["bsdf_1"]["clearcoat"] == 1.0
    ok, _ = mitsuba_available()
    if ok:  # the dict is a valid Mitsuba BSDF
        from streetaug.augment.evaluation.reference import _mi

        _mi().load_dict(d)
