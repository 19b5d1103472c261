"""The camera look's inputs from the pipeline: each object's velocity relative to the moving camera
(from the ego poses around the capture) and the source file's JPEG quality."""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.core import make_transform, yaw_to_quat
from streetaug.augment.pipeline import view as view_module
from streetaug.augment.pipeline.view import velocity_in_camera_mps
from streetaug.datasets.sample import CameraView

from conftest import SHARED_DATA

SEQ = SHARED_DATA / "nuscenes-seq"

# A front camera: OpenCV (x right, y down, z forward) in an ego frame with x forward, y left, z up.
R_EGO_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _T(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _view(poses_around) -> CameraView:
    K = np.array([[1000.0, 0, 800], [0, 1000.0, 450], [0, 0, 1]])
    return CameraView("CAM_FRONT", "", "", K, 1600, 900, _T(R_EGO_FROM_CAM, [0, 0, 1.5]),
                      poses_around[0][1] if poses_around else np.eye(4), 0, ego_poses_around=poses_around)


def test_a_parked_point_approaches_a_camera_driving_forward():
    poses = ((-0.25, _T(np.eye(3), [-2.5, 0, 0])), (0.25, _T(np.eye(3), [2.5, 0, 0])))  # 10 m/s along x
    v = velocity_in_camera_mps(_view(poses), np.array([20.0, 3.0, 0.5]), np.zeros(3))
    np.testing.assert_allclose(v, [0.0, 0.0, -10.0], atol=1e-9)


def test_a_car_driving_alongside_does_not_move_in_the_image():
    poses = ((-0.25, _T(np.eye(3), [-2.5, 0, 0])), (0.25, _T(np.eye(3), [2.5, 0, 0])))
    v = velocity_in_camera_mps(_view(poses), np.array([20.0, 3.0, 0.5]), np.array([10.0, 0.0, 0.0]))
    np.testing.assert_allclose(v, 0.0, atol=1e-9)


def test_turning_sweeps_a_point_ahead_sideways():
    yaw_rate = 0.2  # rad/s, turning left: a point ahead moves right in the image (camera +x)
    R = [make_transform(yaw_to_quat(yaw_rate * t), [0.0, 0.0, 0.0])[:3, :3] for t in (-0.05, 0.05)]
    poses = ((-0.05, _T(R[0], [0, 0, 0])), (0.05, _T(R[1], [0, 0, 0])))
    v = velocity_in_camera_mps(_view(poses), np.array([20.0, 0.0, 1.5]), np.zeros(3))
    assert v[0] == pytest.approx(yaw_rate * 20.0, rel=1e-3)
    assert abs(v[2]) < 0.05


def test_a_single_frame_has_no_motion():
    assert velocity_in_camera_mps(_view(None), np.array([20.0, 0.0, 0.5]), np.zeros(3)) is None


@pytest.mark.skipif(not (SEQ / "v1.0-mini").is_dir(), reason=f"real nuScenes scene not found under {SEQ}")
def test_real_keyframes_know_the_ego_motion_and_the_jpeg_quality():
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(SEQ, "v1.0-mini", with_map=False)
    tokens = reader.sample_tokens()
    first, middle = reader.sample(tokens[0]), reader.sample(tokens[len(tokens) // 2])
    (t0, _), (t1, _) = first.cameras["CAM_FRONT"].ego_poses_around
    assert t0 == 0.0 and 0.4 < t1 < 0.6  # no sweeps: the next keyframe
    view = middle.cameras["CAM_FRONT"]
    (t0, T0), (t1, T1) = view.ego_poses_around
    speed = np.linalg.norm(T1[:3, 3] - T0[:3, 3]) / (t1 - t0)
    assert 0.5 < speed < 30.0
    # A parked point ahead approaches at about the ego speed.
    ahead = (view.T_global_from_cam @ np.array([0.0, 0.0, 20.0, 1.0]))[:3]
    v = velocity_in_camera_mps(view, ahead, np.zeros(3))
    assert v[2] == pytest.approx(-speed, rel=0.15)
    assert view_module._jpeg_quality(view) is not None and 50 <= view_module._jpeg_quality(view) <= 100


def test_the_pipeline_passes_motion_and_jpeg_quality_to_the_renderer(monkeypatch):
    """On the bundled sequence (sweeps between keyframes) a parked car's velocity relative to the driving
    camera and the file's JPEG quality reach ``render_objects``; with the look switched off, neither."""
    import inspect
    from dataclasses import replace

    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.pipeline import InsertOptions, insert_into_sample
    from streetaug.datasets.nuscenes import NuScenesReader

    from streetaug.augment.pipeline.objects import render_objects

    seen = []

    def spy(*args, **kwargs):
        bound = inspect.signature(render_objects).bind(*args, **kwargs)
        bound.apply_defaults()
        seen.append((bound.arguments["velocities_cam_mps"], bound.arguments["jpeg_quality"]))
        return render_objects(*args, **kwargs)

    monkeypatch.setattr(view_module, "render_objects", spy)
    reader = NuScenesReader("examples/nuscenes-sequence", "v1.0-sequence")
    sample = reader.sample(reader.sample_tokens()[1])
    front = sample.cameras["CAM_FRONT"]
    assets = {"CAM_FRONT": select_assets(np.random.default_rng(0), 1)}
    options = InsertOptions(quality="draft", seed=0)
    insert_into_sample(sample, [front], assets, options)
    insert_into_sample(sample, [front], assets, replace(options, match_camera=False))
    (velocities, quality), (velocities_off, quality_off) = seen
    (t0, T0), (t1, T1) = front.ego_poses_around
    ego_speed = np.linalg.norm(T1[:3, 3] - T0[:3, 3]) / (t1 - t0)
    assert ego_speed > 1.0
    assert len(velocities) == 1 and np.linalg.norm(velocities[0]) == pytest.approx(ego_speed, rel=0.1)
    assert quality == 90
    assert velocities_off is None and quality_off is None
