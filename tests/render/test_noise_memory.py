"""add_object_noise draws its noise in row chunks: the bytes and the random stream of one whole-box draw,
without its float64 frame (~50 MB for a near object's 1600 x 900 box)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from streetaug.augment.render import camera_effects
from streetaug.augment.render.camera_effects import QUANT_NOISE, add_object_noise


def _dense(image_rgb, alpha, noise_sigma, rng):
    """The one-draw formula (the chunked one must give its bytes)."""
    extra = float(np.sqrt(max(noise_sigma**2 - QUANT_NOISE**2, 0.0)))
    out = image_rgb.astype(np.float32) / 255.0
    noise = rng.normal(0.0, extra, size=image_rgb.shape).astype(np.float32) * alpha[..., None]
    return np.clip(np.round((out + noise) * 255.0), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(180, 320), (41, 7), (300, 1)])
def test_chunked_noise_is_the_one_draw(shape, monkeypatch):
    monkeypatch.setattr(camera_effects, "NOISE_CHUNK_PX", 1000)  # many chunks, some without the object
    g = np.random.default_rng(2)
    h, w = shape
    image = g.integers(0, 256, (h, w, 3), dtype=np.uint8)
    alpha = np.zeros((h, w), np.float32)
    alpha[h // 3 : h // 2 + 1] = g.random((h // 2 + 1 - h // 3, w), dtype=np.float32)
    r_new, r_old = np.random.default_rng(9), np.random.default_rng(9)
    out = add_object_noise(image, alpha, 0.02, r_new)
    expected = _dense(image, alpha, 0.02, r_old)
    assert out.dtype == np.uint8 and np.array_equal(out, expected)
    assert (out != image).any() and np.array_equal(out[: h // 3], image[: h // 3])
    assert r_new.random() == r_old.random()  # the stream after it is the same


def test_noise_does_not_allocate_a_float64_frame():
    h, w = 900, 1600
    image = np.full((h, w, 3), 128, np.uint8)
    alpha = np.ones((h, w), np.float32)
    tracemalloc.start()
    try:
        add_object_noise(image, alpha, 0.02, np.random.default_rng(0))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < image.nbytes + 12 * 2**20  # the output and a few chunk buffers, not 35 MB of float64 noise
