"""Labels: box_camera / box_global consistency, 2D box and visible fraction, visibility bins."""

from __future__ import annotations

import json

import numpy as np
import pytest

from placement_fixtures import CAMERA, camera_view, ground_grid_ego, lidar_sweep, make_sample
from streetaug.augment.core import (
    PinholeCamera,
    invert_transform,
    pose_camera_to_transform,
    quat_to_rotation,
    transform_points,
)
from streetaug.datasets.nuscenes_format import visibility_token
from streetaug.placement.labels import bbox_from_mask, object_label, placement_label_fields
from streetaug.placement.place import ObjectBox, place_objects
from streetaug.placement.rules import box_corners_object, projected_inside_fraction

WLH = np.array([1.8, 4.5, 1.5])
SMALL_CAMERA = PinholeCamera(np.diag([0.1, 0.1, 1.0]) @ CAMERA.K, 160, 90)


def _label(T_cam_from_object, mask=None, coverage=None, **kw):
    h, w = SMALL_CAMERA.shape
    mask = np.zeros((h, w)) if mask is None else mask
    coverage = np.ones((h, w)) if coverage is None else coverage
    return object_label(T_cam_from_object, WLH, "vehicle.car", SMALL_CAMERA, mask, coverage, **kw)


@pytest.mark.parametrize("yaw_deg", [0.0, 37.0, 90.0, -120.0, 179.0])
def test_box_camera_matches_pose_and_box_global_through_transforms(yaw_deg):
    view = camera_view()
    T_co = pose_camera_to_transform(1.0, 1.5, 20.0, yaw_deg)
    lab = _label(T_co, T_global_from_cam=view.T_global_from_cam)
    assert lab["box_camera"]["yaw_deg"] == pytest.approx(yaw_deg, abs=1e-9)
    np.testing.assert_allclose(lab["box_camera"]["center"], [1.0, 1.5 - WLH[2] / 2, 20.0], atol=1e-12)
    assert lab["box_camera"]["size_wlh"] == WLH.tolist()
    g = lab["box_global"]
    # the global box brought back through T_cam_from_global gives the camera box and yaw
    T_cam_from_global = invert_transform(view.T_global_from_cam)
    center_cam = transform_points(T_cam_from_global, np.array([g["translation"]]))[0]
    np.testing.assert_allclose(center_cam, lab["box_camera"]["center"], atol=1e-9)
    front_cam = T_cam_from_global[:3, :3] @ quat_to_rotation(g["rotation"])[:, 0]
    assert np.degrees(np.arctan2(front_cam[0], front_cam[2])) == pytest.approx(yaw_deg, abs=1e-6)
    assert g["size"] == WLH.tolist() and g["rotation"][0] >= 0
    assert lab["num_lidar_pts"] == 0 and lab["num_radar_pts"] == 0 and lab["attribute"] == "vehicle.moving"


def test_no_box_global_without_poses():
    assert "box_global" not in _label(pose_camera_to_transform(0, 1.5, 20, 0))


def test_bbox_2d_and_visible_fraction_on_synthetic_mask():
    mask = np.zeros((90, 160))
    mask[10:20, 30:50] = 1.0  # 10 rows x 20 cols fully visible
    mask[20, 30] = 0.5  # exactly 0.5 is not visible (> 0.5 is)
    coverage = np.zeros((90, 160))
    coverage[10:30, 30:50] = 1.0  # 400 covered pixels, 200.5 visible
    lab = _label(pose_camera_to_transform(0, 1.5, 20, 0), mask, coverage)
    assert lab["bbox_2d"] == [29.5, 9.5, 49.5, 19.5]
    assert lab["visible_fraction"] == pytest.approx(200.5 / 400)
    assert lab["visibility_token"] == "2"
    empty = _label(pose_camera_to_transform(0, 1.5, 20, 0), np.zeros((90, 160)), np.zeros((90, 160)))
    assert empty["bbox_2d"] is None and empty["visible_fraction"] == 0.0 and empty["visibility_token"] == "1"


def test_bbox_single_pixel_and_full_image():
    m = np.zeros((5, 7))
    m[3, 4] = 1
    assert bbox_from_mask(m) == [3.5, 2.5, 4.5, 3.5]
    assert bbox_from_mask(np.ones((5, 7))) == [-0.5, -0.5, 6.5, 4.5]


@pytest.mark.parametrize("frac,token", [(0.0, "1"), (0.3999, "1"), (0.4, "2"), (0.5999, "2"), (0.6, "3"),
                                        (0.7999, "3"), (0.8, "4"), (1.0, "4")])
def test_visibility_bins_at_edges(frac, token):
    assert visibility_token(frac) == token


def test_truncation():
    centred = _label(pose_camera_to_transform(0, 1.5, 20, 0))
    assert centred["truncation"] == pytest.approx(0.0, abs=1e-9)
    # an object at the image's right edge is partly outside; truncation = 1 - inside fraction
    T = pose_camera_to_transform(13.0, 1.5, 20, 0)
    edge = _label(T)
    corners = box_corners_object(WLH) @ T[:3, :3].T + T[:3, 3]
    expected = 1 - projected_inside_fraction(corners[None], SMALL_CAMERA, 0.1)[0]
    assert 0.1 < edge["truncation"] < 0.9 and edge["truncation"] == pytest.approx(expected)
    behind = _label(pose_camera_to_transform(0, 1.5, -20, 0))
    assert behind["truncation"] == 1.0


def test_label_rejects_mismatched_mask():
    with pytest.raises(ValueError, match="mask"):
        object_label(np.eye(4), WLH, "vehicle.car", CAMERA, np.zeros((10, 10)), np.zeros((10, 10)))


def test_placement_label_fields_are_json_ready():
    pts = ground_grid_ego(0.5)
    s = make_sample(lidar=lidar_sweep(pts))
    p = place_objects(s, s.cameras["CAM_FRONT"], [ObjectBox(WLH)], np.random.default_rng(0)).placements[0]
    fields = json.loads(json.dumps(placement_label_fields(p)))["placement"]
    assert fields["drivable_source"] == "map" and fields["drivable_confidence"] == "high"
    assert fields["ground_source"] == "lidar-plane"
    assert fields["yaw_source"] == ("kerb" if p.zone == "kerb" else "ego")  # by the kerb: along its edge
    assert 10.0 <= fields["distance_m"] <= 40.0
