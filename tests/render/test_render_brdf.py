"""UE4 BRDF and direction sampling: non-negativity, reciprocity, energy, pdf consistency."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from streetaug.augment.core import equirect_solid_angles
from streetaug.augment.render.brdf import (
    BRDFParams,
    brdf_pdf,
    eval_brdf,
    ggx_d,
    reflect,
    sample_brdf,
    specular_albedo,
    tangent_frame,
)
from streetaug.augment.render.environment import environment_tables
from streetaug.augment.render.sampling import (
    EnvSampler,
    cosine_hemisphere,
    equirect_texel_moments,
    fibonacci_hemisphere,
    hemisphere_irradiance,
    irradiance_map,
    lookup_irradiance,
    sample_cone,
)

unit = st.floats(0.0, 1.0)


def _dir_from(theta: float, phi: float) -> np.ndarray:
    return np.array([[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]])


def _albedo(v: np.ndarray, params: BRDFParams, n_samples: int = 200_000, seed: int = 0) -> np.ndarray:
    """Directional albedo  int f(v, l) cos dl  (3,) by uniform hemisphere sampling around n = +z."""
    rng = np.random.default_rng(seed)
    z = rng.random(n_samples)
    phi = rng.random(n_samples) * 2 * np.pi
    r = np.sqrt(1 - z * z)
    l = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    n = np.tile([0.0, 0.0, 1.0], (n_samples, 1))
    f = eval_brdf(n, np.tile(v, (n_samples, 1)), l, params.take(np.zeros(n_samples, int)))
    return (f * z[:, None]).mean(axis=0) * 2 * np.pi


@settings(max_examples=60, deadline=None)
@given(t1=st.floats(0.0, 1.5), p1=st.floats(0, 6.28), t2=st.floats(0.0, 1.5), p2=st.floats(0, 6.28),
       metallic=unit, rough=unit, spec=unit, coat=unit, r=unit, g=unit, b=unit)
def test_brdf_nonnegative_and_reciprocal(t1, p1, t2, p2, metallic, rough, spec, coat, r, g, b):
    params = BRDFParams.uniform(1, (r, g, b), metallic, rough, spec, coat)
    n = np.array([[0.0, 0.0, 1.0]])
    v, l = _dir_from(t1, p1), _dir_from(t2, p2)
    f_vl = eval_brdf(n, v, l, params)
    f_lv = eval_brdf(n, l, v, params)
    assert np.all(f_vl >= 0) and np.all(np.isfinite(f_vl))
    np.testing.assert_allclose(f_vl, f_lv, rtol=1e-9, atol=1e-12)


def test_brdf_zero_below_horizon():
    params = BRDFParams.uniform(1)
    n = np.array([[0.0, 0.0, 1.0]])
    assert np.all(eval_brdf(n, _dir_from(0.3, 0), _dir_from(2.0, 1.0), params) == 0)
    assert np.all(eval_brdf(n, _dir_from(2.0, 0), _dir_from(0.3, 1.0), params) == 0)


@pytest.mark.parametrize("theta_v", [0.0, 0.8, 1.3])
@pytest.mark.parametrize("rough", [0.2, 0.5, 1.0])
def test_white_furnace_energy_at_most_one(theta_v, rough):
    v = _dir_from(theta_v, 0.3)[0]
    metal = _albedo(v, BRDFParams.uniform(1, (1, 1, 1), metallic=1.0, roughness=rough))
    assert np.all(metal <= 1.0 + 0.02), metal
    assert metal.min() > 0.25  # UE4's k = (r+1)^2/8 loses energy at high roughness, but not most of it
    diffuse = _albedo(v, BRDFParams.uniform(1, (1, 1, 1), metallic=0.0, roughness=rough, specular=0.0))
    np.testing.assert_allclose(diffuse, 1.0, atol=0.01)
    painted = _albedo(v, BRDFParams.uniform(1, (0.8, 0.8, 0.8), roughness=rough, specular=0.5, clearcoat=1.0))
    assert np.all(painted <= 1.0 + 0.02), painted


def test_ggx_d_normalised():
    # int D(h) (n.h) dh = 1 over the hemisphere (uniform in cos theta).
    c = (np.arange(200_000) + 0.5) / 200_000
    for alpha in (0.05, 0.3, 1.0):
        integral = (ggx_d(c, np.full_like(c, alpha)) * c).mean() * 2 * np.pi
        assert abs(integral - 1.0) < 0.01, (alpha, integral)


@pytest.mark.parametrize("params", [
    BRDFParams.uniform(1, (0.5, 0.5, 0.5), roughness=0.4),
    BRDFParams.uniform(1, (0.9, 0.7, 0.3), metallic=1.0, roughness=0.25),
])
def test_brdf_sampling_matches_its_pdf(params):
    """Importance-sampled albedo E[f cos / pdf] equals the uniform estimate; the pdf integrates to <= 1."""
    n_s = 200_000
    rng = np.random.default_rng(1)
    v = np.tile(_dir_from(0.6, 0.2)[0], (n_s, 1))
    n = np.tile([0.0, 0.0, 1.0], (n_s, 1))
    p = params.take(np.zeros(n_s, int))
    l = sample_brdf(n, v, p, rng.random((n_s, 3)))
    pdf = brdf_pdf(n, v, l, p)
    f = eval_brdf(n, v, l, p)
    est = np.where(pdf[:, None] > 0, f * np.clip(l[:, 2:3], 0, 1) / np.maximum(pdf[:, None], 1e-300), 0).mean(0)
    ref = _albedo(v[0], params, 400_000, seed=2)
    np.testing.assert_allclose(est, ref, rtol=0.03, atol=2e-3)
    # pdf over the sphere integrates to 1 (mass below the horizon included): check with uniform sphere samples.
    d = rng.normal(size=(n_s, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    total = (brdf_pdf(n, v, d, p) * (d[:, 2] > 0)).mean() * 4 * np.pi
    assert 0.8 < total <= 1.02


def test_clearcoat_pdf_normalised():
    """The lobe mixture with a near-mirror clear coat still integrates to 1 (stratified quadrature)."""
    params = BRDFParams.uniform(1, (0.3, 0.02, 0.02), roughness=0.5, clearcoat=1.0)
    v = _dir_from(0.6, 0.2)
    # Integrate over l = reflect(v, h) in half-vector space: dl = 4 (v.h) dh; h on a fine grid near n.
    m = 2000
    ct = 1 - ((np.arange(m) + 0.5) / m) ** 4  # dense near n.h = 1
    dct = 4 * ((np.arange(m) + 0.5) / m) ** 3 / m
    phi = (np.arange(256) + 0.5) / 256 * 2 * np.pi
    C, P = np.meshgrid(ct, phi, indexing="ij")
    st_ = np.sqrt(1 - C**2)
    h = np.stack([st_ * np.cos(P), st_ * np.sin(P), C], -1).reshape(-1, 3)
    w = np.repeat(dct, 256) * (2 * np.pi / 256)
    vv = np.tile(v, (len(h), 1))
    l = reflect(vv, h)
    vh = np.einsum("ij,ij->i", vv, h)
    ok = vh > 0
    pdf = brdf_pdf(np.tile([0.0, 0, 1], (len(h), 1)), vv, l, params.take(np.zeros(len(h), int)))
    # the diffuse lobe is not reflect-shaped; integrate only the specular + coat mass via the half-vector measure
    probs = params.lobe_probs[0]
    spec_mass = ((pdf - probs[0] * np.clip(l[:, 2], 0, None) / np.pi) * 4 * vh * w * ok).sum()
    assert abs(spec_mass - (probs[1] + probs[2])) < 0.02 * (probs[1] + probs[2])


def test_tangent_frame_orthonormal():
    n = np.random.default_rng(0).normal(size=(1000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[0] = [0, 0, -1]
    t, b = tangent_frame(n)
    for a, c in ((t, b), (t, n), (b, n)):
        np.testing.assert_allclose(np.einsum("ij,ij->i", a, c), 0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)


def test_fibonacci_hemisphere_is_equal_area():
    d = fibonacci_hemisphere(512)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert d[:, 2].min() >= 0
    # cos-weighted sum x 2pi/N = pi (irradiance of a unit uniform sky).
    assert abs(d[:, 2].sum() * 2 * np.pi / 512 - np.pi) < 1e-3
    assert np.abs(d[:, :2].mean(axis=0)).max() < 0.01


def test_cosine_hemisphere_pdf():
    rng = np.random.default_rng(0)
    d, pdf = cosine_hemisphere(rng.random(100_000), rng.random(100_000))
    np.testing.assert_allclose(pdf, d[:, 2] / np.pi)
    assert abs(d[:, 2].mean() - 2 / 3) < 0.01  # E[cos] under a cosine pdf


def test_sample_cone_stays_in_the_disc():
    axis = np.array([0.3, -0.8, 0.5])
    axis /= np.linalg.norm(axis)
    rng = np.random.default_rng(0)
    d = sample_cone(axis, np.radians(2.0), rng.random(10_000), rng.random(10_000))
    cosang = d @ axis
    assert cosang.min() >= np.cos(np.radians(2.0)) - 1e-12
    assert cosang.min() < np.cos(np.radians(1.8))  # fills the disc, not just the centre


def test_env_sampler_pdf_is_consistent():
    rng = np.random.default_rng(0)
    env = rng.random((16, 32, 3)).astype(np.float32)
    env[3, 7] = 500.0  # a sun-like hot pixel must get most samples
    s = EnvSampler.build(env)
    omega = equirect_solid_angles(16, 32)
    assert abs((s.pmf.reshape(16, 32)).sum() - 1) < 1e-9
    d, pdf = s.sample(rng.random((50_000, 3)))
    np.testing.assert_allclose(s.pdf(d), pdf, rtol=1e-9)
    assert np.all(np.abs(np.linalg.norm(d, axis=1) - 1) < 1e-9)
    # E[1 / pdf] = 4 pi (unbiased estimate of the sphere's solid angle).
    assert abs(np.mean(1 / pdf) / (4 * np.pi) - 1) < 0.05
    frac_hot = s.pmf.reshape(16, 32)[3, 7]
    assert frac_hot > 0.5 and frac_hot == pytest.approx(s.pmf.max())
    assert omega.sum() == pytest.approx(4 * np.pi)


def test_irradiance_map_matches_direct_integration():
    rng = np.random.default_rng(3)
    env = (rng.random((64, 128, 3)) * np.linspace(2, 0.1, 64)[:, None, None]).astype(np.float32)
    E = irradiance_map(env)
    for n in ([0, -1.0, 0], [0.6, -0.3, 0.74], [0, 1.0, 0]):
        n = np.asarray(n) / np.linalg.norm(n)
        np.testing.assert_allclose(lookup_irradiance(E, n[None])[0], hemisphere_irradiance(env, n), rtol=0.01)
    tables = environment_tables(env)
    assert environment_tables(env.copy()) is tables and tables.irradiance is tables.irradiance  # built once per content
    np.testing.assert_array_equal(tables.irradiance, E)
    env[0, 0] += 1.0  # changed in place: new content, new tables
    assert environment_tables(env) is not tables


@pytest.mark.parametrize("nv,rough,metallic", [(0.9, 0.5, 1.0), (0.3, 1.0, 1.0), (0.6, 0.2, 0.0), (0.5, 0.8, 0.3)])
def test_specular_albedo_table_matches_integration(nv, rough, metallic):
    """The tabulated GGX-lobe albedo equals the directional albedo integrated by brute force."""

    params = BRDFParams.uniform(1, (0.9, 0.6, 0.05), metallic, rough, 0.5)
    v = np.array([np.sqrt(1 - nv * nv), 0.0, nv])
    brute = _albedo(v, params, 400_000) - params.c_diff[0]  # minus the Lambertian part
    np.testing.assert_allclose(specular_albedo(np.array([nv]), params)[0], brute, rtol=0.04, atol=2e-3)


def test_texel_moments_are_exact_integrals():
    """m = int_texel d dw: summed over the sphere it vanishes, and n . m integrates a cosine exactly."""

    m = equirect_texel_moments(16, 32)
    np.testing.assert_allclose(m.sum(axis=(0, 1)), 0.0, atol=1e-12)
    # The upper hemisphere (rows above the equator) gives int max(0, up . d) dw = pi.
    up = np.array([0.0, -1.0, 0.0])
    np.testing.assert_allclose((m[:8] @ up).sum(), np.pi, rtol=1e-12)
