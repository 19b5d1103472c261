"""Atomic I/O, the ray engine (embree vs numpy reference) and the distant light."""

import numpy as np
import pytest
import trimesh

from streetaug.augment.core import io
from streetaug.augment.core import camera_envmap_directions, equirect_solid_angles, luminance
from streetaug.augment.lighting.light import DistantLight, SunLight
from streetaug.augment.core.raycast import RayScene


class TestAtomicIO:
    def test_failed_write_leaves_nothing(self, tmp_path):
        target = tmp_path / "out.json"
        with pytest.raises(RuntimeError):
            with io.atomic_path(target) as tmp:
                tmp.write_text("half")
                raise RuntimeError("crash")
        assert not target.exists()
        assert list(tmp_path.iterdir()) == []

    def test_exr_round_trip(self, tmp_path):
        a = np.random.default_rng(0).random((6, 9, 3)).astype(np.float32) * 100
        io.write_exr(tmp_path / "a.exr", a)
        np.testing.assert_array_equal(io.read_exr(tmp_path / "a.exr"), a)

    def test_corrupt_image_error_names_file(self, tmp_path):
        p = tmp_path / "broken.jpg"
        p.write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
        with pytest.raises(io.InputError, match="broken.jpg.*cannot decode"):
            io.read_image_rgb(p)
        with pytest.raises(io.InputError, match="not found"):
            io.read_image_rgb(tmp_path / "missing.png")

    def test_png_round_trip(self, tmp_path):
        img = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
        io.write_image_rgb(tmp_path / "x.png", img)
        np.testing.assert_array_equal(io.read_image_rgb(tmp_path / "x.png"), img)


@pytest.fixture(scope="module")
def scenes():
    m = trimesh.creation.icosphere(subdivisions=2)
    return RayScene(m.vertices, m.faces), RayScene(m.vertices, m.faces, backend="numpy")


class TestRayScene:
    def test_embree_matches_numpy_reference(self, scenes):
        fast, ref = scenes
        rng = np.random.default_rng(0)
        o = rng.normal(size=(400, 3)) * 3
        d = -o + rng.normal(size=(400, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        a, b = fast.intersect(o, d), ref.intersect(o, d)
        np.testing.assert_array_equal(a.hit, b.hit)
        np.testing.assert_allclose(a.t[a.hit], b.t[b.hit], atol=1e-4)
        np.testing.assert_array_equal(a.face, b.face)
        np.testing.assert_allclose(fast.hit_points(a)[a.hit], o[a.hit] + d[a.hit] * a.t[a.hit, None], atol=1e-4)
        np.testing.assert_array_equal(fast.occluded(o, d), b.hit)

    def test_t_max_limits_occlusion(self, scenes):
        fast, _ = scenes
        o = np.array([[0.0, 0.0, -5.0]])
        d = np.array([[0.0, 0.0, 1.0]])
        assert fast.occluded(o, d, t_max=10.0)[0]
        assert not fast.occluded(o, d, t_max=3.0)[0]

    def test_empty_mesh_is_refused(self):
        with pytest.raises(ValueError, match="no faces"):
            RayScene(np.zeros((3, 3)), np.zeros((0, 3), dtype=int))


class TestDistantLight:
    def test_sun_split_preserves_energy_and_direction(self):
        H, W = 64, 128
        sky = np.full((H, W, 3), 0.5, np.float32)
        sun = SunLight(direction=np.array([0.3, -0.6, 0.74]) / np.linalg.norm([0.3, -0.6, 0.74]),
                       irradiance_rgb=np.array([20.0, 19.0, 17.0]))
        env = DistantLight(sky, sun).to_envmap()
        split = DistantLight.from_envmap(env)
        assert split.sun is not None
        angle = np.degrees(np.arccos(np.clip(split.sun.direction @ sun.direction, -1, 1)))
        assert angle < 2.0  # within a pixel or so (a pixel is 2.8 deg here)
        np.testing.assert_allclose(split.sun.irradiance_rgb, sun.irradiance_rgb, rtol=0.02)
        np.testing.assert_allclose(split.envmap, sky, atol=1e-5)

    def test_overcast_map_has_no_sun(self):
        H, W = 32, 64
        d = camera_envmap_directions(H, W)
        env = np.repeat((0.5 + 0.5 * np.clip(-d[..., 1], 0, 1))[..., None], 3, axis=2).astype(np.float32)
        assert DistantLight.from_envmap(env).sun is None

    def test_total_energy_of_envmap_includes_sun(self):
        H, W = 32, 64
        sun = SunLight(direction=np.array([0.0, -1.0, 0.0]), irradiance_rgb=np.array([5.0, 5.0, 5.0]))
        env = DistantLight(np.zeros((H, W, 3), np.float32), sun).to_envmap()
        total = (luminance(env) * equirect_solid_angles(H, W)).sum()
        assert total == pytest.approx(5.0, rel=1e-4)

    def test_radiance_sees_the_sun_disc(self):
        sun = SunLight(direction=np.array([0.0, 0.0, 1.0]), irradiance_rgb=np.array([1.0, 1.0, 1.0]))
        light = DistantLight(np.zeros((8, 16, 3), np.float32), sun)
        r = light.radiance(np.zeros((2, 3)), np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
        assert r[0, 0] == pytest.approx(1.0 / sun.solid_angle_sr)
        assert r[1, 0] == 0.0

    def test_nan_envmap_is_refused(self):
        env = np.ones((8, 16, 3), np.float32)
        env[2, 3, 1] = np.nan
        with pytest.raises(ValueError, match="NaN"):
            DistantLight.from_envmap(env)
