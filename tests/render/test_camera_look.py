"""The camera's look: default on, off switch, motion-blur kernel, JPEG quality of a file."""

import dataclasses

import cv2
import numpy as np
import pytest

from streetaug.augment.render import QUALITY_PRESETS, RenderSettings
from streetaug.augment.render.camera_look import (
    image_motion_px,
    jpeg_quality_from_file,
    jpeg_quality_from_table,
    ijg_table,
    motion_kernel,
)


def test_match_camera_on_in_every_preset_and_switchable():
    assert RenderSettings().match_camera
    assert all(s.match_camera for s in QUALITY_PRESETS.values())
    assert not dataclasses.replace(QUALITY_PRESETS["default"], match_camera=False).match_camera


def test_motion_kernel_direction_and_length():
    K = np.array([[1000.0, 0, 800], [0, 1000.0, 450], [0, 0, 1]])
    m = image_motion_px(K, np.array([0.0, 0.0, 10.0]), np.array([10.0, 0.0, 0.0]), 0.004)  # 10 m/s across at 10 m
    np.testing.assert_allclose(m, [4.0, 0.0], atol=1e-9)
    for motion in ([4.0, 0.0], [0.0, 6.0], [3.0, 3.0]):
        k = motion_kernel(np.array(motion))
        assert abs(k.sum() - 1.0) < 1e-5
        ys, xs = np.mgrid[: k.shape[0], : k.shape[1]] - k.shape[0] // 2
        p = np.stack([xs.ravel(), ys.ravel()])
        mean = p @ k.ravel()
        cov = (p - mean[:, None]) * k.ravel() @ (p - mean[:, None]).T  # the kernel's second moments
        assert np.abs(mean).max() < 1e-6  # centred on the pixel
        w, v = np.linalg.eigh(cov)
        direction = v[:, 1]
        expect = np.array(motion) / np.hypot(*motion)
        assert abs(abs(direction @ expect) - 1.0) < 1e-3
        # a uniform segment of length L has variance L^2 / 12 along it (+ the splat's ~1/6 px^2)
        assert abs(np.sqrt(w[1] * 12.0) - np.hypot(*motion)) < 0.6
    assert motion_kernel(np.array([0.2, 0.1])).shape == (1, 1)


def test_jpeg_quality_from_file(tmp_path):
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.integers(0, 255, (64, 96, 3)).astype(np.uint8), (0, 0), 2.0)
    for q in (30, 55, 75, 80, 92):
        path = tmp_path / f"q{q}.jpg"
        cv2.imwrite(str(path), img, [cv2.IMWRITE_JPEG_QUALITY, q])
        assert jpeg_quality_from_file(path) == q
    png = tmp_path / "x.png"
    cv2.imwrite(str(png), img)
    assert jpeg_quality_from_file(png) is None
    assert jpeg_quality_from_table(ijg_table(64)) == 64


@pytest.fixture(scope="module")
def scene():
    from render_fixtures import degrade, primitive_car, sharp_polygons, sunny_light
    from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform

    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    image = degrade(sharp_polygons(3, W, H, n_polygons=25, radius_px=(15, 60)), 1.0, 3.0)
    return image, K, np.full((H, W), np.inf, np.float32), sunny_light(), primitive_car(), \
        pose_camera_to_transform(0.0, 1.0, 10.0, 60.0)


def _render(scene, **kw):
    from streetaug.augment.render import render_insertion

    image, K, depth, light, car, T = scene
    return render_insertion(image, K, depth, light, car, T, quality=kw.pop("quality", "draft"), seed=kw.pop("seed", 0), **kw)


