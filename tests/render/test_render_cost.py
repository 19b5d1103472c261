"""Where the renderer spends less: the sky deficit coarse-to-fine (default), no Monte Carlo residual in the
inner edge samples (optional, INNER_RESIDUAL False) -- each against the full evaluation."""

import numpy as np
import pytest

import streetaug.augment.render.foreground as foreground
import streetaug.augment.render.shadow as shadow
from render_fixtures import primitive_car, sunny_light
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.render import RenderSettings, footprint, prepare_asset, render_insertion
from streetaug.augment.render.bounce import BounceLight

W, H = 480, 270
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])


def _grid_fill(f, hl=40, wl=56, valid=None):
    """D0 of a (hl, wl) grid from ``f(iy, ix)`` through the coarse-to-fine fill; returns it and the evaluated cells."""
    valid = np.ones(hl * wl, bool) if valid is None else valid
    D0, C = np.zeros((hl * wl, 3)), np.zeros((hl * wl, 3))
    seen = []

    def evaluate(cells):
        seen.append(cells)
        iy, ix = np.divmod(cells, wl)
        D0[cells] = f(iy, ix)[:, None]
        C[cells] = 0.5 * f(iy, ix)[:, None]

    shadow._coarse_to_fine_cells(hl, wl, valid, evaluate, D0, C, np.ones(3), {})
    return D0[:, 0].reshape(hl, wl), np.concatenate(seen)


def test_coarse_to_fine_smooth_field_is_interpolated_and_a_step_is_evaluated():
    smooth, cells = _grid_fill(lambda iy, ix: 0.0005 * iy + 0.0003 * ix)  # gentle: nodes suffice
    iy, ix = np.mgrid[0:40, 0:56]
    np.testing.assert_allclose(smooth, 0.0005 * iy + 0.0003 * ix, atol=1e-12)
    assert len(cells) < 40 * 56 / 8  # few evaluations
    step, cells = _grid_fill(lambda iy, ix: np.where(ix >= 23, 0.5, 0.0))  # a sharp edge: exact everywhere
    np.testing.assert_array_equal(step, np.where(ix >= 23, 0.5, 0.0))
    assert len(cells) < 40 * 56 / 2  # but not the whole grid
    # every cell evaluated at most once
    assert len(np.unique(cells)) == len(cells)


def test_coarse_to_fine_keeps_invalid_cells_zero():
    valid = np.ones(40 * 56, bool).reshape(40, 56)
    valid[:, :10] = False
    out, cells = _grid_fill(lambda iy, ix: np.full(len(iy), 0.3), valid=valid.ravel())
    assert np.all(out[:, :10] == 0) and np.allclose(out[:, 10:], 0.3)
    assert valid.ravel()[cells].all()


def _shadow(light, car, T, seed=0):
    prep = prepare_asset(car)
    depth = ground_plane_depth(K, W, H, UP, 1.5)
    settings = RenderSettings()
    bounce = BounceLight.build(light, prep, T, UP)
    box = footprint(CAMERA, car, T, light, settings).shadow_box
    return shadow.render_shadow(CAMERA, box, depth, light, prep, T, UP, settings, np.random.default_rng(seed), bounce)


@pytest.mark.parametrize("distance_m", [6.0, 15.0])
def test_shadow_ratio_coarse_to_fine_matches_every_cell(monkeypatch, distance_m):
    """The ratio map with the coarse-to-fine sky deficit is the one of every cell evaluated (to noise)."""
    light, car = sunny_light(), primitive_car()
    T = pose_camera_to_transform(0.0, 1.5, distance_m, 60.0)
    fast = _shadow(light, car, T)
    monkeypatch.setattr(shadow, "SKY_COARSE_STEP", 1)
    full, other_seed = _shadow(light, car, T), _shadow(light, car, T, seed=1)
    a, b, c = (s.ratio_rgb.mean(axis=2) for s in (fast, full, other_seed))
    assert b.min() < 0.7  # a real shadow
    assert fast.stats["rays"]["shadow_sky"] < 0.9 * full.stats["rays"]["shadow_sky"]
    # the difference is the Monte Carlo noise between two seeds (sun-edge jitter, sky lattice rotations)
    noise = np.abs(b - c)
    assert np.abs(a - b).mean() < 1.2 * noise.mean() + 1e-3
    assert np.percentile(np.abs(a - b), 99) < 1.2 * np.percentile(noise, 99) + 2e-3


def _render(seed=0):
    light, car = sunny_light(), primitive_car()
    T = pose_camera_to_transform(0.0, 1.5, 7.0, 60.0)
    image = np.full((H, W, 3), 110, np.uint8)
    depth = ground_plane_depth(K, W, H, UP, 1.5)
    settings = RenderSettings(match_camera=False)
    return render_insertion(image, K, depth, light, car, T, UP, quality=settings, seed=seed)


def test_residual_free_inner_samples_match_the_full_render(monkeypatch):
    """A near car: fewer light samples, the same object radiance (within the Monte Carlo noise)."""
    full = _render()  # default: the inner edge samples sample the residual too
    monkeypatch.setattr(foreground, "INNER_RESIDUAL", False)
    fast = _render()
    assert fast.stats["rays"]["shade_visibility"] < 0.97 * full.stats["rays"]["shade_visibility"]
    np.testing.assert_array_equal(fast.coverage, full.coverage)  # coverage from every sample either way
    m = (fast.mask > 0.99) & (full.mask > 0.99)
    a, b = fast.object_radiance[m], full.object_radiance[m]
    assert m.sum() > 2000
    rel = np.abs(a.mean(axis=0) - b.mean(axis=0)) / b.mean(axis=0)
    assert np.all(rel < 0.02)  # no bias
    edge = (full.mask > 0.05) & (full.mask < 0.95)
    assert np.abs(fast.image[edge].astype(float) - full.image[edge]).mean() < 4.0
