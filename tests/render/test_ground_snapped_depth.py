"""The occlusion test sees the shadow's ground: depth near the object's ground plane is snapped to it.

Densified LiDAR depth is off by +-0.2 m between rings; at a grazing view a ground 0.15 m too high is metres too
near, and it hid the bottoms of the tyres (the car floated above its own contact shadow).
"""

import numpy as np

from render_fixtures import ground_scene, primitive_car, sunny_light
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.render import render_insertion
from streetaug.augment.render.footprint import PixelBox
from streetaug.augment.render.shadow import GROUND_SNAP_END_M, ground_snapped_depth

W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])
CAMERA_HEIGHT_M = 1.5
T_FAR = pose_camera_to_transform(0.0, CAMERA_HEIGHT_M, 25.0, 90.0)  # a car 25 m ahead, seen from its side
BOX = PixelBox(100, 95, 220, 140)


def _plane(height_above_object_plane_m: float) -> np.ndarray:
    return ground_plane_depth(K, W, H, UP, CAMERA_HEIGHT_M - height_above_object_plane_m).astype(np.float32)


def test_ground_near_the_plane_is_put_on_it_inside_the_box_only():
    true, raised = _plane(0.0), _plane(0.15)
    out = ground_snapped_depth(CAMERA, raised, BOX, UP, T_FAR)
    rows, cols = BOX.slices
    inside = np.isfinite(true[rows, cols])
    assert inside.sum() > 1000
    rel = np.abs(out[rows, cols][inside] / true[rows, cols][inside] - 1.0)
    assert rel.max() < 1e-4, rel.max()
    outside = np.ones((H, W), bool)
    outside[rows, cols] = False
    np.testing.assert_array_equal(out[outside], raised[outside])


def test_structures_far_from_the_plane_and_unknown_depth_are_kept():
    kerb = _plane(GROUND_SNAP_END_M + 0.3)  # a surface well above the object's ground: a real occluder
    kerb[100:110, :] = np.inf  # unknown depth stays unknown
    out = ground_snapped_depth(CAMERA, kerb, BOX, UP, T_FAR)
    np.testing.assert_array_equal(out, kerb)


def test_a_ground_slightly_too_high_does_not_hide_the_tyres():
    """The car on a ground map 0.2 m too high covers what it covers on the true ground (the old code hid the
    tyres' bottoms: 1.1 % of the car's visible pixels at 25 m with 0.15 m, 5 % with 0.3 m)."""
    car = primitive_car()
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, _, ev = ground_scene(light, K, W, H)
    on_true = render_insertion(image, K, _plane(0.0), light, car, T_FAR, ev=ev, seed=0)
    on_raised = render_insertion(image, K, _plane(0.2), light, car, T_FAR, ev=ev, seed=0)
    visible_true = float(on_true.mask.sum())
    assert visible_true > 300
    assert float(on_raised.mask.sum()) > 0.997 * visible_true, (on_raised.mask.sum(), visible_true)
