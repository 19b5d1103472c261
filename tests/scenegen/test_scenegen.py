"""Tests of the bundled sample-scene generator (augment/scenegen), on small renders in tmp dirs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import devkit

from streetaug.augment.core import (
    camera_dir_to_lonlat,
    invert_transform,
    luminance,
    make_transform,
    read_exr,
    read_image_rgb,
    rotate_vectors,
    sample_equirect,
    transform_points,
    yaw_to_quat,
)
from streetaug.augment.lighting.sun import sun_direction_global
from streetaug.augment.pipeline.lidar import empty_beams
from streetaug.augment.scenegen.ground_truth import ground_truth_light
from streetaug.augment.scenegen.lidar import N_AZIMUTH, N_RINGS, beam_directions_sensor, points_in_box
from streetaug.augment.scenegen.make import CAMERA_RIGS, SAMPLE_SCENES, choose_exposure, make_sample_scenes
from streetaug.augment.scenegen.render import SkyParams, StreetRenderer
from streetaug.augment.scenegen.street import StreetParams, build_street
from streetaug.datasets.nuscenes_format import LIDARSEG_CAR, LIDARSEG_DRIVEABLE, visibility_token
from streetaug.datasets.sample import Box

W, H = 320, 180
FAST = dict(width=W, height=H, seed=0, spp=1, sky_rays=1)
VERSION = "v1.0-samples"


@pytest.fixture(scope="module")
def dataroot(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("samples")
    make_sample_scenes(out, **FAST)
    return out


def _tables(root: Path) -> dict[str, list[dict]]:
    return {p.stem: json.loads(p.read_text()) for p in sorted((root / VERSION).glob("*.json"))}


def _by_token(rows: list[dict]) -> dict[str, dict]:
    return {r["token"]: r for r in rows}


def _pose(row: dict) -> np.ndarray:
    return make_transform(np.array(row["rotation"]), row["translation"])


def _lidar_global(root: Path, tables: dict, scene_name: str):
    """Points (N, 3) global, labels (N,), and the scene's annotations."""
    scene = next(s for s in tables["scene"] if s["name"] == scene_name)
    sd = next(d for d in tables["sample_data"] if d["sample_token"] == scene["first_sample_token"] and d["fileformat"] == "pcd")
    cs = _by_token(tables["calibrated_sensor"])[sd["calibrated_sensor_token"]]
    ego = _by_token(tables["ego_pose"])[sd["ego_pose_token"]]
    pts = np.fromfile(root / sd["filename"], dtype=np.float32).reshape(-1, 5)
    seg = next(r for r in tables["lidarseg"] if r["sample_data_token"] == sd["token"])
    labels = np.fromfile(root / seg["filename"], dtype=np.uint8)
    p_global = transform_points(_pose(ego) @ _pose(cs), pts[:, :3].astype(np.float64))
    anns = [a for a in tables["sample_annotation"] if a["sample_token"] == scene["first_sample_token"]]
    return p_global, labels, anns


def test_writes_every_expected_file(dataroot: Path) -> None:
    for name in ("sample-sunny", "sample-overcast", "sample-lowsun"):
        assert (dataroot / "ground_truth" / name / "lighting.json").is_file()
        assert (dataroot / "ground_truth" / name / "envmap_world.exr").is_file()
    for folder in ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_BACK", "LIDAR_TOP"):
        assert len(list((dataroot / "samples" / folder).iterdir())) == 3
    assert (dataroot / "maps" / "expansion" / "boston-seaport.json").is_file()
    assert (dataroot / "maps" / "expansion" / "singapore-onenorth.json").is_file()
    img = read_image_rgb(next((dataroot / "samples" / "CAM_FRONT").iterdir()))
    assert img.shape == (H, W, 3)


def test_regeneration_is_byte_identical(dataroot: Path, tmp_path: Path) -> None:
    make_sample_scenes(tmp_path, **FAST)
    files_a = sorted(p.relative_to(dataroot) for p in dataroot.rglob("*") if p.is_file())
    files_b = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert files_a == files_b
    different = [str(f) for f in files_a if (dataroot / f).read_bytes() != (tmp_path / f).read_bytes()]
    assert different == []