def test_render_default_on_off_switch_and_determinism(scene):
    from streetaug.augment.render.camera_effects import estimate_noise_sigma

    on, again = _render(scene), _render(scene)
    off = _render(scene, quality=dataclasses.replace(QUALITY_PRESETS["draft"], match_camera=False))
    np.testing.assert_array_equal(on.image, again.image)  # deterministic by seed
    assert "camera_effects" in on.stats and "camera_effects" not in off.stats
    inner = cv2.erode((off.coverage > 0.99).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    assert 255 * estimate_noise_sigma(on.image, inner) > 2.0 > 255 * estimate_noise_sigma(off.image, inner)
    assert not np.array_equal(_render(scene, seed=1).image[inner], on.image[inner])


def test_motion_blur_smears_along_the_motion(scene):
    still = _render(scene)
    moving = _render(scene, velocity_cam_mps=np.array([20.0, 0.0, 0.0]), exposure_s=0.02)  # ~ 10 px to the right
    image = scene[0]

    def extent(ins):  # width and height (pixels) of the region the object changed
        ys, xs = np.nonzero(np.any(ins.image != image, axis=2) & (ins.shadow_ratio >= 1))
        return xs.max() - xs.min(), ys.max() - ys.min()

    (w0, h0), (w1, h1) = extent(still), extent(moving)
    assert w1 - w0 >= 6  # smeared ~ 10 px along u ...
    assert abs(h1 - h0) <= 2  # ... not along v


def test_jpeg_round_trip_only_in_touched_blocks(scene):
    plain = _render(scene)
    jpg = _render(scene, jpeg_quality=30)
    changed = np.any(jpg.image != plain.image, axis=2)
    assert changed.any()
    ys, xs = np.nonzero(plain.coverage > 0)
    assert not changed[: max(ys.min() - 32, 0)].any() and not changed[ys.max() + 32 :].any()


def test_motion_stays_bounded_near_the_camera_plane_and_for_wild_speeds():
    from streetaug.augment.render.camera_look import MAX_MOTION_PX, image_motion_px, motion_kernel

    K = np.array([[1266.0, 0, 800], [0, 1266.0, 450], [0, 0, 1]])
    # a car beside the camera (its shadow alone in view): its centre 1 cm in front of the camera plane
    assert np.all(image_motion_px(K, np.array([3.0, 1.0, 0.01]), np.array([0.0, 0.0, -10.0]), 0.002) == 0)
    k = motion_kernel(np.array([1.3e5, 2.0e4]))  # a wild input gives a bounded kernel
    assert k.shape[0] <= 2 * (int(np.ceil(MAX_MOTION_PX / 2)) + 1) + 1 and abs(k.sum() - 1) < 1e-5
    assert motion_kernel(np.array([np.nan, 1.0])).shape == (1, 1)


def test_jpeg_noise_survival_compensates_the_round_trip():
    """Noise of std target / survival, re-encoded at the same quality, measures about the target (the
    photo's noise was measured after its own JPEG); the uncompensated noise measures well below it."""
    import numpy as np

    from streetaug.augment.render.camera_look import jpeg_noise_survival, jpeg_round_trip

    q, target = 90, 2.0 / 255.0
    s = target
    for _ in range(3):
        s = target / jpeg_noise_survival(q, s)
    rng = np.random.default_rng(1)
    touched = np.ones((96, 96), bool)

    def measured(sigma):
        img = np.clip(np.round(120.0 + rng.normal(0.0, sigma * 255.0, (96, 96, 3))), 0, 255).astype(np.uint8)
        return jpeg_round_trip(img, touched, q).astype(np.float64).std() / 255.0

    assert abs(measured(s) - target) < 0.2 * target
    assert measured(target) < 0.75 * target


def test_jpeg_round_trip_adds_no_colour_bias():
    """Re-encoding a car's blocks (4:2:0, quality 80) quantises each flat colour's chroma to the DC step (a few
    tenths of a* / b*) but adds no cast over colours and keeps their chroma (issue #20: no warm shift)."""
    from streetaug.augment.evaluation.realism import srgb_to_lab
    from streetaug.augment.render.camera_look import jpeg_round_trip

    rng = np.random.default_rng(4)
    colours = rng.integers(20, 235, (64, 3))
    img = np.repeat(np.repeat(colours.reshape(8, 8, 3), 32, 0), 32, 1).astype(np.uint8)  # 32 x 32 px patches
    out = jpeg_round_trip(img, np.ones(img.shape[:2], bool), 80)
    def per_patch(image):  # mean CIELAB of each patch's middle (its edges share chroma with the neighbours)
        lab = srgb_to_lab(image).astype(np.float64).reshape(8, 32, 8, 32, 3)
        return lab[:, 8:24, :, 8:24].mean(axis=(1, 3)).reshape(64, 3)

    a, b = per_patch(img), per_patch(out)
    shift = b - a
    assert np.all(np.abs(shift[:, 1:]) < 1.5), shift  # each colour: within a few DC steps
    assert np.all(np.abs(shift[:, 1:].mean(axis=0)) < 0.15), shift.mean(axis=0)  # no cast over colours
    chroma_in, chroma_out = np.hypot(a[:, 1], a[:, 2]), np.hypot(b[:, 1], b[:, 2])
    assert chroma_out.mean() > 0.98 * chroma_in.mean()
