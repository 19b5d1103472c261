"""The camera's neutral axis (its tone-dependent colour cast) is measured in the image and carried to the
object's pixels (:mod:`streetaug.augment.render.camera_look`)."""

import numpy as np

from streetaug.augment.render.camera_look import apply_neutral_axis, neutral_axis


def _cast_image(green_dn: float, below: float, seed: int = 0) -> np.ndarray:
    """A noisy grey-ramp image whose neutral pixels have G ``green_dn`` above R and B at levels < ``below``."""
    rng = np.random.default_rng(seed)
    level = np.tile(np.linspace(4, 240, 400), (200, 1))
    img = np.repeat(level[..., None], 3, axis=2) + rng.normal(0, 1.0, (200, 400, 3))
    dark = level < below
    img[..., 1] += np.where(dark, 2.0 / 3.0 * green_dn, 0.0)
    img[..., 0] -= np.where(dark, green_dn / 3.0, 0.0)
    img[..., 2] -= np.where(dark, green_dn / 3.0, 0.0)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def test_neutral_axis_finds_a_dark_green_cast_and_none_where_there_is_none():
    axis = neutral_axis(_cast_image(3.0, 100.0), step=1)
    g_minus_r = axis.offset_at(np.array([20.0, 50.0, 160.0, 220.0]))
    g_minus_r = g_minus_r[:, 1] - g_minus_r[:, 0]
    assert np.all(np.abs(g_minus_r[:2] - 3.0) < 0.8), g_minus_r
    assert np.all(np.abs(g_minus_r[2:]) < 0.5), g_minus_r
    flat = neutral_axis(_cast_image(0.0, 100.0), step=2)
    assert np.abs(flat.offsets_dn).max() < 0.5


def test_a_neutral_object_takes_the_images_cast_only_where_its_alpha_is():
    axis = neutral_axis(_cast_image(3.0, 100.0), step=1)
    obj = np.full((20, 40, 3), 50, np.uint8)  # a neutral grey object at a dark-mid level
    alpha = np.zeros((20, 40), np.float32)
    alpha[:, :20] = 1.0
    alpha[:, 20:30] = 0.5
    out = apply_neutral_axis(obj, alpha, axis).astype(int)
    full, half, none = out[:, :20], out[:, 20:30], out[:, 30:]
    assert np.all(full[..., 1] - full[..., 0] >= 2)  # G - R ~ 2.8: the image's cast (3)
    assert np.all(half[..., 1] - half[..., 0] >= 1) and np.all(half[..., 1] - half[..., 0] <= 2)
    assert np.array_equal(none, obj[:, 30:])
    bright = np.full((4, 4, 3), 200, np.uint8)
    assert np.array_equal(apply_neutral_axis(bright, np.ones((4, 4), np.float32), axis), bright)


def test_a_tinted_scene_is_not_taken_for_the_camera():
    """A strongly green scene (no near-neutral pixels) yields no cast, and offsets are bounded."""
    rng = np.random.default_rng(1)
    img = np.zeros((100, 100, 3), np.uint8)
    img[..., 1] = rng.integers(60, 120, (100, 100))
    img[..., 0] = img[..., 1] // 2
    img[..., 2] = img[..., 1] // 3
    axis = neutral_axis(img, step=1)
    assert np.abs(axis.offsets_dn).max() < 1e-9


def test_a_yellow_tint_of_the_neutral_pixels_is_left_to_the_scene():
    """Blue-yellow offsets (the road's own tint) are not carried; only the red-green axis is."""
    img = _cast_image(0.0, 100.0).astype(int)
    img[..., 2] = np.clip(img[..., 2] - 3, 0, 255)  # yellowish: B 3 DN below R and G everywhere
    axis = neutral_axis(img.astype(np.uint8), step=1)
    assert np.abs(axis.offsets_dn).max() < 0.3, axis.offsets_dn