def test_every_token_reference_resolves(dataroot: Path) -> None:
    t = _tables(dataroot)
    tok = {name: set(_by_token(rows)) for name, rows in t.items()}
    refs = {
        "sample": [("scene_token", "scene")],
        "scene": [("log_token", "log"), ("first_sample_token", "sample"), ("last_sample_token", "sample")],
        "sample_data": [("sample_token", "sample"), ("ego_pose_token", "ego_pose"), ("calibrated_sensor_token", "calibrated_sensor")],
        "calibrated_sensor": [("sensor_token", "sensor")],
        "sample_annotation": [("sample_token", "sample"), ("instance_token", "instance"), ("visibility_token", "visibility")],
        "instance": [("category_token", "category"), ("first_annotation_token", "sample_annotation"), ("last_annotation_token", "sample_annotation")],
        "lidarseg": [("sample_data_token", "sample_data")],
    }
    for table, fields in refs.items():
        assert t[table], f"{table} is empty"
        for row in t[table]:
            for field, target in fields:
                assert row[field] in tok[target], f"{table}.{field} = {row[field]} not in {target}"
    for a in t["sample_annotation"]:
        assert all(x in tok["attribute"] for x in a["attribute_tokens"])
    for m in t["map"]:
        assert m["log_tokens"] and all(x in tok["log"] for x in m["log_tokens"])
    for row in t["sample_data"]:
        assert (dataroot / row["filename"]).is_file()
        assert row["ego_pose_token"] == row["token"]
    assert len(t["scene"]) == 3 and len(t["sample"]) == 3
    for scene in t["scene"]:
        log = _by_token(t["log"])[scene["log_token"]]
        assert log["location"] == SAMPLE_SCENES[scene["name"]].location


def test_camera_calibration_looks_along_ego_x(dataroot: Path) -> None:
    t = _tables(dataroot)
    sensors = _by_token(t["sensor"])
    for cs in t["calibrated_sensor"]:
        channel = sensors[cs["sensor_token"]]["channel"]
        if channel == "CAM_FRONT":
            R = _pose(cs)[:3, :3]
            np.testing.assert_allclose(R @ [0, 0, 1], [1, 0, 0], atol=1e-6)  # optical axis -> ego +x
            np.testing.assert_allclose(R @ [1, 0, 0], [0, -1, 0], atol=1e-6)  # image right -> ego right
            np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, -1], atol=1e-6)  # image down -> ego down
            K = np.array(cs["camera_intrinsic"])
            np.testing.assert_allclose(K[0, 0], 1266.417 * W / 1600, rtol=1e-6)


def test_lidar_road_points_lie_on_the_ground(dataroot: Path) -> None:
    t = _tables(dataroot)
    for name in SAMPLE_SCENES:
        p, labels, _ = _lidar_global(dataroot, t, name)
        assert len(p) == len(labels) > 10000
        road = labels == LIDARSEG_DRIVEABLE
        assert road.sum() > 1000
        assert np.abs(p[road, 2]).max() < 0.05
        # and nothing else that low near the ego is labelled as something standing
        assert set(np.unique(labels)) <= {0, 12, 17, 24, 26, 27, 28, 30}


def test_lidar_stores_every_beam_in_firing_order_as_nuscenes_does(dataroot: Path) -> None:
    t = _tables(dataroot)
    scene = next(s for s in t["scene"] if s["name"] == "sample-sunny")
    sd = next(d for d in t["sample_data"] if d["sample_token"] == scene["first_sample_token"] and d["fileformat"] == "pcd")
    pts = np.fromfile(dataroot / sd["filename"], dtype=np.float32).reshape(-1, 5)
    _, labels, _ = _lidar_global(dataroot, t, "sample-sunny")
    assert pts.shape == (N_RINGS * N_AZIMUTH, 5)
    np.testing.assert_array_equal(pts[:, 4], np.arange(len(pts)) % N_RINGS)  # ring after ring, firing after firing
    none = ~pts[:, :3].any(axis=1)  # no return: at the sensor, intensity 0, class noise
    assert 0 < none.sum() < len(pts) // 2 and not pts[none, 3].any() and not labels[none].any()
    # the insertion rebuilds those beams where the generator cast them
    empty = empty_beams(pts)
    d, ring = beam_directions_sensor()
    firing_order = np.arange(len(d)).reshape(N_RINGS, N_AZIMUTH).T.ravel()
    truth = d[firing_order][empty.mask]
    assert empty.mask.sum() > 0.5 * none.sum()  # the steep rings' (below -10 deg) are left alone
    assert np.degrees(np.arccos(np.clip((empty.directions * truth).sum(1), -1, 1))).max() < 0.05


