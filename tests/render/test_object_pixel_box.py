"""The object's pixel box when its 3D box straddles the camera plane: only the part in front can be seen.

It was the whole frame: objects placed for a neighbouring camera traced 1.44 M camera rays at 1600 x 900 and
hit nothing (5 of 13 renders of a scene-0916 sample, ~0.5 GB and 1.4-2 CPU-s each).
"""

import numpy as np

from streetaug.augment.core import PinholeCamera, intrinsics_from_fov
from streetaug.augment.render.footprint import NEAR_PLANE_M, clip_to_near_plane, object_pixel_box

W, H = 1600, 900
CAMERA = PinholeCamera(intrinsics_from_fov(W, H, 70.0), W, H)


def _box_corners(centre, size) -> np.ndarray:
    c, h = np.asarray(centre, float), np.asarray(size, float) / 2
    return np.array([[c[0] + sx * h[0], c[1] + sy * h[1], c[2] + sz * h[2]]
                     for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def _dense_visible_bounds(corners: np.ndarray):
    """Pixel bounds of many points inside the box in front of the near plane (brute force)."""
    rng = np.random.default_rng(0)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    p = lo + rng.random((200_000, 3)) * (hi - lo)
    p = np.concatenate([p, corners])
    p = p[p[:, 2] > NEAR_PLANE_M * 50]
    uv, _ = CAMERA.project(p)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    return uv[inside]


def test_a_box_beside_the_camera_is_off_screen():
    corners = _box_corners((4.0, 0.5, 0.0), (1.9, 1.6, 4.6))  # a car alongside, half behind the camera plane
    assert corners[:, 2].min() < 0 < corners[:, 2].max()
    assert len(_dense_visible_bounds(corners)) == 0
    assert object_pixel_box(CAMERA, np.eye(4), corners, pad_px=0) is None


def test_a_straddling_box_gets_the_bounds_of_its_visible_part():
    corners = _box_corners((1.2, 0.8, 0.5), (1.9, 1.6, 4.6))  # ahead-right, its rear behind the camera
    box = object_pixel_box(CAMERA, np.eye(4), corners, pad_px=0)
    uv = _dense_visible_bounds(corners)
    assert box is not None and len(uv) > 1000
    assert box.x0 <= uv[:, 0].min() and box.y0 <= uv[:, 1].min()
    assert box.x1 >= uv[:, 0].max() and box.y1 >= uv[:, 1].max()
    assert box.width * box.height < 0.7 * W * H  # not the whole frame
    assert box.x0 > 0.4 * W  # the box is right of the camera: its left image edge stays right of centre


def test_clipping_keeps_points_in_front_and_puts_crossings_on_the_plane():
    pts = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, -2.0], [0.0, 1.0, 1.0]])
    out = clip_to_near_plane(pts, 0.5)
    assert len(out) == 4  # 2 in front, 2 crossings
    np.testing.assert_allclose(out[2], [0.375, 0.0, 0.5])
    np.testing.assert_allclose(out[3], [1 / 6, 5 / 6, 0.5])
