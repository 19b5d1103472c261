"""The photo's veil (haze + veiling glare) measured from an image with depth, and applied to an inserted object."""

import dataclasses

import numpy as np
import pytest

from render_fixtures import ground_scene, primitive_car, sunny_light
from streetaug.augment.core import hdr_to_ldr_uint8, ldr_uint8_to_hdr, pose_camera_to_transform
from streetaug.augment.render import QUALITY_PRESETS, Veil, estimate_veil, render_insertion
from streetaug.augment.render.veil import MAX_VEIL_FRACTION, dark_channel_blocks

W, H = 640, 360
K = np.array([[506.0, 0.0, 320.0], [0.0, 506.0, 180.0], [0.0, 0.0, 1.0]])
AIRLIGHT = np.array([0.80, 0.85, 0.95])


def textured_scene(seed: int = 0):
    """Linear radiance (H, W, 3) of a ground plane with random albedo blocks, 8 % of them black (tyres, the ground
    under cars), its depth (H, W) and the sky (inf) above the horizon; ev of the scene."""
    _, depth, ev = ground_scene(sunny_light(), K=K, width=W, height=H)
    rng = np.random.default_rng(seed)
    blocks = rng.uniform(0.15, 0.6, (H // 8 + 1, W // 8 + 1, 1)) * rng.uniform(0.8, 1.2, (H // 8 + 1, W // 8 + 1, 3))
    blocks[rng.random(blocks.shape[:2]) < 0.08] = 0.0
    J = np.kron(blocks, np.ones((8, 8, 1)))[:H, :W]
    J = np.where(np.isfinite(depth)[..., None], J, AIRLIGHT)  # the sky is the airlight
    return J, depth, ev


def hazy(J: np.ndarray, depth: np.ndarray, beta_per_m: float, glare: float, ev: float) -> np.ndarray:
    """uint8 image of ``J`` through air of extinction ``beta_per_m`` plus a uniform veiling glare ``glare``."""
    t = np.where(np.isfinite(depth), np.exp(-beta_per_m * np.where(np.isfinite(depth), depth, 0.0)), 0.0)[..., None]
    return hdr_to_ldr_uint8(J * t + AIRLIGHT * (1.0 - t) + glare * AIRLIGHT, ev)


@pytest.mark.parametrize("beta,glare", [(0.002, 0.0), (0.004, 0.0), (0.002, 0.01), (0.0, 0.02)])
def test_recovers_known_haze_and_glare(beta, glare):
    J, depth, ev = textured_scene()
    veil = estimate_veil(hazy(J, depth, beta, glare, ev), depth, ev)
    np.testing.assert_allclose(veil.airlight_rgb / veil.airlight_rgb.max(), AIRLIGHT / AIRLIGHT.max(), atol=0.03)
    for d in (10.0, 20.0, 30.0, 40.0):
        # the veil's share of the airlight at d: (1 - t) + glare (the glare counts as airlight)
        expected = 1.0 - np.exp(-beta * d) + glare
        got = float(veil.haze_at(np.array(d)))
        assert abs(got - expected) < 0.25 * expected + 0.004, (d, got, expected)


def test_clear_air_has_no_veil():
    J, depth, ev = textured_scene(1)
    veil = estimate_veil(hazy(J, depth, 0.0, 0.0, ev), depth, ev)
    assert float(np.max(veil.haze_at(np.array([5.0, 20.0, 60.0])))) < 0.003


def test_veil_never_decreases_with_depth_and_is_capped():
    """A scene with nothing dark far away (a bright wall beyond 30 m) bounds the veil only from above:
    nearer, darker bins keep it low, and it never exceeds its cap."""
    J, depth, ev = textured_scene(2)
    J = np.where((depth > 30.0)[..., None] & np.isfinite(depth)[..., None], 0.9, J)
    veil = estimate_veil(hazy(J, depth, 0.002, 0.0, ev), depth, ev)
    assert np.all(np.diff(veil.floor) >= 0)
    assert float(veil.haze_at(np.array(20.0))) < 0.08
    median = np.median(ldr_uint8_to_hdr(hazy(J, depth, 0.002, 0.0, ev), ev) @ [0.2126, 0.7152, 0.0722])
    assert veil.floor.max() <= MAX_VEIL_FRACTION * median * 1.05


def test_a_scene_with_nothing_dark_shows_no_veil():
    """A flat grey road and a grey wall (no dark things at any depth) bound the veil but do not show it: the
    dark channel there is the grey content, not haze (the Mitsuba reference scene is such a ground plane)."""
    J, depth, ev = textured_scene(3)
    J = np.where(np.isfinite(depth)[..., None], np.array([0.2, 0.2, 0.2]), AIRLIGHT)
    veil = estimate_veil(hazy(J, depth, 0.0, 0.0, ev), depth, ev)
    assert float(np.max(veil.haze_at(np.array([5.0, 20.0, 60.0])))) == 0.0
    # the same grey scene with a few dark things in it does show the haze it is seen through
    J2, _, _ = textured_scene(3)
    J2 = np.where((J2.max(axis=2, keepdims=True) == 0.0), 0.0, J)
    veil = estimate_veil(hazy(J2, depth, 0.004, 0.0, ev), depth, ev)
    assert float(veil.haze_at(np.array(20.0))) > 0.5 * (1.0 - np.exp(-0.004 * 20.0))


def test_dark_channel_blocks_is_the_block_minimum():
    img = np.random.default_rng(0).integers(0, 256, (40, 64, 3), dtype=np.uint8)
    dc = dark_channel_blocks(img)
    block_min = img.min(axis=2).reshape(10, 4, 16, 4).min(axis=(1, 3))
    assert dc.shape == (10, 16)
    assert dc[5, 8] == block_min[4:7, 7:10].min()


def test_no_depth_means_no_veil():
    img = np.full((H, W, 3), 120, np.uint8)
    veil = estimate_veil(img, np.full((H, W), np.inf, np.float32))
    out = veil.apply(np.full((2, 2, 3), 0.3, np.float32), np.ones((2, 2)), np.full((2, 2), 20.0))
    np.testing.assert_allclose(out, 0.3)


def _dark_level(image: np.ndarray, mask: np.ndarray) -> float:
    return float(np.percentile(image.min(axis=2)[mask], 2))


def test_inserted_car_gets_the_veil_of_its_neighbours():
    """In a hazy image, the car seen through the image's veil has dark levels (2nd percentile of min RGB)
    closer to those of the dark things at its distance, and less contrast, than without it."""
    J, depth, ev = textured_scene(3)
    image = hazy(J, depth, 0.006, 0.01, ev)
    T = pose_camera_to_transform(0.0, 1.5, 20.0, 60.0)
    quality = dataclasses.replace(QUALITY_PRESETS["draft"], match_camera=True)
    kw = dict(quality=quality, ev=ev, seed=0)
    light = sunny_light()
    car = primitive_car()
    clear = render_insertion(image, K, depth, light, car, T, veil=Veil.none(), **kw)
    veiled = render_insertion(image, K, depth, light, car, T, **kw)  # estimated from the image
    inner = clear.coverage > 0.99
    assert inner.sum() > 500
    near = np.isfinite(depth) & (np.abs(depth - 20.0) < 3.0) & (J.max(axis=2) == 0.0) & (clear.coverage == 0)
    neighbours = _dark_level(image, near)
    before, after = _dark_level(clear.image, inner), _dark_level(veiled.image, inner)
    assert after > before + 3
    assert abs(after - neighbours) < abs(before - neighbours)
    y_before, y_after = clear.image[inner].mean(axis=1), veiled.image[inner].mean(axis=1)
    assert y_after.std() / y_after.mean() < y_before.std() / y_before.mean()


def test_without_the_camera_look_the_veil_changes_nothing():
    """The veil is part of the camera look: with ``match_camera`` off (the Mitsuba reference benchmark's
    setting) the composite is byte-identical whatever veil is given."""
    J, depth, ev = textured_scene(4)
    image = hazy(J, depth, 0.006, 0.01, ev)
    T = pose_camera_to_transform(0.0, 1.5, 20.0, 60.0)
    off = dataclasses.replace(QUALITY_PRESETS["draft"], match_camera=False)
    strong = Veil(np.array([0.0, 100.0]), np.array([0.3, 0.3]), np.ones(3))
    a = render_insertion(image, K, depth, sunny_light(), primitive_car(), T, quality=off, ev=ev, seed=0)
    b = render_insertion(image, K, depth, sunny_light(), primitive_car(), T, quality=off, ev=ev, seed=0, veil=strong)
    assert a.coverage.sum() > 500
    np.testing.assert_array_equal(a.image, b.image)


def test_shadow_darkens_only_what_is_behind_the_veil():
    veil = Veil(np.array([0.0, 100.0]), np.array([0.0, 0.1]), np.ones(3))  # V = 0.02 at 20 m
    image = np.full((2, 2, 3), 128, np.uint8)
    I = float(ldr_uint8_to_hdr(np.array([128], np.uint8))[0])
    depth = np.array([[20.0, 20.0], [np.inf, 20.0]])
    S = np.array([[0.2, 1.0], [0.2, 0.5]])[..., None] * np.ones(3)
    out = veil.shadow_ratio(S, image, depth)
    np.testing.assert_allclose(out[0, 0] * I, (I - 0.02) * 0.2 + 0.02, rtol=1e-5)
    np.testing.assert_allclose(out[0, 1], 1.0)
    np.testing.assert_allclose(out[1, 0], 0.2, rtol=1e-6)  # the sky: no veil kept
    np.testing.assert_allclose(out[1, 1] * I, (I - 0.02) * 0.5 + 0.02, rtol=1e-5)


def test_inserted_shadow_keeps_the_veil_of_its_ground():
    """In a hazy image the car's shadow core is no darker than the veil at its depth (it was, without it)."""
    J, depth, ev = textured_scene(5)
    J = np.where(np.isfinite(depth)[..., None], 0.3, J)  # a plain ground: the shadow alone makes it dark
    J[np.isfinite(depth) & (np.arange(W)[None, :] % 97 < 3)] = 0.0  # a few black stripes give the dark channel
    image = hazy(J, depth, 0.006, 0.01, ev)
    T = pose_camera_to_transform(0.0, 1.5, 20.0, 60.0)
    quality = dataclasses.replace(QUALITY_PRESETS["draft"], match_camera=True)
    veil = estimate_veil(image, depth, ev)
    clear = render_insertion(image, K, depth, sunny_light(), primitive_car(), T, quality=quality, ev=ev, seed=0,
                             veil=Veil.none())
    veiled = render_insertion(image, K, depth, sunny_light(), primitive_car(), T, quality=quality, ev=ev, seed=0,
                              veil=veil)
    core = (clear.shadow_ratio < 0.3) & (clear.coverage == 0) & (J.max(axis=2) > 0)
    assert core.sum() > 50
    V = veil.haze_at(depth[core])[:, None] * veil.airlight_rgb
    lin_clear = ldr_uint8_to_hdr(clear.image, ev)[core]
    lin_veiled = ldr_uint8_to_hdr(veiled.image, ev)[core]
    assert np.median(lin_clear.min(axis=1) / V.min(axis=1)) < 0.9
    assert np.median(lin_veiled.min(axis=1) / V.min(axis=1)) > 0.95
