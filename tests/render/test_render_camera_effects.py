"""Blur / noise estimation of an image and matching the inserted object to it."""

import dataclasses

import cv2
import numpy as np
import pytest

from render_fixtures import degrade, primitive_car, sharp_polygons, sunny_light
from streetaug.augment.core import InputError, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.render import QUALITY_PRESETS, render_insertion
from streetaug.augment.render.camera_effects import (
    CameraEffects,
    add_object_noise,
    blur_object_layer,
    estimate_blur_sigma,
    estimate_camera_effects,
    estimate_noise_sigma,
)


@pytest.fixture(scope="module")
def sharp():
    return sharp_polygons(0, 320, 180, n_polygons=25, radius_px=(15, 60))


@pytest.mark.parametrize("blur,noise", [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (1.0, 3.0), (1.5, 6.0)])
def test_estimates_known_blur_and_noise(sharp, blur, noise):
    e = estimate_camera_effects(degrade(sharp, blur, noise))
    assert isinstance(e, CameraEffects) and e.edge_pixels > 100
    assert abs(e.blur_sigma_px - blur) < 0.25, (e.blur_sigma_px, blur)
    assert abs(255 * e.noise_sigma - noise) < 0.1 * noise + 0.3, (255 * e.noise_sigma, noise)


def test_noise_estimate_ignores_edges(sharp):
    """A sharp image full of edges and no noise: the noise estimate stays at (near) zero."""
    assert 255 * estimate_noise_sigma(degrade(sharp, 0.0, 0.0)) < 0.3


def test_estimates_restricted_to_a_mask(sharp):
    img = degrade(sharp, 0.0, 0.0)
    noisy = degrade(sharp, 0.0, 8.0)
    half = np.zeros(img.shape[:2], bool)
    half[:, : img.shape[1] // 2] = True
    mixed = np.where(half[..., None], noisy, img)
    assert abs(255 * estimate_noise_sigma(mixed, half) - 8.0) < 1.0
    assert 255 * estimate_noise_sigma(mixed, ~half) < 0.5
    blurred = degrade(sharp, 2.0, 0.0)
    mixed = np.where(half[..., None], blurred, img)
    b_left, _ = estimate_blur_sigma(mixed, mask=half)
    b_right, _ = estimate_blur_sigma(mixed, mask=~half)
    assert b_left > 1.5 and b_right < 0.5


def test_flat_image_has_no_edges():
    blur, n = estimate_blur_sigma(np.full((64, 64, 3), 120, np.uint8))
    assert blur == 0.0 and n == 0


def test_bad_image():
    with pytest.raises(InputError, match="uint8"):
        estimate_camera_effects(np.zeros((8, 8, 3), np.float32))


def test_blur_keeps_premultiplied_layer_consistent():
    rad = np.zeros((40, 40, 3), np.float32)
    alpha = np.zeros((40, 40), np.float32)
    alpha[10:30, 10:30] = 1.0
    rad[10:30, 10:30] = [0.5, 0.2, 0.1]
    rb, ab = blur_object_layer(rad, alpha, 1.5)
    assert ab.max() <= 1.0 and ab[20, 20] > 0.99 and 0 < ab[20, 9] < 0.5
    inside = ab > 0.05
    np.testing.assert_allclose(rb[inside] / ab[inside, None], np.broadcast_to([0.5, 0.2, 0.1], rb[inside].shape), rtol=1e-4)
    np.testing.assert_allclose(rb.sum(axis=(0, 1)), rad.sum(axis=(0, 1)), rtol=1e-3)  # energy kept
    same = blur_object_layer(rad, alpha, 0.0)
    assert same[0] is rad and same[1] is alpha


def test_object_noise_only_where_covered():
    img = np.full((50, 50, 3), 128, np.uint8)
    alpha = np.zeros((50, 50), np.float32)
    alpha[10:40, 10:40] = 1.0
    out = add_object_noise(img, alpha, 4.0 / 255, np.random.default_rng(0))
    np.testing.assert_array_equal(out[alpha == 0], img[alpha == 0])
    std = out[alpha == 1].astype(np.float64).std()
    assert 3.5 < std < 4.5


def test_match_camera_in_render_insertion():
    """With matching on, the object gets the image's noise and blur; off, the image is untouched elsewhere."""

    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    photo = cv2.resize(sharp_polygons(3, 320, 180, n_polygons=25, radius_px=(15, 60)), (W, H))
    image = degrade(photo, 1.5, 5.0)
    depth = np.full((H, W), np.inf, np.float32)
    T = pose_camera_to_transform(0.0, 1.0, 10.0, 60.0)
    light = sunny_light()
    car = primitive_car()
    off = dataclasses.replace(QUALITY_PRESETS["draft"], match_camera=False)
    a = render_insertion(image, K, depth, light, car, T, quality=off, seed=0)
    b = render_insertion(image, K, depth, light, car, T, quality="draft", seed=0)  # on by default
    inner = cv2.erode((a.coverage > 0.99).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    assert inner.sum() > 300
    assert 255 * estimate_noise_sigma(a.image, inner) < 2.0
    assert 255 * estimate_noise_sigma(b.image, inner) > 3.5
    assert abs(b.stats["camera_effects"]["blur_sigma_px"] - 1.5) < 0.35
    rim = (cv2.dilate((a.coverage > 0.5).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0) & (a.coverage < 0.5)
    # the blurred object bleeds a little over its silhouette: pixels just outside it change
    assert np.abs(b.image[rim].astype(int) - a.image[rim].astype(int)).mean() > 1.0
