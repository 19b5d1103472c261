"""The realism check's features and classifier on synthetic crops (fast: small images, no pipeline)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from streetaug.augment.core import project_points
from streetaug.augment.evaluation.realism import (
    FEATURE_NAMES, CarCrop, box_corners_cam, box_in_image, classifier_accuracy, crop_descriptor, crop_features,
    edge_sharpness, extract_crop, feature_gaps, ground_distance_map, ground_points_box, grouped_folds,
    laplacian_sharpness, luma, noise_sigma, shadow_darkness, size_matched, srgb_to_lab, yaw_to_ray_deg,
)

W, H = 240, 160
K = np.array([[200.0, 0, 119.5], [0, 200.0, 79.5], [0, 0, 1]])
WLH = np.array([1.8, 4.5, 1.5])


def T_cam_from_box(z_m: float = 12.0, x_m: float = 0.0, yaw: float = 0.4) -> np.ndarray:
    """A box standing on the ground 1.5 m below the camera (camera y down), ``z_m`` ahead."""
    c, s = np.cos(yaw), np.sin(yaw)
    R_cam_from_flat = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float)  # box x -> cam z, y -> -x, z -> -y
    R_yaw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = R_cam_from_flat @ R_yaw
    T[:3, 3] = [x_m, 1.5 - WLH[2] / 2, z_m]
    return T


@pytest.fixture(scope="module")
def scene():
    """(image, T): a textured road with a patterned 'car' inside the box's hull."""
    rng = np.random.default_rng(0)
    T = T_cam_from_box()
    img = np.full((H, W, 3), 120, np.float32) + rng.normal(0, 1.0, (H, W, 1))
    hull = np.zeros((H, W), np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.round(project_points(K, box_corners_cam(T, WLH))[0]).astype(np.int32)), 1)
    stripes = (np.arange(W)[None, :] // 6 % 2) * 120 + 40
    img = np.where(hull[..., None].astype(bool), np.stack([stripes * 1.0, stripes * 0.4, stripes * 0.3], -1)
                   * np.ones((H, 1, 1)), img)
    return np.clip(img, 0, 255).astype(np.uint8), T


def crop_of(image, T):
    return extract_crop(image, K, T, WLH)


def test_box_geometry(scene):
    _, T = scene
    corners = box_corners_cam(T, WLH)
    assert np.allclose(corners[:4, 1], 1.5) and np.allclose(corners[4:, 1], 1.5 - WLH[2])  # bottom on the ground
    assert box_in_image(K, T, WLH, W, H)
    assert not box_in_image(K, T_cam_from_box(x_m=8.0), WLH, W, H)  # partly outside the image
    window = (0, 0, W, H)
    d = ground_distance_map(K, T, WLH, window)
    assert np.all(np.isnan(d[:70]))  # above the horizon (row 79.5)
    bottom_centre = project_points(K, (T @ np.array([0, 0, -WLH[2] / 2, 1]))[None, :3])[0][0]
    assert d[int(round(bottom_centre[1])), int(round(bottom_centre[0]))] == 0.0
    assert np.nanmax(d[-1]) > 3.0  # the bottom row is metres in front of the car


def test_crop_window_includes_ground_under_the_car(scene):
    image, T = scene
    crop = crop_of(image, T)
    rows_with_car = np.flatnonzero(crop.car_mask.any(axis=1))
    assert rows_with_car.max() < crop.rgb.shape[0] - 3  # margin below the box
    assert crop.car_mask.mean() > 0.3 and 11 < crop.distance_m < 13


def test_blur_lowers_sharpness(scene):
    image, T = scene
    sharp = crop_features(crop_of(image, T))
    blurred = crop_features(crop_of(cv2.GaussianBlur(image, (0, 0), 1.5), T))
    assert blurred["laplacian_sharpness"] < 0.5 * sharp["laplacian_sharpness"]
    assert blurred["edge_sharpness"] < 0.7 * sharp["edge_sharpness"]


def test_edge_sharpness_ignores_contrast():
    y = np.tile((np.arange(64) >= 32).astype(np.float32), (64, 1))
    mask = np.ones_like(y, bool)
    assert edge_sharpness(100 * y, mask) == pytest.approx(edge_sharpness(20 * y, mask), rel=1e-4)
    assert laplacian_sharpness(100 * y, mask) == pytest.approx(laplacian_sharpness(20 * y, mask), rel=1e-4)


def test_noise_estimate_follows_added_noise(scene):
    image, T = scene
    rng = np.random.default_rng(1)
    clean = crop_features(crop_of(image, T))["noise_sigma"]
    noisy_img = np.clip(image + rng.normal(0, 6.0, image.shape), 0, 255).astype(np.uint8)
    noisy = crop_features(crop_of(noisy_img, T))["noise_sigma"]
    assert noisy > clean + 3.0
    flat = np.full((80, 80), 100.0) + rng.normal(0, 5.0, (80, 80))
    assert noise_sigma(flat, np.ones((80, 80), bool), flat_fraction=1.0) == pytest.approx(5.0, rel=0.15)


def test_darker_road_under_the_car_raises_shadow_darkness(scene):
    image, T = scene
    crop = crop_of(image, T)
    y = luma(crop.rgb)
    none = shadow_darkness(y, crop.ground_dist_m, crop.car_mask)
    assert abs(none) < 0.05
    under = (crop.ground_dist_m < 0.4) & ~crop.car_mask
    shaded = shadow_darkness(np.where(under, 0.5 * y, y), crop.ground_dist_m, crop.car_mask)
    assert shaded == pytest.approx(0.5, abs=0.05)
    excluded = shadow_darkness(np.where(under, 0.5 * y, y), crop.ground_dist_m, crop.car_mask, exclude_mask=under)
    assert np.isnan(excluded)  # nothing left under the car


def test_colour_and_contrast(scene):
    image, T = scene
    f = crop_features(crop_of(image, T))
    assert f["a_mean"] > 10 and f["chroma_mean"] > 10  # reddish stripes
    assert f["rms_contrast"] > 0.3
    grey = np.full((20, 20, 3), 128, np.uint8)
    lab = srgb_to_lab(grey)
    assert np.allclose(lab[..., 1:], 0, atol=0.5) and lab[0, 0, 0] == pytest.approx(53.6, abs=0.5)
    assert set(f) == set(FEATURE_NAMES)


def test_descriptor_has_fixed_length(scene):
    image, T = scene
    a = crop_descriptor(crop_of(image, T))
    b = crop_descriptor(crop_of(image, T_cam_from_box(z_m=20.0)))
    assert a.shape == b.shape == (1764 + 24 + len(FEATURE_NAMES),)


def test_grouped_folds_keep_groups_together():
    labels = np.tile([0, 1], 30)
    groups = np.repeat(np.arange(12), 5)
    folds = grouped_folds(labels, groups, n_splits=5, seed=3)
    tested = np.concatenate([test for _, test in folds])
    assert np.array_equal(np.sort(tested), np.arange(60))
    for train, test in folds:
        assert not set(groups[train]) & set(groups[test])


def test_classifier_chance_on_one_distribution_and_perfect_on_different_ones():
    rng = np.random.default_rng(0)
    n, d = 120, 40
    labels = np.tile([0, 1], n // 2)
    groups = np.repeat(np.arange(24), 5)
    same = rng.normal(size=(n, d))
    accs = [classifier_accuracy(same, labels, groups, seed=s)["accuracy_mean"] for s in range(3)]
    assert 0.35 < np.mean(accs) < 0.65
    different = same + 1.5 * labels[:, None]
    result = classifier_accuracy(different, labels, groups)
    assert result["accuracy_mean"] > 0.95 and len(result["fold_accuracy"]) == 5


def test_feature_gaps_and_size_matching():
    a = [{"x": v} for v in [1.0, 2.0, 3.0, np.nan]]
    b = [{"x": v} for v in [11.0, 12.0, 13.0]]
    g = feature_gaps(a, b, names=("x",))["x"]
    assert g["median_gap"] == -10.0 and g["standardised_gap"] == pytest.approx(-10.0) and g["n_inserted"] == 3
    rng = np.random.default_rng(0)
    ha, hb = rng.uniform(30, 200, 80), rng.uniform(30, 100, 50)
    ia, ib = size_matched(ha, hb, [30, 60, 100, 200], rng)
    assert len(ia) == len(ib) > 0
    assert np.array_equal(np.bincount(np.digitize(ha[ia], [30, 60, 100, 200]), minlength=4),
                          np.bincount(np.digitize(hb[ib], [30, 60, 100, 200]), minlength=4))
    ia, ib = size_matched(ha, hb, [30, 60, 100, 200], rng, max_each=10)
    assert len(ia) == len(ib) <= 10


def test_box_rect_keeps_only_the_corners_in_front_of_the_camera():
    from streetaug.augment.evaluation.realism import box_rect_px

    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 1.0]  # a box around the camera plane: half its corners behind the camera
    rect = box_rect_px(K, T, np.array([1.0, 1.0, 4.0]))
    assert np.all(np.isfinite(rect)) and rect[0] < rect[2] and rect[1] < rect[3]
    front = box_corners_cam(T, np.array([1.0, 1.0, 4.0]))
    uv = project_points(K, front[front[:, 2] > 0])[0]
    np.testing.assert_allclose(rect, [uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
    T[:3, 3] = [0.0, 0.0, -10.0]  # wholly behind
    assert np.isnan(box_rect_px(K, T, np.array([1.0, 1.0, 4.0]))).all()


def test_car_only_descriptor_ignores_the_surroundings():
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.5, 12.0]
    rng = np.random.default_rng(0)
    image = np.full((H, W, 3), 120, np.uint8)
    other = image.copy()
    other[:, :] = rng.integers(0, 255, (H, W, 3))  # busy surroundings
    crop_a = extract_crop(image, K, T, WLH)
    inside = crop_a.car_mask
    other_crop = extract_crop(other, K, T, WLH)
    rgb = np.where(inside[..., None], crop_a.rgb, other_crop.rgb).astype(np.uint8)  # same car, other background
    crop_b = CarCrop(rgb, inside, crop_a.ground_dist_m, crop_a.exclude_mask, crop_a.window, crop_a.box_height_px,
                     crop_a.distance_m)
    feats = crop_features(crop_a)
    n_hog = 1764
    plain = crop_descriptor(crop_a, feats)[:n_hog], crop_descriptor(crop_b, feats)[:n_hog]
    car = crop_descriptor(crop_a, feats, car_only=True)[:n_hog], crop_descriptor(crop_b, feats, car_only=True)[:n_hog]
    assert np.abs(plain[0] - plain[1]).max() > 0.05  # the plain HOG sees the background
    np.testing.assert_allclose(car[0], car[1], atol=1e-6)


def test_yaw_to_ray_is_0_end_on_and_90_side_on():
    assert yaw_to_ray_deg(T_cam_from_box(yaw=0.0)) == pytest.approx(0.0, abs=1e-6)  # straight ahead, nose away
    assert yaw_to_ray_deg(T_cam_from_box(yaw=np.pi)) == pytest.approx(0.0, abs=1e-6)  # nose towards the camera
    assert yaw_to_ray_deg(T_cam_from_box(yaw=np.pi / 2)) == pytest.approx(90.0, abs=1e-6)
    assert yaw_to_ray_deg(T_cam_from_box(yaw=0.4)) == pytest.approx(np.degrees(0.4), abs=1e-6)
    # off to the side: the ray turns, so a box heading along the optical axis is no longer end-on
    assert yaw_to_ray_deg(T_cam_from_box(z_m=10.0, x_m=10.0, yaw=0.0)) == pytest.approx(45.0, abs=1e-6)


def test_ground_points_are_where_pixel_rays_meet_the_box_ground_plane():
    T = T_cam_from_box(yaw=0.3)
    window = (0, 0, W, H)
    hit = ground_points_box(K, T, WLH, window)
    assert np.all(np.isnan(hit[:70]))  # above the horizon
    # the pixel of a ground point 1 m ahead and 0.5 m left of the box centre (box frame) maps back to it
    p_box = np.array([1.0, 0.5, -WLH[2] / 2])
    uv = project_points(K, (T[:3, :3] @ p_box + T[:3, 3])[None])[0][0]
    u, v = int(round(uv[0])), int(round(uv[1]))
    assert np.allclose(hit[v, u], p_box[:2], atol=0.15)  # within a pixel's footprint at 12 m
    assert np.allclose(ground_distance_map(K, T, WLH, window)[v, u], 0.0)  # inside the footprint
