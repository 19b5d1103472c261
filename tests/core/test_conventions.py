"""Every convention of augment/core has a test (frames, quaternions, equirect, response)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from streetaug.augment import core as cv


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return cv.quat_to_rotation(q / np.linalg.norm(q))


class TestTransforms:
    def test_inverse_round_trip(self):
        rng = np.random.default_rng(0)
        T = cv.make_transform(random_rotation(rng), rng.normal(size=3))
        np.testing.assert_allclose(T @ cv.invert_transform(T), np.eye(4), atol=1e-12)

    def test_transform_points_matches_homogeneous(self):
        rng = np.random.default_rng(1)
        T = cv.make_transform(random_rotation(rng), rng.normal(size=3))
        p = rng.normal(size=(5, 3))
        ph = np.concatenate([p, np.ones((5, 1))], axis=1) @ T.T
        np.testing.assert_allclose(cv.transform_points(T, p), ph[:, :3], atol=1e-12)

    def test_quaternion_order_is_wxyz(self):
        # 90 deg about +z: [w, x, y, z] = [cos 45, 0, 0, sin 45] maps +x to +y.
        R = cv.quat_to_rotation([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
        np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)

    @settings(max_examples=50, deadline=None)
    @given(st.lists(st.floats(-1, 1), min_size=4, max_size=4))
    def test_quat_matrix_round_trip(self, q):
        q = np.array(q)
        if np.linalg.norm(q) < 1e-3:
            return
        q = q / np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        back = cv.rotation_to_quat(cv.quat_to_rotation(q))
        # q and -q are the same rotation; rotation_to_quat returns w >= 0.
        assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-6

    def test_yaw_quaternion(self):
        for yaw in (-3.0, -1.0, 0.0, 0.5, 3.0):
            assert cv.quat_to_yaw(cv.yaw_to_quat(yaw)) == pytest.approx(yaw, abs=1e-9)

    def test_bad_quaternion_raises(self):
        with pytest.raises(cv.ConventionError, match="quaternion"):
            cv.quat_to_rotation([0, 0, 0, 0])
        with pytest.raises(cv.ConventionError, match="expected shape"):
            cv.quat_to_rotation([1, 0, 0])


class TestPinhole:
    K = np.array([[1000.0, 0, 800.0], [0, 1000.0, 450.0], [0, 0, 1]])

    def test_optical_axis_projects_to_principal_point(self):
        uv, z = cv.project_points(self.K, np.array([[0.0, 0.0, 7.0]]))
        np.testing.assert_allclose(uv[0], [800.0, 450.0])
        assert z[0] == 7.0

    def test_project_unproject_round_trip(self):
        rng = np.random.default_rng(2)
        p = rng.uniform([-5, -2, 1], [5, 2, 50], size=(100, 3))
        uv, z = cv.project_points(self.K, p)
        np.testing.assert_allclose(cv.unproject_depth(self.K, uv, z), p, atol=1e-9)

    def test_points_behind_camera_are_nan(self):
        uv, _ = cv.project_points(self.K, np.array([[1.0, 1.0, -3.0]]))
        assert np.all(np.isnan(uv))

    def test_fov_intrinsics(self):
        K = cv.intrinsics_from_fov(1600, 900, 90.0)
        assert K[0, 0] == pytest.approx(800.0)
        # The left image edge (u = -0.5) is at 45 deg.
        d = cv.pixel_rays(K, np.array([[-0.5 + 0.0, K[1, 2]]]))[0]
        assert np.degrees(np.arctan2(-d[0], d[2])) == pytest.approx(45.0, abs=0.1)


class TestEquirect:
    def test_contract_directions(self):
        # Straight ahead (+z) is the map centre; +x (right) is at lon +90 deg; up (-y) at the top.
        lon, lat = cv.camera_dir_to_lonlat(np.array([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]]))
        np.testing.assert_allclose(np.degrees(lon[:2]), [0, 90], atol=1e-9)
        np.testing.assert_allclose(np.degrees(lat), [0, 0, 90], atol=1e-9)
        u, v = cv.lonlat_to_uv(lon[:2], lat[:2], 128, 256)
        np.testing.assert_allclose(u, [128, 192])
        np.testing.assert_allclose(v, [64, 64])

    @settings(max_examples=100, deadline=None)
    @given(st.floats(-np.pi + 1e-6, np.pi - 1e-6), st.floats(-np.pi / 2, np.pi / 2))
    def test_camera_round_trip_including_poles_and_seam(self, lon, lat):
        d = cv.lonlat_to_camera_dir(np.array(lon), np.array(lat))
        lon2, lat2 = cv.camera_dir_to_lonlat(d)
        assert abs(lat2 - lat) < 1e-6
        if abs(lat) < np.pi / 2 - 1e-4:  # longitude is undefined at the poles
            assert abs(np.angle(np.exp(1j * (lon2 - lon)))) < 1e-6

    def test_world_round_trip(self):
        rng = np.random.default_rng(3)
        d = rng.normal(size=(50, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        np.testing.assert_allclose(cv.lonlat_to_world_dir(*cv.world_dir_to_lonlat(d)), d, atol=1e-12)

    def test_solid_angles_sum_to_sphere(self):
        assert cv.equirect_solid_angles(32, 64).sum() == pytest.approx(4 * np.pi)

    def test_sample_equirect_wraps_at_seam(self):
        env = np.zeros((4, 8, 1))
        env[:, 0] = 1.0
        env[:, -1] = 3.0
        # Exactly on the seam (lon = +-pi) the value is the mean of the first and last column.
        val = cv.sample_equirect(env, np.array([np.pi]), np.array([0.0]))
        assert val[0, 0] == pytest.approx(2.0)

    def test_pixel_centre_lookup_is_exact(self):
        rng = np.random.default_rng(4)
        env = rng.random((16, 32, 3))
        lon, lat = cv.equirect_pixel_lonlat(16, 32)
        np.testing.assert_allclose(cv.sample_equirect(env, lon, lat), env, atol=1e-12)


class TestCameraResponse:
    def test_round_trip_below_shoulder(self):
        x = np.linspace(0, 0.85, 50)
        np.testing.assert_allclose(cv.ldr_to_hdr(cv.hdr_to_ldr(x)), x, atol=1e-9)

    def test_softclip_is_continuous_and_monotonic(self):
        x = np.linspace(0, 5, 10001)
        y = cv.softclip(x)
        assert np.all(np.diff(y) >= 0)
        assert np.max(np.abs(np.diff(y))) < 1e-3
        assert y.max() <= 1.0 and cv.softclip(1.0) < 1.0

    def test_ev_scales_exposure(self):
        assert cv.hdr_to_ldr(0.1, ev=1.0) == pytest.approx(cv.hdr_to_ldr(0.2))

    def test_uint8_round_trip(self):
        img = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
        back = cv.hdr_to_ldr_uint8(cv.ldr_uint8_to_hdr(img))
        assert np.abs(back.astype(int) - img).max() <= 1


class TestPoseCamera:
    def test_yaw_zero_faces_forward_and_up_is_minus_y(self):
        T = cv.pose_camera_to_transform(1, 2, 3, 0.0)
        np.testing.assert_allclose(T[:3, 0], [0, 0, 1], atol=1e-12)  # front
        np.testing.assert_allclose(T[:3, 2], [0, -1, 0], atol=1e-12)  # up
        np.testing.assert_allclose(T[:3, 1], [-1, 0, 0], atol=1e-12)  # left = image left
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)

    @pytest.mark.parametrize("yaw", [-170.0, -90.0, 0.0, 45.0, 90.0, 179.0])
    def test_round_trip(self, yaw):
        origin, back = cv.transform_to_pose_camera(cv.pose_camera_to_transform(0.5, 1.5, 12.0, yaw))
        assert back == pytest.approx(yaw)
        np.testing.assert_allclose(origin, [0.5, 1.5, 12.0])


def test_check_shape_message_names_the_array():
    with pytest.raises(cv.ConventionError, match=r"points_ego: expected shape \(N, 3\), got \(4, 2\)"):
        cv.check_shape(np.zeros((4, 2)), ("N", 3), "points_ego")
