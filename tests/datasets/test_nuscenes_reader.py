"""Tests of the devkit-free nuScenes reader (datasets/nuscenes.py, lidarseg.py, nuscenes_map.py).

Real data: ../shared/data/nuscenes-real (one keyframe of scene-0061) and ../shared/data/nuscenes-fixtures
(a 40-point lidarseg fixture); those tests skip when the folder is absent.  A tiny synthetic dataset
written into tmp_path covers the table logic and the error cases without any shared data.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import devkit
import shapely

import streetaug.augment.core.io as sio
from streetaug.augment.core import (
    invert_transform,
    make_transform,
    project_points,
    transform_points,
    yaw_to_quat,
)
from streetaug.augment.core import InputError
from streetaug.datasets import nuscenes as nus
from streetaug.datasets.nuscenes import DatasetError, NuScenesReader
from streetaug.datasets.lidarseg import read_lidar_points, read_lidarseg_labels
from streetaug.datasets.nuscenes_map import read_drivable_area

DATA = (Path(__file__).parents[2] / ".." / "shared" / "data").resolve()
REAL = DATA / "nuscenes-real"
FIXTURES = DATA / "nuscenes-fixtures"
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"

needs_real = pytest.mark.skipif(not (REAL / "v1.0-mini").is_dir(), reason=f"{REAL} (shared real nuScenes data) absent")
needs_fixtures = pytest.mark.skipif(not FIXTURES.is_dir(), reason=f"{FIXTURES} (lidarseg fixture) absent")


def points_in_box_mask(box, points_global: np.ndarray) -> np.ndarray:
    """(N,) bool: points inside the box, bounds inclusive (as the devkit's points_in_box)."""
    p = transform_points(invert_transform(box.T_global_from_box), points_global)
    w, l, h = box.wlh
    return (np.abs(p[:, 0]) <= l / 2) & (np.abs(p[:, 1]) <= w / 2) & (np.abs(p[:, 2]) <= h / 2)


# ============================================================================ real data


@pytest.fixture(scope="module")
def real_reader() -> NuScenesReader:
    if not (REAL / "v1.0-mini").is_dir():
        pytest.skip(f"{REAL} (shared real nuScenes data) absent")
    return NuScenesReader(REAL, "v1.0-mini")


@pytest.fixture(scope="module")
def real_sample(real_reader):
    return real_reader.sample(REAL_SAMPLE)


@needs_real
class TestRealTables:
    def test_scenes_and_samples(self, real_reader):
        assert real_reader.scene_names() == ["scene-0061"]
        assert real_reader.sample_tokens("scene-0061") == [REAL_SAMPLE]
        assert real_reader.sample_tokens() == [REAL_SAMPLE]
        scene = real_reader.find_scene("scene-0061")
        assert real_reader.find_scene(scene["token"]) is scene
        assert real_reader.location_of(REAL_SAMPLE) == "singapore-onenorth"
        assert len(real_reader.table("sample_annotation")) == 68

    def test_sample_fields(self, real_sample, real_reader):
        s = real_sample
        assert (s.token, s.scene_name, s.location) == (REAL_SAMPLE, "scene-0061", "singapore-onenorth")
        assert s.timestamp_us == real_reader.get("sample", REAL_SAMPLE)["timestamp"]
        assert set(s.cameras) == {"CAM_FRONT", "CAM_FRONT_LEFT", "CAM_BACK"}
        assert len(s.boxes) == 68
        for channel, cam in s.cameras.items():
            assert cam.channel == channel
            assert (cam.width, cam.height) == (1600, 900)
            assert cam.K.shape == (3, 3) and cam.K[2, 2] == 1.0
            assert Path(cam.image_path).is_file()
            assert channel in cam.image_path
            # each camera has its own ego pose, close to the sample's time
            assert abs(cam.timestamp_us - s.timestamp_us) < 100_000
        assert len({tuple(c.T_global_from_ego[:3, 3]) for c in s.cameras.values()}) == 3
        cats = {b.category for b in s.boxes}
        assert "vehicle.car" in cats
        assert any(b.attributes for b in s.boxes)
        assert all(np.isclose(np.linalg.norm(b.rotation), 1.0) for b in s.boxes)

    def test_camera_extrinsics(self, real_sample):
        cam = real_sample.cameras["CAM_FRONT"]
        np.testing.assert_allclose(cam.T_ego_from_cam @ cam.T_cam_from_ego, np.eye(4), atol=1e-12)
        np.testing.assert_allclose(cam.T_global_from_cam @ cam.T_cam_from_global, np.eye(4), atol=1e-9)
        centre_ego = cam.T_ego_from_cam[:3, 3]
        assert 1.4 < centre_ego[2] < 1.8  # height above the ego origin (on the ground)
        assert centre_ego[0] > 1.0  # forward of the rear axle
        # CAM_FRONT optical axis (+z cam) points along ego +x; image down (+y cam) along ego -z
        axes_ego = cam.T_ego_from_cam[:3, :3]
        assert axes_ego[:, 2] @ np.array([1.0, 0, 0]) > 0.99
        assert axes_ego[:, 1] @ np.array([0, 0, -1.0]) > 0.99
        back = real_sample.cameras["CAM_BACK"].T_ego_from_cam[:3, :3]
        assert back[:, 2] @ np.array([-1.0, 0, 0]) > 0.99

    @pytest.mark.parametrize("channel,sign", [("CAM_FRONT", 1.0), ("CAM_BACK", -1.0)])
    def test_boxes_ahead_project_into_image(self, real_sample, channel, sign):
        """Boxes well inside the camera's cone, decided in the ego frame, land inside its image."""
        cam = real_sample.cameras[channel]
        centres_global = np.array([b.center for b in real_sample.boxes])
        centres_ego = transform_points(invert_transform(cam.T_global_from_ego), centres_global)
        fwd = sign * centres_ego[:, 0]
        ahead = (fwd > 4.0) & (np.abs(centres_ego[:, 1]) < 0.4 * fwd)
        assert ahead.sum() >= 3, "the real sample has several boxes in this camera's view"
        uv, z = project_points(cam.K, transform_points(cam.T_cam_from_global, centres_global[ahead]))
        assert np.all(z > 0)
        assert np.all((uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1))
        # boxes behind the camera are behind it in the camera frame too
        behind = fwd < -2.0
        _, z_behind = project_points(cam.K, transform_points(cam.T_cam_from_global, centres_global[behind]))
        assert np.all(z_behind < 0)

    def test_lidar_points_in_boxes_equal_num_lidar_pts(self, real_sample, real_reader):
        """Strong frame test: points-in-box counts through all tables equal sample_annotation.num_lidar_pts."""
        sweep = real_sample.lidar
        assert sweep.points_sensor.shape == (34688, 3) and sweep.labels is None
        points_global = sweep.points_global
        counts = np.array([points_in_box_mask(b, points_global).sum() for b in real_sample.boxes])
        expected = np.array([real_reader.get("sample_annotation", b.token)["num_lidar_pts"] for b in real_sample.boxes])
        np.testing.assert_array_equal(counts, expected)
        assert (counts > 0).mean() > 0.8

    def test_lidar_projects_into_cam_front(self, real_sample):
        cam = real_sample.cameras["CAM_FRONT"]
        sweep = real_sample.lidar
        p_ego = sweep.points_in(invert_transform(cam.T_global_from_ego))
        # a cone around ego +x from the camera centre, narrower than the field of view (decided in the ego frame)
        d = p_ego - cam.T_ego_from_cam[:3, 3]
        cone = (d[:, 0] > 3.0) & (np.abs(d[:, 1]) < 0.5 * d[:, 0]) & (np.abs(d[:, 2]) < 0.25 * d[:, 0])
        assert cone.sum() > 1000
        uv, z = project_points(cam.K, sweep.points_in(cam.T_cam_from_global)[cone])
        assert np.all(z > 0)
        assert np.all((uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height))
        # ground returns ahead (ego z ~ 0) lie below the principal point (image y down)
        ground = cone & (np.abs(p_ego[:, 2]) < 0.3) & (p_ego[:, 0] < 30)
        assert ground.sum() > 100
        uv_g, _ = project_points(cam.K, sweep.points_in(cam.T_cam_from_global)[ground])
        assert np.all(uv_g[:, 1] > cam.K[1, 2])

    def test_boxes_in_camera_frame(self, real_sample):
        """Box.transformed keeps the box where its LiDAR points are, in the camera frame."""
        cam = real_sample.cameras["CAM_FRONT"]
        points_cam = real_sample.lidar.points_in(cam.T_cam_from_global)
        b = max(real_sample.boxes, key=lambda b: points_in_box_mask(b, real_sample.lidar.points_global).sum())
        b_cam = b.transformed(cam.T_cam_from_global)
        np.testing.assert_array_equal(points_in_box_mask(b_cam, points_cam), points_in_box_mask(b, real_sample.lidar.points_global))

    def test_lazy_images_and_lidar(self, real_reader, monkeypatch):
        calls = {"image": 0, "lidar": 0}
        real_read_image, real_read_lidar = nus.read_image_rgb, nus.read_lidar_points

        def counting_image(path):
            calls["image"] += 1
            return real_read_image(path)

        def counting_lidar(path):
            calls["lidar"] += 1
            return real_read_lidar(path)

        monkeypatch.setattr(nus, "read_image_rgb", counting_image)  # the reader decodes (after its path checks)
        monkeypatch.setattr(nus, "read_lidar_points", counting_lidar)
        s = real_reader.sample(REAL_SAMPLE)
        assert calls == {"image": 0, "lidar": 0}
        assert all("image" not in c.__dict__ for c in s.cameras.values())
        assert "lidar" not in s.__dict__
        image = s.cameras["CAM_FRONT"].image
        assert image.shape == (900, 1600, 3) and image.dtype == np.uint8
        assert s.cameras["CAM_FRONT"].image is image
        assert calls["image"] == 1
        assert s.lidar is s.lidar and calls["lidar"] == 1

    def test_corrupt_jpeg(self, tmp_path):
        root = tmp_path / "nus"
        shutil.copytree(REAL / "v1.0-mini", root / "v1.0-mini")
        src = REAL / "samples" / "CAM_FRONT"
        (root / "samples" / "CAM_FRONT").mkdir(parents=True)
        for f in src.iterdir():
            (root / "samples" / "CAM_FRONT" / f.name).write_bytes(f.read_bytes()[:5000])
        cam = NuScenesReader(root, "v1.0-mini").sample(REAL_SAMPLE).cameras["CAM_FRONT"]
        with pytest.raises(InputError, match="cannot decode") as e:
            cam.image
        assert cam.image_path in str(e.value)
        missing = NuScenesReader(root, "v1.0-mini").sample(REAL_SAMPLE).cameras["CAM_BACK"]
        with pytest.raises(InputError, match="not found"):
            missing.image


@needs_real
class TestRealDrivableArea:
    def test_ego_on_drivable_area(self, real_reader, real_sample):
        area = real_reader.drivable_area("singapore-onenorth")
        geoms = real_sample.drivable_area_global
        assert geoms is area.geometries and len(geoms) == 7
        ego_xy = real_sample.cameras["CAM_FRONT"].T_global_from_ego[:2, 3]
        assert area.contains_xy(ego_xy[None]).tolist() == [True]
        assert any(g.contains(shapely.Point(*ego_xy)) for g in geoms)
        # 200 m away in a straight line from the ego, sideways, is not all road
        far = ego_xy[None] + np.array([[500.0, 500.0], [-500.0, 500.0]])
        assert not area.contains_xy(far).all()

    def test_near(self, real_reader, real_sample):
        ego_xy = real_sample.cameras["CAM_FRONT"].T_global_from_ego[:2, 3]
        near = real_reader.drivable_area_near("singapore-onenorth", ego_xy, 30.0)
        assert near.contains(shapely.Point(*ego_xy))
        assert 0 < near.area <= 60.0**2 + 1e-6
        minx, miny, maxx, maxy = near.bounds
        assert minx >= ego_xy[0] - 30 - 1e-9 and maxx <= ego_xy[0] + 30 + 1e-9
        assert miny >= ego_xy[1] - 30 - 1e-9 and maxy <= ego_xy[1] + 30 + 1e-9
        # drivable area is cached per location
        assert real_reader.drivable_area("singapore-onenorth") is real_reader.drivable_area("singapore-onenorth")

    def test_holes_are_kept(self):
        geoms = read_drivable_area(REAL / "maps" / "expansion" / "singapore-onenorth.json")
        data = json.loads((REAL / "maps" / "expansion" / "singapore-onenorth.json").read_text())
        n_holes = sum(len(p["holes"]) for p in data["polygon"])
        interiors = sum(
            len(p.interiors) for g in geoms for p in (g.geoms if hasattr(g, "geoms") else [g])
        )
        assert n_holes > 0 and interiors == n_holes


# ============================================================================ lidarseg fixture


@needs_fixtures
class TestLidarsegFixture:
    def test_points_and_labels(self):
        pcd = next((FIXTURES / "samples" / "LIDAR_TOP").glob("*.pcd.bin"))
        points = read_lidar_points(pcd)
        assert points.shape == (40, 5) and points.dtype == np.float32
        assert np.all(np.isfinite(points))
        ring = points[:, 4]
        assert np.all(ring == np.round(ring)) and ring.min() >= 0 and ring.max() < 32
        seg = FIXTURES / "lidarseg" / "v1.0-trainval" / "5f6c1e0a0c3b444b97e78d2aa3fa34d2_lidarseg.bin"
        labels = read_lidarseg_labels(seg, num_points=len(points))
        assert labels.shape == (40,) and labels.dtype == np.uint8
        values, counts = np.unique(labels, return_counts=True)
        # histogram documented in nuscenes-fixtures/README.md
        assert dict(zip(values.tolist(), counts.tolist())) == {17: 2, 24: 15, 27: 1, 28: 12, 30: 1, 31: 9}
        # vehicle.ego (31) points are close to the sensor, the others are not all
        dist = np.linalg.norm(points[:, :2], axis=1)
        assert dist[labels == 31].max() < dist[labels != 31].max()

    def test_count_mismatch(self):
        seg = FIXTURES / "lidarseg" / "v1.0-trainval" / "5f6c1e0a0c3b444b97e78d2aa3fa34d2_lidarseg.bin"
        with pytest.raises(DatasetError, match="40 labels but the LiDAR sweep has 41 points") as e:
            read_lidarseg_labels(seg, num_points=41)
        assert str(seg) in str(e.value)

    def test_truncated_pcd(self, tmp_path):
        pcd = next((FIXTURES / "samples" / "LIDAR_TOP").glob("*.pcd.bin"))
        bad = tmp_path / pcd.name
        bad.write_bytes(pcd.read_bytes()[:-7])
        with pytest.raises(DatasetError, match="not a multiple of 20") as e:
            read_lidar_points(bad)
        assert str(bad) in str(e.value)


# ============================================================================ synthetic dataset

VERSION = "v1.0-test"
SCENE_TOKEN = "scene_tok"
SAMPLES = ["s_first", "s_second"]
CAM_K = [[1000.0, 0.0, 79.5], [0.0, 1000.0, 44.5], [0.0, 0.0, 1.0]]
# nuScenes-like CAM_FRONT rotation: camera (x right, y down, z fwd) -> ego (x fwd, y left, z up)
CAM_ROT = [0.5, -0.5, 0.5, -0.5]
CAM_T = [1.7, 0.0, 1.5]
LIDAR_ROT = [1.0, 0.0, 0.0, 0.0]
LIDAR_T = [0.9, 0.0, 1.8]


def _write_table(root: Path, name: str, rows: list[dict]) -> None:
    (root / VERSION).mkdir(parents=True, exist_ok=True)
    (root / VERSION / f"{name}.json").write_text(json.dumps(rows))


def make_dataset(root: Path, n_points: int = 6, lidarseg: str = "table") -> Path:
    """A 2-sample nuScenes-format dataset: CAM_FRONT (160x90 JPEG) + LIDAR_TOP + 1 car + a map."""
    _write_table(root, "sensor", [
        {"token": "sen_cam", "channel": "CAM_FRONT", "modality": "camera"},
        {"token": "sen_lidar", "channel": "LIDAR_TOP", "modality": "lidar"},
    ])
    _write_table(root, "calibrated_sensor", [
        {"token": "cs_cam", "sensor_token": "sen_cam", "rotation": CAM_ROT, "translation": CAM_T, "camera_intrinsic": CAM_K},
        {"token": "cs_lidar", "sensor_token": "sen_lidar", "rotation": LIDAR_ROT, "translation": LIDAR_T, "camera_intrinsic": []},
    ])
    _write_table(root, "log", [{"token": "log0", "location": "test-town", "logfile": "l", "vehicle": "v", "date_captured": "2020-01-01"}])
    _write_table(root, "map", [{"token": "map0", "category": "semantic_prior", "filename": "", "log_tokens": ["log0"]}])
    _write_table(root, "scene", [{
        "token": SCENE_TOKEN, "name": "scene-test", "description": "", "log_token": "log0",
        "nbr_samples": 2, "first_sample_token": SAMPLES[0], "last_sample_token": SAMPLES[1],
    }])
    # table order deliberately differs from time order
    _write_table(root, "sample", [
        {"token": SAMPLES[1], "timestamp": 2_000_000, "scene_token": SCENE_TOKEN, "prev": SAMPLES[0], "next": ""},
        {"token": SAMPLES[0], "timestamp": 1_500_000, "scene_token": SCENE_TOKEN, "prev": "", "next": SAMPLES[1]},
    ])
    sample_data, ego_poses = [], []
    for i, s in enumerate(SAMPLES):
        for kind, cs, ext, w, h, dt in (("cam", "cs_cam", "jpg", 160, 90, -10_000), ("lidar", "cs_lidar", "pcd.bin", 0, 0, 0)):
            tok = f"sd_{kind}_{i}"
            channel = "CAM_FRONT" if kind == "cam" else "LIDAR_TOP"
            sample_data.append({
                "token": tok, "sample_token": s, "ego_pose_token": tok, "calibrated_sensor_token": cs,
                "timestamp": 1_500_000 + 500_000 * i + dt, "fileformat": ext.split(".")[0], "is_key_frame": True,
                "height": h, "width": w, "filename": f"samples/{channel}/{tok}.{ext}", "prev": "", "next": "",
            })
            ego_poses.append({"token": tok, "timestamp": 0, "rotation": yaw_to_quat(0.1 * i).tolist(), "translation": [100.0 + 5 * i, 200.0, 0.0]})
        # a non-keyframe sweep of the camera must be ignored
        sample_data.append({**sample_data[-2], "token": f"sd_cam_sweep_{i}", "ego_pose_token": f"sd_cam_{i}", "is_key_frame": False})
    _write_table(root, "sample_data", sample_data)
    _write_table(root, "ego_pose", ego_poses)
    _write_table(root, "category", [{"token": "cat_car", "name": "vehicle.car", "description": "", "index": 17}])
    _write_table(root, "attribute", [{"token": "att_park", "name": "vehicle.parked", "description": ""}])
    _write_table(root, "instance", [{"token": "inst0", "category_token": "cat_car", "nbr_annotations": 1,
                                     "first_annotation_token": "ann0", "last_annotation_token": "ann0"}])
    _write_table(root, "sample_annotation", [{
        "token": "ann0", "sample_token": SAMPLES[0], "instance_token": "inst0", "attribute_tokens": ["att_park"],
        "visibility_token": "4", "translation": [115.0, 201.0, 0.8], "size": [1.9, 4.5, 1.6],
        "rotation": yaw_to_quat(0.3).tolist(), "num_lidar_pts": 2, "num_radar_pts": 0, "prev": "", "next": "",
    }])
    # files
    image = np.zeros((90, 160, 3), np.uint8)
    image[:, :80] = (200, 30, 30)
    for i in range(2):
        (root / "samples" / "CAM_FRONT").mkdir(parents=True, exist_ok=True)
        (root / "samples" / "LIDAR_TOP").mkdir(parents=True, exist_ok=True)
        (root / "samples" / "CAM_FRONT" / f"sd_cam_{i}.jpg").write_bytes(sio.encode_image_rgb(image, ".jpg"))
        pts = np.zeros((n_points, 5), np.float32)
        pts[:, 0] = np.arange(n_points) + 1.0
        pts[:, 3] = 7.0
        pts.tofile(root / "samples" / "LIDAR_TOP" / f"sd_lidar_{i}.pcd.bin")
    labels = (np.arange(n_points) % 3 + 24).astype(np.uint8)
    if lidarseg == "table":
        (root / "lidarseg" / VERSION).mkdir(parents=True)
        labels.tofile(root / "lidarseg" / VERSION / "labels0.bin")
        _write_table(root, "lidarseg", [{"token": "ls0", "sample_data_token": "sd_lidar_0", "filename": f"lidarseg/{VERSION}/labels0.bin"}])
    elif lidarseg == "fallback":
        (root / "lidarseg" / VERSION).mkdir(parents=True)
        labels.tofile(root / "lidarseg" / VERSION / "sd_lidar_0_lidarseg.bin")
    # map expansion: a 40 m x 20 m road with a 2 m x 2 m hole (an island), plus a separate square
    nodes = {"a": (90, 190), "b": (130, 190), "c": (130, 210), "d": (90, 210),
             "h1": (119, 199), "h2": (121, 199), "h3": (121, 201), "h4": (119, 201),
             "e": (300, 300), "f": (310, 300), "g": (310, 310)}
    exp = {
        "version": "1.3",
        "node": [{"token": k, "x": float(x), "y": float(y)} for k, (x, y) in nodes.items()],
        "polygon": [
            {"token": "p0", "exterior_node_tokens": ["a", "b", "c", "d"], "holes": [{"node_tokens": ["h1", "h2", "h3", "h4"]}]},
            {"token": "p1", "exterior_node_tokens": ["e", "f", "g"], "holes": []},
        ],
        "drivable_area": [{"token": "da0", "polygon_tokens": ["p0"]}, {"token": "da1", "polygon_tokens": ["p1"]}],
    }
    (root / "maps" / "expansion").mkdir(parents=True)
    (root / "maps" / "expansion" / "test-town.json").write_text(json.dumps(exp))
    return root


@pytest.fixture
def mini(tmp_path) -> Path:
    return make_dataset(tmp_path / "mini")


class TestSyntheticDataset:
    def test_tokens_in_time_order(self, mini):
        r = NuScenesReader(mini, VERSION)
        assert r.scene_names() == ["scene-test"]
        assert r.sample_tokens() == SAMPLES
        assert r.sample_tokens(SCENE_TOKEN) == SAMPLES
        assert r.location_of(SAMPLES[1]) == "test-town"

    def test_sample(self, mini):
        r = NuScenesReader(mini, VERSION)
        s = r.sample(SAMPLES[1])
        assert (s.scene_name, s.location, s.timestamp_us) == ("scene-test", "test-town", 2_000_000)
        assert list(s.cameras) == ["CAM_FRONT"] and s.boxes == ()
        cam = s.cameras["CAM_FRONT"]
        assert (cam.width, cam.height, cam.timestamp_us, cam.sample_data_token) == (160, 90, 1_990_000, "sd_cam_1")
        np.testing.assert_array_equal(cam.K, np.array(CAM_K))
        np.testing.assert_allclose(cam.T_ego_from_cam, make_transform(CAM_ROT, CAM_T))
        np.testing.assert_allclose(cam.T_global_from_ego, make_transform(yaw_to_quat(0.1), [105.0, 200.0, 0.0]))
        # a point 10 m ahead of the ego at camera height projects to the principal point
        p_global = transform_points(cam.T_global_from_ego, np.array([[10.0 + CAM_T[0], 0.0, CAM_T[2]]]))
        uv, z = project_points(cam.K, transform_points(cam.T_cam_from_global, p_global))
        np.testing.assert_allclose(uv[0], [79.5, 44.5], atol=1e-9)
        np.testing.assert_allclose(z, [10.0])
        image = cam.image
        assert image.shape == (90, 160, 3)
        assert image[45, 20, 0] > 150 and image[45, 140, 0] < 50  # red left half: RGB order kept

    def test_box_and_attributes(self, mini):
        s = NuScenesReader(mini, VERSION).sample(SAMPLES[0])
        (box,) = s.boxes
        assert (box.category, box.token, box.attributes) == ("vehicle.car", "ann0", ("vehicle.parked",))
        np.testing.assert_allclose(box.center, [115.0, 201.0, 0.8])
        np.testing.assert_allclose(box.wlh, [1.9, 4.5, 1.6])
        # heading 0.3 rad: the front corner lies along (cos 0.3, sin 0.3) from the centre
        front_mid = box.corners()[:4].mean(axis=0)
        np.testing.assert_allclose((front_mid - box.center)[:2], 2.25 * np.array([np.cos(0.3), np.sin(0.3)]), atol=1e-9)

    def test_lidar_and_lidarseg_from_table(self, mini):
        r = NuScenesReader(mini, VERSION)
        sweep = r.sample(SAMPLES[0]).lidar
        np.testing.assert_allclose(sweep.points_sensor[:, 0], np.arange(6) + 1.0)
        assert sweep.intensity.dtype == np.float32 and np.all(sweep.intensity == 7.0)
        assert sweep.labels.tolist() == [24, 25, 26, 24, 25, 26]
        # sensor (x, 0, 0) -> ego (x + 0.9, 0, 1.8) -> global at the lidar's ego pose
        np.testing.assert_allclose(sweep.points_global[0], [100.0 + 1.9, 200.0, 1.8])
        # the second sample has no lidarseg row and no fallback file
        assert r.sample(SAMPLES[1]).lidar.labels is None

    def test_lidarseg_fallback_path(self, tmp_path):
        r = NuScenesReader(make_dataset(tmp_path / "fb", lidarseg="fallback"), VERSION)
        assert r.table("lidarseg") == []
        assert r.sample(SAMPLES[0]).lidar.labels.tolist() == [24, 25, 26, 24, 25, 26]

    def test_drivable_area(self, mini):
        r = NuScenesReader(mini, VERSION)
        s = r.sample(SAMPLES[0])
        assert len(s.drivable_area_global) == 2
        area = r.drivable_area("test-town")
        xy = np.array([[100.0, 200.0], [120.0, 200.0], [125.0, 205.0], [150.0, 200.0], [308.0, 301.0]])
        assert area.contains_xy(xy).tolist() == [True, False, True, False, True]  # (120, 200) is in the hole
        near = r.drivable_area_near("test-town", [100.0, 200.0], 5.0)
        assert near.area == pytest.approx(100.0)
        far = r.drivable_area_near("test-town", [0.0, 0.0], 5.0)
        assert far.is_empty
        assert NuScenesReader(mini, VERSION, with_map=False).sample(SAMPLES[0]).drivable_area_global is None

    def test_no_map_is_not_an_error(self, mini):
        shutil.rmtree(mini / "maps")
        r = NuScenesReader(mini, VERSION)
        assert r.sample(SAMPLES[0]).drivable_area_global is None
        assert r.drivable_area_near("test-town", [0.0, 0.0], 5.0) is None


class TestErrors:
    def test_missing_dataroot(self, tmp_path):
        with pytest.raises(DatasetError, match="dataset root folder not found") as e:
            NuScenesReader(tmp_path / "nope", VERSION)
        assert str(tmp_path / "nope") in str(e.value)
        assert isinstance(e.value, InputError)

    def test_missing_version(self, mini):
        with pytest.raises(DatasetError, match=f"versions found: {VERSION}") as e:
            NuScenesReader(mini, "v1.0-mini")
        assert "v1.0-mini" in str(e.value)

    @pytest.mark.parametrize("table", ["sample_annotation", "ego_pose", "sensor"])
    def test_missing_table(self, mini, table):
        (mini / VERSION / f"{table}.json").unlink()
        with pytest.raises(DatasetError, match="required nuScenes table missing") as e:
            NuScenesReader(mini, VERSION)
        assert f"{table}.json" in str(e.value)

    def test_bad_json_table(self, mini):
        (mini / VERSION / "sample.json").write_text("[{")
        r = NuScenesReader(mini, VERSION)
        with pytest.raises(DatasetError, match="sample.json: table is not valid JSON"):
            r.sample_tokens()

    def test_unknown_scene(self, mini):
        r = NuScenesReader(mini, VERSION)
        with pytest.raises(DatasetError, match="scene-9999.*known scenes: scene-test"):
            r.sample_tokens("scene-9999")

    def test_unknown_sample(self, mini):
        r = NuScenesReader(mini, VERSION)
        with pytest.raises(DatasetError, match="unknown sample token 'deadbeef'") as e:
            r.sample("deadbeef")
        assert "sample.json" in str(e.value)

    def test_dangling_token(self, mini):
        rows = json.loads((mini / VERSION / "instance.json").read_text())
        rows[0]["category_token"] = "cat_missing"
        (mini / VERSION / "instance.json").write_text(json.dumps(rows))
        with pytest.raises(DatasetError, match="no category with token 'cat_missing'"):
            NuScenesReader(mini, VERSION).sample(SAMPLES[0])

    def test_bad_intrinsics(self, mini):
        rows = json.loads((mini / VERSION / "calibrated_sensor.json").read_text())
        rows[0]["camera_intrinsic"] = [[1, 0], [0, 1]]
        (mini / VERSION / "calibrated_sensor.json").write_text(json.dumps(rows))
        with pytest.raises(DatasetError, match="camera_intrinsic must be a finite 3x3"):
            NuScenesReader(mini, VERSION).sample(SAMPLES[0])

    def test_truncated_pcd_through_reader(self, mini):
        path = mini / "samples" / "LIDAR_TOP" / "sd_lidar_0.pcd.bin"
        path.write_bytes(path.read_bytes()[:-3])
        s = NuScenesReader(mini, VERSION).sample(SAMPLES[0])  # still lazy: building works
        with pytest.raises(DatasetError, match="not a multiple of 20") as e:
            s.lidar
        assert str(path) in str(e.value)

    def test_missing_pcd(self, mini):
        path = mini / "samples" / "LIDAR_TOP" / "sd_lidar_0.pcd.bin"
        path.unlink()
        with pytest.raises(DatasetError, match="LiDAR file not found"):
            NuScenesReader(mini, VERSION).sample(SAMPLES[0]).lidar

    def test_lidarseg_count_mismatch(self, mini):
        seg = mini / "lidarseg" / VERSION / "labels0.bin"
        seg.write_bytes(seg.read_bytes()[:-1])
        with pytest.raises(DatasetError, match="5 labels but the LiDAR sweep has 6 points") as e:
            NuScenesReader(mini, VERSION).sample(SAMPLES[0]).lidar
        assert str(seg) in str(e.value)

    def test_corrupt_jpeg(self, mini):
        path = mini / "samples" / "CAM_FRONT" / "sd_cam_0.jpg"
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
        cam = NuScenesReader(mini, VERSION).sample(SAMPLES[0]).cameras["CAM_FRONT"]
        with pytest.raises(InputError, match="cannot decode image") as e:
            cam.image
        assert str(path) in str(e.value)

    def test_bad_map(self, mini):
        (mini / "maps" / "expansion" / "test-town.json").write_text(json.dumps({"node": [], "polygon": []}))
        with pytest.raises(DatasetError, match="no 'drivable_area' layer"):
            NuScenesReader(mini, VERSION).sample(SAMPLES[0])

    def test_next_cycle(self, mini):
        rows = json.loads((mini / VERSION / "sample.json").read_text())
        rows[0]["next"] = SAMPLES[0]  # second -> first -> second ...
        (mini / VERSION / "sample.json").write_text(json.dumps(rows))
        with pytest.raises(DatasetError, match="cycle"):
            NuScenesReader(mini, VERSION).sample_tokens()


# ============================================================================ parity with the official devkit


@needs_real
class TestDevkitParity:
    """Our tables-to-frames chain agrees with the nuScenes devkit (skipped when it is not installed)."""

    def test_boxes_in_camera_frame_match_devkit(self, real_sample):
        NuScenes = devkit().NuScenes

        nusc = NuScenes(version="v1.0-mini", dataroot=str(REAL), verbose=False)
        sample_row = nusc.get("sample", REAL_SAMPLE)
        ours_by_token = {b.token: b for b in real_sample.boxes}
        for channel, cam in real_sample.cameras.items():
            path, dk_boxes, dk_K = nusc.get_sample_data(sample_row["data"][channel])
            assert Path(path) == Path(cam.image_path)
            np.testing.assert_allclose(cam.K, dk_K)
            assert len(dk_boxes) >= 2  # boxes visible in this camera (devkit's BoxVisibility.ANY)
            for dk in dk_boxes:
                ours = ours_by_token[dk.token].transformed(cam.T_cam_from_global)
                np.testing.assert_allclose(ours.center, dk.center, atol=1e-6)
                np.testing.assert_allclose(ours.wlh, dk.wlh)
                np.testing.assert_allclose(ours.corners(), dk.corners().T, atol=1e-6)
                assert ours.category == dk.name

    def test_drivable_area_matches_devkit(self):
        devkit()
        from nuscenes.map_expansion.map_api import NuScenesMap

        nmap = NuScenesMap(dataroot=str(REAL), map_name="singapore-onenorth")
        ours = read_drivable_area(REAL / "maps" / "expansion" / "singapore-onenorth.json")
        assert len(ours) == len(nmap.drivable_area)
        for geom, rec in zip(ours, nmap.drivable_area):
            theirs = shapely.union_all([nmap.extract_polygon(t) for t in rec["polygon_tokens"]])
            assert geom.symmetric_difference(theirs).area < 1e-6 * max(theirs.area, 1.0)


def test_with_image_and_with_lidar_replace_only_what_they_say(tmp_path):
    from placement_fixtures import camera_view, lidar_sweep, make_sample

    view = camera_view()
    other = np.full((view.height, view.width, 3), 7, np.uint8)
    swapped = view.with_image(other)
    assert swapped.image is other and swapped.K is view.K and view.image.max() == 0
    sample = make_sample(lidar=lidar_sweep(np.array([[10.0, 0.0, 0.0], [12.0, 1.0, 0.5]])))
    assert sample.lidar is not None and sample.with_lidar(None).lidar is None
    evolved = sample.evolve(boxes=())
    assert evolved.lidar is sample.lidar and evolved.boxes == ()