def test_boxes_contain_their_lidar_points(dataroot: Path) -> None:
    t = _tables(dataroot)
    for name in SAMPLE_SCENES:
        p, labels, anns = _lidar_global(dataroot, t, name)
        assert len(anns) >= 5
        boxes = [Box(np.array(a["translation"]), np.array(a["size"]), np.array(a["rotation"]), "vehicle.car") for a in anns]
        inside_any = np.zeros(len(p), dtype=bool)
        for a, box in zip(anns, boxes):
            inside = points_in_box(box, p, margin_m=0.0)
            assert a["num_lidar_pts"] == inside.sum()
            inside_any |= points_in_box(box, p, margin_m=0.06)  # range noise sigma = 1 cm
        assert sum(a["num_lidar_pts"] > 0 for a in anns) >= len(anns) - 2
        cars = labels == LIDARSEG_CAR
        assert cars.sum() > 100
        assert inside_any[cars].all(), "car points outside every annotated box"


def test_ground_truth_sun_matches_the_ephemeris(dataroot: Path) -> None:
    t = _tables(dataroot)
    for name, spec in SAMPLE_SCENES.items():
        gt = json.loads((dataroot / "ground_truth" / name / "lighting.json").read_text())
        sample = next(s for s in t["sample"] if s["token"] == gt["sample_token"])
        log = next(lg for lg in t["log"] if lg["token"] == next(s for s in t["scene"] if s["name"] == name)["log_token"])
        eph = sun_direction_global(log["location"], sample["timestamp"]).direction_global
        d = np.array(gt["sun"]["direction_global"])
        assert np.degrees(np.arccos(np.clip(d @ eph, -1, 1))) < 0.01
        # per-camera directions agree with the tables' calibration and ego pose
        sds = _by_token(t["sample_data"])
        for channel, cam in gt["cameras"].items():
            sd = sds[cam["sample_data_token"]]
            T_global_from_cam = _pose(_by_token(t["ego_pose"])[sd["ego_pose_token"]]) @ _pose(
                _by_token(t["calibrated_sensor"])[sd["calibrated_sensor_token"]])
            expect = rotate_vectors(invert_transform(T_global_from_cam), eph[None])[0]
            np.testing.assert_allclose(gt["sun"]["direction_camera"][channel], expect, atol=1e-6)
        env = read_exr(dataroot / "ground_truth" / name / "envmap_world.exr")
        assert env.shape == (64, 128, 3) and np.all(np.isfinite(env)) and env.min() > 0
        sky = SkyParams(eph, spec.turbidity, spec.cloud_cover, gt["sky"]["ground_albedo"])
        np.testing.assert_allclose(env, sky.envmap_world(64, 128) * gt["exposure_k"], rtol=1e-4)
        if spec.cloud_cover == 0.0:
            assert gt["sun"]["visibility"] == 1.0 and min(gt["sun"]["irradiance_rgb"]) > 0
    lowsun = json.loads((dataroot / "ground_truth" / "sample-lowsun" / "lighting.json").read_text())
    sunny = json.loads((dataroot / "ground_truth" / "sample-sunny" / "lighting.json").read_text())
    assert 5 < lowsun["sun"]["elevation_deg"] < 20 < 35 < sunny["sun"]["elevation_deg"]


