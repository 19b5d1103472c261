"""The renderer runs BLAS on one thread: its (N, 3) x (3, 3) products only lose from more."""

import numpy as np
import pytest
import threadpoolctl

from render_fixtures import ground_scene, primitive_car, sunny_light
from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.render import insert as insert_module
from streetaug.augment.render import render_insertion


W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]


def test_blas_on_one_thread_inside_the_render_only():
    if not _blas_threads():
        pytest.skip("no BLAS library that threadpoolctl controls")
    with threadpoolctl.threadpool_limits(2, "blas"):
        outside = _blas_threads()
        with insert_module._one_blas_thread():
            inside = _blas_threads()
        after = _blas_threads()
    assert set(inside) == {1}
    assert after == outside  # restored


def test_same_image_whatever_the_blas_threads():
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light, K, W, H)
    car = primitive_car()
    T = pose_camera_to_transform(0.5, 1.5, 9.0, 35.0)
    runs = []
    for n in (1, 2):
        with threadpoolctl.threadpool_limits(n, "blas"):
            runs.append(render_insertion(image, K, depth, light, car, T, quality="draft", ev=ev, seed=5))
    assert runs[0].coverage.sum() > 500
    np.testing.assert_array_equal(runs[0].image, runs[1].image)
    np.testing.assert_array_equal(runs[0].shadow_ratio, runs[1].shadow_ratio)
