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


def _albedo_sampled(v: np.ndarray, params: BRDFParams, n_samples: int, seed: int) -> np.ndarray:
    """``int f(v, l) cos dl`` (3,) by BRDF importance sampling (narrow lobes: the clear coat) around n = +z."""
    n, vv = np.tile([0.0, 0.0, 1.0], (n_samples, 1)), np.tile(v, (n_samples, 1))
    p = params.take(np.zeros(n_samples, int))
    l = sample_brdf(n, vv, p, np.random.default_rng(seed).random((n_samples, 3)))
    pdf = brdf_pdf(n, vv, l, p)
    ok = (l[:, 2] > 0) & (pdf > 0)
    return np.where(ok[:, None], eval_brdf(n, vv, l, p) * l[:, 2:3] / np.where(ok, pdf, 1.0)[:, None], 0.0).mean(axis=0)


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


@pytest.mark.parametrize("theta,rough", [(0.3, 0.35), (1.2, 0.35), (0.8, 0.05), (1.45, 0.05)])
def test_mirror_variate_expectation_is_the_lobes_integral(theta, rough):
    """The shader's near-mirror control variate (clear coat, glass): its closed form is the MC integral."""
    from streetaug.augment.render.brdf import mirror_albedo, mirror_lobes

    M = 200_000
    v1 = np.array([np.sin(theta), 0.0, np.cos(theta)])
    p = BRDFParams.uniform(M, **dict(PAINT, roughness=rough))
    w = np.full(M, 1.0 if rough < 0.1 else 0.0)
    n, v = np.tile([0.0, 0.0, 1.0], (M, 1)), np.tile(v1, (M, 1))
    l = sample_brdf(n, v, p, np.random.default_rng(5).random((M, 3)))
    pdf = brdf_pdf(n, v, l, p)
    ok = (l[:, 2] > 0) & (pdf > 0)
    mc = np.where(ok[:, None], mirror_lobes(n, v, l, p, w) * l[:, 2:3] / np.where(ok, pdf, 1.0)[:, None], 0.0).mean(0)
    np.testing.assert_allclose(mirror_albedo(v1[2:3], p.take(np.array([0])), w[:1])[0], mc, rtol=0.02)


def test_shading_under_a_uniform_sky_is_unbiased_with_flakes_and_mirror_variates():
    """A convex sphere under a uniform map L: outgoing radiance = L x albedo, whatever the variates do."""
    from render_fixtures import sphere_asset
    from streetaug.augment.core import pose_camera_to_transform
    from streetaug.augment.lighting.light import DistantLight
    from streetaug.augment.render import RenderSettings, prepare_asset
    from streetaug.augment.render.environment import environment_tables
    from streetaug.augment.render.shade import ShadingContext, shade

    prep = prepare_asset(sphere_asset(1.0))
    T = pose_camera_to_transform(0.0, 1.5, 10.0, 0.0)
    light = DistantLight(np.full((32, 64, 3), 0.5, np.float32), None)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(3000, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = d + [0.0, 0.0, 1.0] + 1e-3 * d
    v = -T[:3, :3].T @ T[:3, 3] - p
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    keep = np.einsum("ij,ij->i", v, d) > 0.1
    p, n, v = p[keep], d[keep], v[keep]
    for kw in (dict(PAINT), dict(PAINT, flake=0.8), dict(PAINT, roughness=0.05, clearcoat=0.0)):
        params = BRDFParams.uniform(len(p), **kw)
        out = []
        for seed in range(6):
            ctx = ShadingContext.for_object(prep, light, environment_tables(light.envmap), T, RenderSettings(),
                                            np.random.default_rng(seed), np.zeros(3), np.zeros(3))
            smooth, noisy = shade(ctx, p, n, n, v, params)
            out.append((smooth + noisy).mean(axis=0))
        # Isotropic: only n.v matters; the view in the local frame of n.  Every 10th point: the smooth glass's pane
        # Fresnel rises steeply at grazing n.v, and every 40th point mis-estimated its mean by up to 7 %.
        nv = np.einsum("ij,ij->i", n, v)[::10]
        albedo = np.mean([_albedo_sampled(np.array([np.sqrt(1 - c * c), 0.0, c]), BRDFParams.uniform(1, **kw), 20_000, i)
                          for i, c in enumerate(nv)], axis=0)
        np.testing.assert_allclose(np.mean(out, axis=0), 0.5 * albedo, rtol=0.04, atol=0.004)


def test_flake_energy_column_equals_the_2d_albedo_table():
    """The 1-D column lookup (the shader calls it per sample) gives the 2-D table's values, clamped the same."""
    from streetaug.augment.render.brdf import BRDFParams, FLAKE_ROUGHNESS, specular_albedo

    x = np.concatenate([np.linspace(-0.1, 1.1, 2001), [0.0, 1.0, 0.5 / 32, 1 - 0.5 / 32]])
    white = BRDFParams.uniform(len(x), base_color=(1.0, 1.0, 1.0), metallic=1.0, roughness=FLAKE_ROUGHNESS)
    np.testing.assert_allclose(flake_energy(x), specular_albedo(x, white)[:, 0], rtol=0, atol=1e-12)