def test_shadowed_road_is_darker_than_lit_road_in_the_sunny_image(dataroot: Path) -> None:
    t = _tables(dataroot)
    spec = SAMPLE_SCENES["sample-sunny"]
    gt = json.loads((dataroot / "ground_truth" / spec.name / "lighting.json").read_text())
    sd = _by_token(t["sample_data"])[gt["cameras"]["CAM_FRONT"]["sample_data_token"]]
    image = read_image_rgb(dataroot / sd["filename"]).astype(np.float64) / 255
    # re-trace the same view to find which road pixels the sun reaches
    T = make_transform(yaw_to_quat(np.radians(spec.heading_deg)), [*spec.origin_xy, 0.0])
    scene = build_street(StreetParams(seed=spec.street_seed, drive_on_left=spec.drive_on_left), T)
    renderer = StreetRenderer(scene, SkyParams(np.array(gt["sun"]["direction_global"]), spec.turbidity, spec.cloud_cover))
    rig = CAMERA_RIGS["CAM_FRONT"]
    res = renderer.render(rig.K(W, H), scene.T_global_from_ego @ rig.T_ego_from_cam(), W, H, spp=1, sky_rays=1, denoise=False)
    road = res.label == LIDARSEG_DRIVEABLE
    lit, shaded = road & (res.shadow > 0.99), road & (res.shadow < 0.01)
    assert lit.sum() > 200 and shaded.sum() > 200
    lum = luminance(image)
    assert np.median(lum[shaded]) < 0.75 * np.median(lum[lit])


def test_exposure_puts_the_road_in_range() -> None:
    label = np.full((10, 10), LIDARSEG_DRIVEABLE, dtype=np.uint8)
    radiance = np.full((10, 10, 3), 7.0)
    k = choose_exposure(radiance, label)
    ldr = (k * 7.0) ** (1 / 2.2)
    assert 0.25 - 1e-3 <= ldr <= 0.45 + 1e-3
    assert choose_exposure(radiance * 10, label) == pytest.approx(k / 10, rel=1e-5)


def test_visibility_levels() -> None:
    assert [visibility_token(f) for f in (0.0, 0.39, 0.5, 0.7, 0.95, 1.0)] == ["1", "1", "2", "3", "4", "4"]


def test_street_is_deterministic_and_leaves_the_lane_ahead_free() -> None:
    T = np.eye(4)
    a = build_street(StreetParams(seed=5), T)
    b = build_street(StreetParams(seed=5), T)
    c = build_street(StreetParams(seed=6), T)
    np.testing.assert_array_equal(a.vertices_global, b.vertices_global)
    assert a.vertices_global.shape != c.vertices_global.shape or not np.array_equal(a.vertices_global, c.vertices_global)
    ego_xy = a.T_global_from_ego[:2, 3]
    for box in a.objects:
        rel = box.center[:2] - ego_xy
        # nothing annotated in the ego's half of the road 10-40 m ahead
        assert not (10 <= rel[0] <= 40 and -4.5 < rel[1] < 1.5), (box.category, rel)


def test_unknown_scene_name_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown sample scene"):
        make_sample_scenes(tmp_path, names=["sample-nope"], width=W, height=H)


def test_devkit_loads_the_dataset(dataroot: Path) -> None:
    nuscenes = devkit()
    nusc = nuscenes.NuScenes(version=VERSION, dataroot=str(dataroot), verbose=False)
    assert len(nusc.scene) == 3
    sample = nusc.get("sample", nusc.scene[0]["first_sample_token"])
    _, boxes, K = nusc.get_sample_data(sample["data"]["CAM_FRONT"])
    assert K.shape == (3, 3) and len(boxes) > 0


