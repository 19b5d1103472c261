"""Smooth glass reflects with a pane's exact Fresnel (two faces, n = 1.5), not Schlick's single face (issue #20).

A windscreen raked 62 deg seen from a camera ahead reflects ~15 % of the sky, not the ~7 % of Schlick's curve
with the GGX lobe's masking; the mirror term the shader uses for environment reflections (``mirror_albedo``) and
the sampled GGX lobe (``eval_brdf``) must agree, stay reciprocal and not create energy.
"""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.render.brdf import (BRDFParams, eval_brdf, mirror_albedo, reflect, sample_ggx_half,
                                           schlick_weight, specular_albedo)

GLASS_SPECULAR = 0.054 / 0.08  # the clear front glass's F0 (procedural.pane_specular): 5.4 %


def _glass(n: int, roughness: float = 0.05, **kw) -> BRDFParams:
    return BRDFParams.uniform(n, base_color=(0.02, 0.02, 0.02), roughness=roughness, specular=GLASS_SPECULAR, **kw)


def _view(theta_deg: np.ndarray) -> np.ndarray:
    t = np.radians(np.asarray(theta_deg, dtype=np.float64))
    return np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=1)


@pytest.mark.parametrize("theta, expected, tol", [(0.0, 0.054, 0.003), (62.0, 0.147, 0.012), (80.0, 0.53, 0.04)])
def test_mirror_reflectance_of_clear_glass(theta, expected, tol):
    """Head-on 5.4 % (unchanged), 62 deg ~14.7 % (Schlick: 7.2), 80 deg ~53 % (Schlick: 15)."""
    p = _glass(1)
    n_v = np.array([np.cos(np.radians(theta))])
    r = mirror_albedo(n_v, p, np.ones(1))
    assert abs(float(r[0, 1]) - expected) < tol, (theta, r)


def _lobe_albedo(theta_deg: float, params_of, n_samples: int = 4096) -> np.ndarray:
    """``int f_spec cos dl`` at view angle theta (3,) by GGX importance sampling (f includes the diffuse, whose
    albedo is c_diff exactly and is subtracted)."""
    v = np.repeat(_view([theta_deg]), n_samples, axis=0)
    n = np.tile([0.0, 0.0, 1.0], (n_samples, 1))
    p = params_of(n_samples)
    k = np.arange(n_samples)
    u1 = (k + 0.5) / n_samples
    u2 = np.array([int(f"{i:032b}"[::-1], 2) for i in k], dtype=np.float64) / 2.0**32
    h = sample_ggx_half(n, p.alpha, u1, u2)
    l = reflect(v, h)
    ok = l[:, 2] > 1e-6
    n_h, v_h = h[:, 2], np.einsum("ij,ij->i", v, h)
    d = p.alpha**2 / (np.pi * (n_h**2 * (p.alpha**2 - 1) + 1) ** 2)
    pdf = d * n_h / (4.0 * np.maximum(v_h, 1e-9))
    f = eval_brdf(n, v, l, p) - p.c_diff / np.pi
    return np.where(ok[:, None], f * (l[:, 2] / np.maximum(pdf, 1e-300))[:, None], 0.0).mean(axis=0)


@pytest.mark.parametrize("theta", [0.0, 40.0, 62.0, 75.0])
def test_sampled_lobe_agrees_with_the_mirror_term(theta):
    """The GGX lobe's directional albedo (importance-sampled) is the mirror term's reflectance within 10 %."""
    alb = _lobe_albedo(theta, _glass)
    mirror = mirror_albedo(np.array([np.cos(np.radians(theta))]), _glass(1), np.ones(1))[0]
    assert np.allclose(alb, mirror, rtol=0.10), (theta, alb, mirror)


def test_reciprocal():
    rng = np.random.default_rng(3)
    m = 2000
    n = np.tile([0.0, 0.0, 1.0], (m, 1))
    a = rng.normal(size=(m, 3))
    b = rng.normal(size=(m, 3))
    a[:, 2], b[:, 2] = np.abs(a[:, 2]), np.abs(b[:, 2])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    for rough in (0.05, 0.12):
        p = _glass(m, rough)
        assert np.allclose(eval_brdf(n, a, b, p), eval_brdf(n, b, a, p), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 75.0, 85.0, 89.0])
def test_energy_at_most_one(theta):
    """Diffuse plus specular albedo <= 1 at every view angle, for the mirror term and the sampled lobe."""
    p1 = _glass(1)
    mirror = mirror_albedo(np.array([np.cos(np.radians(theta))]), p1, np.ones(1))[0] + p1.c_diff[0]
    assert (mirror <= 1.0).all(), (theta, mirror)
    alb = _lobe_albedo(theta, _glass) + p1.c_diff[0]
    assert (alb <= 1.0).all(), (theta, alb)


def test_only_smooth_dielectrics_without_coat():
    """Metals, clear-coated paint and rough dielectrics keep their Schlick lobe; the pane fades in from 0.15 to
    0.1 roughness."""
    n_v = np.array([np.cos(np.radians(62.0))])
    one = np.ones(1)
    for p in (_glass(1, 0.05, metallic=1.0), _glass(1, 0.2)):
        assert np.allclose(mirror_albedo(n_v, p, one), specular_albedo(n_v, p)), p
    glass = [float(mirror_albedo(n_v, _glass(1, r), one)[0, 1]) for r in (0.05, 0.125, 0.2)]
    assert glass[0] > 0.13 and glass[2] < 0.09 and glass[2] < glass[1] < glass[0], glass
    # A clear coat over a smooth base: the coat takes the Fresnel, the base below keeps Schlick.
    coated = _glass(1, 0.05, clearcoat=1.0)
    base = mirror_albedo(n_v, coated, one) - mirror_albedo(n_v, coated, np.zeros(1))
    keep = 1.0 - (0.04 + 0.96 * schlick_weight(n_v))
    assert np.allclose(base, specular_albedo(n_v, coated) * keep[:, None]), base


def test_what_the_glass_transmits_is_what_it_does_not_reflect():
    """A ray through the glass keeps ``1 - F`` with the same pane Fresnel as the reflection (was Schlick's)."""
    from streetaug.augment.render.brdf import mirror_fresnel

    n_v = np.cos(np.radians([0.0, 62.0, 80.0]))
    p = _glass(3)
    assert np.allclose(mirror_fresnel(n_v, p), mirror_albedo(n_v, p, np.ones(3)), rtol=0.02)
