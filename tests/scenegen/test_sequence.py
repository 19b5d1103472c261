"""Tests of the generated sequence scene (augment/scenegen/sequence.py) and the sweeps helper (datasets/sweeps.py).

One small sequence (3 keyframes, CAM_FRONT + CAM_BACK at 96 x 54, 1 spp) with sweeps is generated per module;
the devkit reads it. The committed ``examples/nuscenes-sequence`` (keyframes only) is checked against the
generator without rendering its images.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA, devkit

from streetaug.augment.core import InputError, make_transform, read_image_rgb, transform_points
from streetaug.augment.scenegen.lidar import T_ego_from_lidar, points_in_box, simulate_lidar
from streetaug.augment.scenegen.make import CAMERA_RIGS
from streetaug.augment.scenegen.sequence import (
    CAMERA_FRAMES_PER_KEYFRAME,
    KEYFRAME_PERIOD_US,
    LIDAR_FRAMES_PER_KEYFRAME,
    SEQUENCE_SCENE,
    SEQUENCE_VERSION,
    SequenceWorld,
    make_sequence_scene,
)
from streetaug.datasets import DatasetError, NuScenesReader
from streetaug.datasets.bundled import BUNDLED_SEQUENCE_VERSION, bundled_sequence_dataroot
from streetaug.datasets.sweeps import (
    interpolation_of,
    keyframe_of_sample,
    missing_sweep_files,
    sweeps_by_links,
    sweeps_of_sample,
    sweeps_unavailable_reason,
)

N_KEY = 3
CAMS = ("CAM_FRONT", "CAM_BACK")
SMALL = dict(width=96, height=54, seed=0, spp=1, sky_rays=1, n_keyframes=N_KEY, cameras=CAMS)
CHANNELS = CAMS + ("LIDAR_TOP",)
FRAMES_PER_KEY = {"CAM_FRONT": CAMERA_FRAMES_PER_KEYFRAME, "CAM_BACK": CAMERA_FRAMES_PER_KEYFRAME,
                  "LIDAR_TOP": LIDAR_FRAMES_PER_KEYFRAME}


@pytest.fixture(scope="module")
def seq_root(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sequence")
    make_sequence_scene(out, sweeps=True, **SMALL)
    return out


@pytest.fixture(scope="module")
def keyframes_root(tmp_path_factory) -> Path:
    """The same sequence without the sweep files."""
    out = tmp_path_factory.mktemp("sequence_keyframes")
    make_sequence_scene(out, sweeps=False, **SMALL)
    return out


@pytest.fixture(scope="module")
def nusc(seq_root: Path):
    return devkit().NuScenes(version=SEQUENCE_VERSION, dataroot=str(seq_root), verbose=False)


@pytest.fixture(scope="module")
def world() -> SequenceWorld:
    return SequenceWorld.build(SEQUENCE_SCENE, seed=0)


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def _channel(nusc, sd: dict) -> str:
    return nusc.get("sensor", nusc.get("calibrated_sensor", sd["calibrated_sensor_token"])["sensor_token"])["channel"]


def _left_of(direction_xy: np.ndarray, offset_xy: np.ndarray) -> float:
    """z of direction x offset: > 0 when ``offset_xy`` lies to the left of ``direction_xy``."""
    return float(direction_xy[0] * offset_xy[1] - direction_xy[1] * offset_xy[0])


# ----------------------------------------------------------------------------- the scene in the devkit


def test_devkit_loads_the_scene_with_linked_samples(nusc) -> None:
    assert len(nusc.scene) == 1
    scene = nusc.scene[0]
    assert scene["name"] == SEQUENCE_SCENE.name and scene["nbr_samples"] == N_KEY
    samples = []
    token = scene["first_sample_token"]
    while token:
        samples.append(nusc.get("sample", token))
        token = samples[-1]["next"]
    assert len(samples) == N_KEY and samples[-1]["token"] == scene["last_sample_token"]
    assert samples[0]["prev"] == ""
    t = np.array([s["timestamp"] for s in samples])
    assert np.all(np.diff(t) == KEYFRAME_PERIOD_US), f"sample timestamps {t.tolist()}: expected 0.5 s apart"
    for s in samples:
        assert set(s["data"]) == set(CHANNELS), f"sample {s['token']}: keyframes {sorted(s['data'])}"
        lidar = nusc.get("sample_data", s["data"]["LIDAR_TOP"])
        assert lidar["timestamp"] == s["timestamp"], "the sample's time is its LIDAR_TOP keyframe's"
        for cam in CAMS:
            sd = nusc.get("sample_data", s["data"][cam])
            assert sd["timestamp"] - s["timestamp"] == CAMERA_RIGS[cam].time_offset_us, f"{cam} capture offset"
            assert sd["filename"].startswith(f"samples/{cam}/") and sd["is_key_frame"]


def test_ego_drives_along_its_left_lane(nusc, world: SequenceWorld) -> None:
    lidar = [sd for sd in nusc.sample_data if _channel(nusc, sd) == "LIDAR_TOP"]
    lidar.sort(key=lambda r: r["timestamp"])
    xy = np.array([nusc.get("ego_pose", sd["ego_pose_token"])["translation"][:2] for sd in lidar])
    t_s = np.array([sd["timestamp"] for sd in lidar]) * 1e-6
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.diff(t_s)
    np.testing.assert_allclose(speed, SEQUENCE_SCENE.ego_speed_mps, atol=0.05,
                               err_msg="ego speed between consecutive LiDAR frames (m/s)")
    heading = np.array([np.cos(np.radians(SEQUENCE_SCENE.scene.heading_deg)),
                        np.sin(np.radians(SEQUENCE_SCENE.scene.heading_deg))])
    np.testing.assert_allclose((xy[-1] - xy[0]) / np.linalg.norm(xy[-1] - xy[0]), heading, atol=1e-6)
    centre = np.array(SEQUENCE_SCENE.scene.origin_xy)
    assert _left_of(heading, xy[0] - centre) > 0, "Singapore: the ego drives left of the centre line"


def test_box_velocity_of_the_annotated_vehicles_is_their_true_velocity(nusc, world: SequenceWorld) -> None:
    moving_attr = next(a["token"] for a in nusc.attribute if a["name"] == "vehicle.moving")
    parked_attr = next(a["token"] for a in nusc.attribute if a["name"] == "vehicle.parked")
    n_moving = n_parked = 0
    centre = np.array(SEQUENCE_SCENE.scene.origin_xy)
    for i, v_true in enumerate(world.velocities_global):
        inst_tok = devkit_instance_token(i)
        inst = next((r for r in nusc.instance if r["token"] == inst_tok), None)
        if inst is None or inst["nbr_annotations"] < 2:
            continue
        first = nusc.get("sample_annotation", inst["first_annotation_token"])
        v = nusc.box_velocity(first["token"])
        np.testing.assert_allclose(v[:2], v_true[:2], atol=0.01, err_msg=f"instance {inst_tok}: box_velocity (m/s)")
        if moving_attr in first["attribute_tokens"]:
            n_moving += 1
            assert np.linalg.norm(v_true) > 1.0
            assert _left_of(v_true[:2] / np.linalg.norm(v_true[:2]), np.array(first["translation"][:2]) - centre) > 0, \
                f"instance {inst_tok} drives right of the centre line (Singapore: left-hand traffic)"
        elif parked_attr in first["attribute_tokens"]:
            n_parked += 1
            assert np.all(v_true == 0)
    assert n_moving >= 2 and n_parked >= 3, f"tracked: {n_moving} moving, {n_parked} parked vehicles"


def devkit_instance_token(index: int) -> str:
    from streetaug.datasets.nuscenes_format import content_token

    return content_token("instance", SEQUENCE_SCENE.name, index)


def test_instances_are_contiguous_linked_tracks(nusc) -> None:
    sample_index = {s["token"]: k for k, s in enumerate(sorted(nusc.sample, key=lambda s: s["timestamp"]))}
    for inst in nusc.instance:
        chain = []
        token = inst["first_annotation_token"]
        while token:
            chain.append(nusc.get("sample_annotation", token))
            token = chain[-1]["next"]
        assert len(chain) == inst["nbr_annotations"] and chain[-1]["token"] == inst["last_annotation_token"]
        ks = [sample_index[a["sample_token"]] for a in chain]
        assert ks == list(range(ks[0], ks[0] + len(ks))), f"instance {inst['token']}: samples {ks} not contiguous"
        assert all(a["instance_token"] == inst["token"] for a in chain)
        assert chain[0]["prev"] == ""


def test_map_expansion_has_road_and_lanes(seq_root: Path) -> None:
    m = json.loads((seq_root / "maps" / "expansion" / "singapore-onenorth.json").read_text())
    assert len(m["drivable_area"]) == 1 and len(m["lane"]) == 4
    reader = NuScenesReader(seq_root, SEQUENCE_VERSION)
    sample = reader.sample(reader.sample_tokens()[0])
    assert sample.lanes is not None and sample.drivable_area_global


# ----------------------------------------------------------------------------- sweeps


def test_sweeps_chain_from_keyframe_to_keyframe(nusc, seq_root: Path) -> None:
    samples = sorted(nusc.sample, key=lambda s: s["timestamp"])
    for channel in CHANNELS:
        per = FRAMES_PER_KEY[channel]
        sd = nusc.get("sample_data", samples[0]["data"][channel])
        assert sd["prev"] == "", f"{channel}: the scene starts with its keyframe"
        frames = [sd]
        while frames[-1]["next"]:
            frames.append(nusc.get("sample_data", frames[-1]["next"]))
        assert len(frames) == (N_KEY - 1) * per + 1, f"{channel}: {len(frames)} frames"
        assert [f["token"] for f in frames if f["is_key_frame"]] == [s["data"][channel] for s in samples]
        assert all(f["is_key_frame"] == (j % per == 0) for j, f in enumerate(frames))
        dt_us = np.diff([f["timestamp"] for f in frames])
        np.testing.assert_allclose(dt_us, KEYFRAME_PERIOD_US / per, atol=1, err_msg=f"{channel} frame spacing (us)")
        for j, f in enumerate(frames):
            assert _channel(nusc, f) == channel
            assert f["prev"] == (frames[j - 1]["token"] if j else "")
            if not f["is_key_frame"]:
                assert f["filename"].startswith(f"sweeps/{channel}/"), f["filename"]
                # devkit convention (NuScenes.get_boxes): a sweep belongs to the sample of the NEXT keyframe
                assert f["sample_token"] == samples[-(-j // per)]["token"], f"{channel} frame {j}: sample_token"
            assert (seq_root / f["filename"]).is_file(), f["filename"]


def test_devkit_interpolated_sweep_boxes_are_the_true_boxes(nusc, world: SequenceWorld) -> None:
    samples = sorted(nusc.sample, key=lambda s: s["timestamp"])
    sweep = nusc.get("sample_data", nusc.get("sample_data", samples[1]["data"]["LIDAR_TOP"])["prev"])
    assert not sweep["is_key_frame"]
    true_boxes = world.boxes_at(sweep["timestamp"])
    token_to_index = {devkit_instance_token(i): i for i in range(len(true_boxes))}
    n_checked = 0
    for box in nusc.get_boxes(sweep["token"]):
        i = token_to_index[nusc.get("sample_annotation", box.token)["instance_token"]]
        np.testing.assert_allclose(box.center, true_boxes[i].center, atol=2e-3,
                                   err_msg=f"object {i}: devkit-interpolated centre at the sweep's time")
        n_checked += int(world.velocities_global[i].any())
    assert n_checked >= 2, "the moving vehicles are among the interpolated boxes"


def test_lidar_sweeps_see_the_street_at_their_own_time(seq_root: Path, world: SequenceWorld) -> None:
    reader = NuScenesReader(seq_root, SEQUENCE_VERSION)
    tokens = reader.sample_tokens()
    last = sweeps_of_sample(reader, tokens[-1], "LIDAR_TOP")[-1]  # 0.95 s after the first keyframe
    mid = reader.lidar_sweep(last["token"])
    assert mid.labels is None, "no lidarseg for sweeps (as nuScenes)"
    assert mid.points_sensor.shape == (32000, 3)
    np.testing.assert_allclose(mid.T_global_from_ego, world.T_global_from_ego(mid.timestamp_us), atol=1e-5)
    key_prev = reader.lidar_sweep(keyframe_of_sample(reader, tokens[0], "LIDAR_TOP")["token"])

    def range_error(t_us: int) -> float:
        """Fraction of beams whose range differs by > 0.1 m between the stored sweep and the street simulated
        (other noise seed) at time ``t_us``."""
        sim = simulate_lidar(world.scene_at(t_us), world.T_global_from_ego(t_us) @ T_ego_from_lidar(), seed=1)
        diff = np.abs(np.linalg.norm(sim.points_sensor, axis=1) - np.linalg.norm(mid.points_sensor, axis=1))
        return float(np.mean(diff > 0.1))

    right, wrong = range_error(mid.timestamp_us), range_error(key_prev.timestamp_us)
    assert right < 0.02 and wrong > 10 * right, \
        f"beams off by > 0.1 m: {right:.4f} at the sweep's time, {wrong:.4f} at the first keyframe's"
    boxes_now, boxes_then = world.boxes_at(mid.timestamp_us), world.boxes_at(key_prev.timestamp_us)
    p_global = transform_points(mid.T_global_from_lidar, mid.points_sensor)
    p_global = p_global[p_global[:, 2] > 0.3]  # not the road
    moving = [i for i, v in enumerate(world.velocities_global) if v.any()]
    n_now = sum(int(points_in_box(boxes_now[i], p_global, 0.05).sum()) for i in moving)
    n_then = sum(int(points_in_box(boxes_then[i], p_global, 0.05).sum()) for i in moving)
    assert n_now > 10 and n_now > 3 * n_then, f"moving cars where they are at the sweep's time: {n_now} vs {n_then}"


def test_camera_sweeps_read_as_camera_views(seq_root: Path, world: SequenceWorld) -> None:
    reader = NuScenesReader(seq_root, SEQUENCE_VERSION)
    token = reader.sample_tokens()[2]
    sweeps = sweeps_of_sample(reader, token, "CAM_FRONT")
    assert len(sweeps) == CAMERA_FRAMES_PER_KEYFRAME - 1
    key = reader.camera_view(keyframe_of_sample(reader, token, "CAM_FRONT")["token"])
    images = []
    for sd in sweeps:
        view = reader.camera_view(sd["token"])
        assert view.channel == "CAM_FRONT" and view.timestamp_us == sd["timestamp"]
        np.testing.assert_allclose(view.T_global_from_ego, world.T_global_from_ego(sd["timestamp"]), atol=1e-5)
        np.testing.assert_allclose(view.K, key.K)
        images.append(view.image)
        assert images[-1].shape == (SMALL["height"], SMALL["width"], 3)
    assert np.abs(images[0].astype(int) - key.image.astype(int)).mean() > 1.0, "the sweep sees the street moved"


# ----------------------------------------------------------------------------- determinism, keyframes-only


def test_regeneration_is_byte_identical(seq_root: Path, tmp_path: Path) -> None:
    make_sequence_scene(tmp_path, sweeps=True, **SMALL)
    files = _files(seq_root)
    assert files == _files(tmp_path)
    different = [f for f in files if (seq_root / f).read_bytes() != (tmp_path / f).read_bytes()]
    assert not different, f"regeneration changed {different[:5]}"


def test_without_sweeps_the_same_files_less_the_sweeps(seq_root: Path, keyframes_root: Path) -> None:
    with_sweeps = _files(seq_root)
    keyframes = _files(keyframes_root)
    assert keyframes == [f for f in with_sweeps if not f.startswith("sweeps/")]
    assert any(f.startswith("sweeps/") for f in with_sweeps)
    different = [f for f in keyframes if (seq_root / f).read_bytes() != (keyframes_root / f).read_bytes()]
    assert not different, f"--sweeps changed {different[:5]}"


# ----------------------------------------------------------------------------- datasets/sweeps.py


def test_sweeps_of_sample_match_the_links(seq_root: Path) -> None:
    reader = NuScenesReader(seq_root, SEQUENCE_VERSION)
    tokens = reader.sample_tokens()
    for channel in CHANNELS:
        assert sweeps_of_sample(reader, tokens[0], channel) == [], "the first sample has no sweeps"
        assert sweeps_by_links(reader, tokens[0], channel) == []
        for token in tokens[1:]:
            rows = sweeps_of_sample(reader, token, channel)
            assert len(rows) == FRAMES_PER_KEY[channel] - 1
            assert [r["token"] for r in rows] == [r["token"] for r in sweeps_by_links(reader, token, channel)]
            t = [r["timestamp"] for r in rows]
            assert t == sorted(t) and not any(r["is_key_frame"] for r in rows)
            assert t[-1] < keyframe_of_sample(reader, token, channel)["timestamp"]
    assert sweeps_unavailable_reason(reader, tokens, CHANNELS) is None
    assert missing_sweep_files(reader, sweeps_of_sample(reader, tokens[1], "CAM_FRONT")) == []
    with pytest.raises(DatasetError, match="no sample with token"):
        sweeps_of_sample(reader, "not-a-sample", "CAM_FRONT")


def test_interpolation_of_a_sweep_gives_the_true_boxes(seq_root: Path, world: SequenceWorld) -> None:
    reader = NuScenesReader(seq_root, SEQUENCE_VERSION)
    tokens = reader.sample_tokens()
    boxes_by_sample = {t: world.boxes_at(reader.get("sample", t)["timestamp"]) for t in tokens}
    for sd in sweeps_of_sample(reader, tokens[2], "CAM_BACK"):
        before, after, fraction = interpolation_of(reader, sd)
        assert (before, after) == (tokens[1], tokens[2]) and 0 < fraction < 1
        truth = world.boxes_at(sd["timestamp"])
        for b0, b1, bt in zip(boxes_by_sample[before], boxes_by_sample[after], truth):
            np.testing.assert_allclose(b0.center + fraction * (b1.center - b0.center), bt.center, atol=1e-6)
    key = keyframe_of_sample(reader, tokens[1], "CAM_BACK")
    assert interpolation_of(reader, key) == (tokens[1], tokens[1], 1.0)


def test_absent_sweep_files_give_one_reason(keyframes_root: Path) -> None:
    reader = NuScenesReader(keyframes_root, SEQUENCE_VERSION)
    tokens = reader.sample_tokens()
    rows = sweeps_of_sample(reader, tokens[1], "LIDAR_TOP")
    assert len(rows) == LIDAR_FRAMES_PER_KEYFRAME - 1
    assert missing_sweep_files(reader, rows) == [keyframes_root / r["filename"] for r in rows]
    reason = sweeps_unavailable_reason(reader, tokens, CHANNELS)
    n = (N_KEY - 1) * (2 * (CAMERA_FRAMES_PER_KEYFRAME - 1) + LIDAR_FRAMES_PER_KEYFRAME - 1)
    assert reason is not None and "\n" not in reason
    assert f"{n} of {n} sweep files are absent" in reason and "make-samples --sequence --sweeps" in reason
    assert "LIDAR_TOP 18/18" in reason
    # the keyframes stay usable
    sample = reader.sample(tokens[1])
    assert sample.cameras["CAM_FRONT"].image.shape == (SMALL["height"], SMALL["width"], 3)


def test_dataset_listing_no_sweeps_gives_one_reason(keyframes_root: Path, tmp_path: Path) -> None:
    root = tmp_path / "keyframes_only"
    shutil.copytree(keyframes_root, root)
    sd_path = root / SEQUENCE_VERSION / "sample_data.json"
    rows = [r for r in json.loads(sd_path.read_text()) if r["is_key_frame"]]
    by_token = {r["token"]: r for r in rows}
    for r in rows:  # relink keyframe to keyframe, as a dataset without sweeps would
        r["prev"] = r["prev"] if r["prev"] in by_token else ""
        r["next"] = r["next"] if r["next"] in by_token else ""
    sd_path.write_text(json.dumps(rows))
    reader = NuScenesReader(root, SEQUENCE_VERSION)
    reason = sweeps_unavailable_reason(reader, reader.sample_tokens(), ["CAM_FRONT"])
    assert reason is not None and "lists no sweeps of CAM_FRONT" in reason and f"for {N_KEY - 1} sample" in reason


def test_broken_links_are_reported(keyframes_root: Path, tmp_path: Path) -> None:
    root = tmp_path / "broken"
    shutil.copytree(keyframes_root, root)
    sd_path = root / SEQUENCE_VERSION / "sample_data.json"
    rows = json.loads(sd_path.read_text())
    reader = NuScenesReader(keyframes_root, SEQUENCE_VERSION)
    token = reader.sample_tokens()[1]
    key_front = keyframe_of_sample(reader, token, "CAM_FRONT")["token"]
    key_lidar = keyframe_of_sample(reader, token, "LIDAR_TOP")["token"]
    lidar_sweep = next(r for r in rows if r["token"] == key_lidar)["prev"]
    for r in rows:
        if r["token"] == key_front:
            r["prev"] = lidar_sweep
    sd_path.write_text(json.dumps(rows))
    with pytest.raises(DatasetError, match="but is a LIDAR_TOP frame"):
        sweeps_by_links(NuScenesReader(root, SEQUENCE_VERSION), token, "CAM_FRONT")


@pytest.mark.skipif(not (SHARED_DATA / "nuscenes-seq" / "v1.0-mini").is_dir(),
                    reason=f"{SHARED_DATA / 'nuscenes-seq'} (real scene without sweeps) not present")
def test_real_scene_without_sweeps_gives_one_reason() -> None:
    root = SHARED_DATA / "nuscenes-seq"
    reader = NuScenesReader(root, "v1.0-mini", with_map=False)
    tokens = reader.sample_tokens()
    assert sweeps_of_sample(reader, tokens[1], "CAM_FRONT") == []
    reason = sweeps_unavailable_reason(reader, tokens[:5], ["CAM_FRONT", "LIDAR_TOP"])
    assert reason is not None and "lists no sweeps" in reason


# ----------------------------------------------------------------------------- the committed sequence


LIDAR_POINT_TOLERANCE_M = 1e-5  # float32 rounding of ray casts differs between numpy / Embree builds (seen: 7.6e-6 m)


def _same_generated_file(committed: Path, regenerated: Path) -> bool:
    """Byte-identical, or for a LiDAR sweep (``.pcd.bin``, float32 x y z intensity ring): the same points within
    ``LIDAR_POINT_TOLERANCE_M`` and the same intensities and rings (another machine's libraries may round the
    ray casts' last bit differently; the committed files must still be what the generator makes)."""
    a, b = committed.read_bytes(), regenerated.read_bytes()
    if a == b:
        return True
    if not committed.name.endswith(".pcd.bin") or len(a) != len(b) or len(a) % 20:
        return False
    pa, pb = np.frombuffer(a, np.float32).reshape(-1, 5), np.frombuffer(b, np.float32).reshape(-1, 5)
    same_rest = np.array_equal(pa[:, 3:], pb[:, 3:])
    return bool(same_rest and np.max(np.abs(pa[:, :3] - pb[:, :3])) <= LIDAR_POINT_TOLERANCE_M)


def test_a_regenerated_sweep_may_differ_only_by_rounding(tmp_path: Path) -> None:
    points = np.random.default_rng(0).normal(size=(50, 5)).astype(np.float32)
    committed = tmp_path / "a.pcd.bin"
    points.tofile(committed)
    for change, same in (((0, 1, 4e-6), True), ((0, 1, 1e-3), False), ((3, 4, 1.0), False)):
        row, column, delta = change
        other = points.copy()
        other[row, column] += np.float32(delta)
        other.tofile(tmp_path / "b.pcd.bin")
        assert _same_generated_file(committed, tmp_path / "b.pcd.bin") is same, change
    (tmp_path / "c.json").write_bytes(b"[1]")
    (tmp_path / "d.json").write_bytes(b"[2]")
    assert not _same_generated_file(tmp_path / "c.json", tmp_path / "d.json")


def test_committed_sequence_matches_the_generator(tmp_path: Path) -> None:
    try:
        root = bundled_sequence_dataroot()
    except InputError as e:
        pytest.fail(f"the committed sequence scene is missing: {e}")
    readme = (root / "README.md").read_text()
    assert f"version='{BUNDLED_SEQUENCE_VERSION}'" in readme
    make_sequence_scene(tmp_path, render_images=False)  # tables, LiDAR, lidarseg, map, README: no rendering
    regenerated = _files(tmp_path)
    different = [f for f in regenerated if not _same_generated_file(root / f, tmp_path / f)]
    assert not different, (f"examples/nuscenes-sequence differs from the generator in {different[:5]}; "
                           "regenerate with `streetaug make-samples --sequence --out examples/nuscenes-sequence`")
    committed = [f for f in _files(root) if not f.startswith("sweeps/")]  # sweeps/ is git-ignored
    images = [f for f in committed if f.endswith(".jpg")]
    assert len(images) == SEQUENCE_SCENE.n_keyframes * len(SEQUENCE_SCENE.scene.cameras)
    assert all(f.startswith("samples/") for f in images)
    assert (root / ".gitignore").read_text().split() == ["sweeps/"], "generated sweeps stay out of git"
    size = sum((root / f).stat().st_size for f in committed)
    assert size < 6e6, f"the committed sequence is {size / 1e6:.1f} MB (budget: 6 MB)"
    reader = NuScenesReader(root, BUNDLED_SEQUENCE_VERSION)
    tokens = reader.sample_tokens()
    reason = sweeps_unavailable_reason(reader, tokens, ["CAM_FRONT", "LIDAR_TOP"])
    assert reason is None or "sweep files are absent" in reason
    view = reader.camera_view(keyframe_of_sample(reader, tokens[-1], "CAM_FRONT")["token"])
    assert view.image.shape == (450, 800, 3)
    assert read_image_rgb(root / images[0]).dtype == np.uint8


def test_cli_refuses_sweeps_without_sequence(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from streetaug.cli.main import main

    result = CliRunner().invoke(main, ["make-samples", "--sweeps", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--sweeps needs --sequence" in result.output


def test_world_poses_are_rigid(world: SequenceWorld) -> None:
    T0 = world.T_global_from_ego(world.t0_us)
    T1 = world.T_global_from_ego(world.t0_us + 1_000_000)
    np.testing.assert_allclose(T0[:3, :3], T1[:3, :3])
    np.testing.assert_allclose(T1[:3, 3] - T0[:3, 3], world.ego_velocity_global, atol=1e-9)
    scene = world.scene_at(world.t0_us + 500_000)
    i = next(i for i, v in enumerate(world.velocities_global) if v.any())
    shift = scene.vertices_global - world.base.vertices_global
    moved = np.linalg.norm(shift, axis=1) > 0
    assert set(np.unique(scene.face_object[np.isin(scene.faces, np.flatnonzero(moved)).any(axis=1)])) <= \
        {j for j, v in enumerate(world.velocities_global) if v.any()}, "only moving objects' vertices move"
    np.testing.assert_allclose(scene.objects[i].center - world.base.objects[i].center,
                               world.velocities_global[i] * 0.5, atol=1e-9)
    np.testing.assert_allclose(make_transform(scene.objects[i].rotation, [0, 0, 0]),
                               make_transform(world.base.objects[i].rotation, [0, 0, 0]))