def test_map_drivable_area_covers_the_road_points_and_the_ego(dataroot: Path) -> None:
    from shapely.geometry import MultiPoint, Point, Polygon

    t = _tables(dataroot)
    for name, spec in SAMPLE_SCENES.items():
        m = json.loads((dataroot / "maps" / "expansion" / f"{spec.location}.json").read_text())
        nodes = {n["token"]: (n["x"], n["y"]) for n in m["node"]}
        polys = {p["token"]: Polygon([nodes[k] for k in p["exterior_node_tokens"]]) for p in m["polygon"]}
        areas = [polys[tok] for da in m["drivable_area"] for tok in da["polygon_tokens"]]
        assert m["version"] and len(m["canvas_edge"]) == 2 and len(m["lane"]) >= 4
        p, labels, _ = _lidar_global(dataroot, t, name)
        scene = next(s for s in t["scene"] if s["name"] == name)
        lidar_sd = next(d for d in t["sample_data"] if d["sample_token"] == scene["first_sample_token"] and d["fileformat"] == "pcd")
        ego = _by_token(t["ego_pose"])[lidar_sd["ego_pose_token"]]
        ego_xy = ego["translation"][:2]
        area = next(a for a in areas if a.contains(Point(ego_xy)))
        # Lanes lie on the drivable area, and the ego drives along the lane it stands in.
        assert all(area.buffer(0.05).contains(polys[lane["polygon_token"]]) for lane in m["lane"]
                   if polys[lane["polygon_token"]].intersects(area))
        w, x, y, z = ego["rotation"]
        ego_yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        own = [lane for lane in m["lane"] if polys[lane["polygon_token"]].contains(Point(ego_xy))]
        assert len(own) == 1
        (path,) = m["arcline_path_3"][own[0]["token"]]
        assert abs(np.angle(np.exp(1j * (path["start_pose"][2] - ego_yaw)))) < 1e-3
        road_xy = p[labels == LIDARSEG_DRIVEABLE, :2]
        inside = np.array([area.buffer(0.05).contains(Point(xy)) for xy in road_xy[::20]])
        assert inside.all()
        # sidewalk points are outside the drivable area
        side_xy = p[labels == 26, :2][::20]
        assert not any(area.buffer(-0.05).contains(Point(xy)) for xy in side_xy)
        assert MultiPoint([tuple(x) for x in road_xy[::200]]).convex_hull.within(area.buffer(0.1))


def test_ground_truth_light_in_the_camera_frame(dataroot: Path) -> None:
    gt = json.loads((dataroot / "ground_truth" / "sample-sunny" / "lighting.json").read_text())
    light = ground_truth_light(dataroot, "sample-sunny", "CAM_FRONT", 64, 128)
    np.testing.assert_allclose(light.sun.direction, gt["sun"]["direction_camera"]["CAM_FRONT"], atol=1e-6)
    np.testing.assert_allclose(light.sun.irradiance_rgb, gt["sun"]["irradiance_rgb"], rtol=1e-5)
    # the camera-frame map agrees with the world map at the same physical direction (straight up)
    world = read_exr(dataroot / "ground_truth" / "sample-sunny" / "envmap_world.exr")
    up_cam = np.array([gt["cameras"]["CAM_FRONT"]["up_direction_camera"]])
    lon, lat = camera_dir_to_lonlat(up_cam)
    zenith_cam = sample_equirect(light.envmap, lon, lat)[0]
    np.testing.assert_allclose(zenith_cam, world[0].mean(axis=0), rtol=0.05)
    overcast = ground_truth_light(dataroot, "sample-overcast", "CAM_BACK")
    assert overcast.envmap.shape == (128, 256, 3)
    assert luminance(overcast.sun.irradiance_rgb) < 0.1 * luminance(light.sun.irradiance_rgb)


def test_committed_sample_scenes_match_their_specs() -> None:
    root = Path(__file__).resolve().parents[2] / "examples" / "nuscenes-samples"
    if not (root / VERSION).is_dir():
        pytest.skip(f"{root} not generated (python -m streetaug.augment.scenegen.make {root})")
    t = _tables(root)
    assert sorted(s["name"] for s in t["scene"]) == sorted(SAMPLE_SCENES)
    for name, spec in SAMPLE_SCENES.items():
        gt = json.loads((root / "ground_truth" / name / "lighting.json").read_text())
        assert (gt["location"], gt["timestamp_us"]) == (spec.location, spec.timestamp_us)
        assert gt["render"]["width"] == 1600 and gt["render"]["height"] == 900
        assert sorted(gt["cameras"]) == sorted(spec.cameras)
    total = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
    assert total < 10e6
