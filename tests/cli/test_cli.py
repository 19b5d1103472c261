"""The command line end to end: both insert forms, predict-light, and bad input -> clear error + exit code.

Runs in-process through click's runner (fast); one test runs the installed ``streetaug`` executable to
check the real exit code and the one-line error on stderr.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner, Result

from streetaug.augment.core import project_points, read_exr, write_exr
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.cli.main import main
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "nuscenes-real"


def run(*args: str) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def box_corners_cam(box: dict) -> np.ndarray:
    """(8, 3) corners of a label's camera box (yaw about -y, 0 = front along +z)."""
    w, l, h = box["size_wlh"]
    yaw = np.radians(box["yaw_deg"])
    front = np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    right = np.array([np.cos(yaw), 0.0, -np.sin(yaw)])
    down = np.array([0.0, 1.0, 0.0])
    c = np.asarray(box["center"])
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    return c + 0.5 * (signs[:, :1] * l * front + signs[:, 1:2] * w * right + signs[:, 2:] * h * down)


@pytest.fixture(scope="module")
def sunny_insert(tmp_path_factory):
    out = tmp_path_factory.mktemp("sunny")
    result = run("insert", "--scene", "sample-sunny", "--quality", "draft", "--debug", "--explain", "--out", out)
    assert result.exit_code == 0, result.output
    return out


class TestInsertDatasetForm:
    def test_writes_contract_files(self, sunny_insert):
        labels = json.loads((sunny_insert / "labels.json").read_text())
        assert labels["schema"] == "streetaug.labels/1"
        assert labels["image"] == "image.jpg"  # the bundled images are JPEG
        (obj,) = labels["objects"]
        assert obj["category"] == "vehicle.car"
        assert set(obj["box_global"]) == {"translation", "size", "rotation"}
        assert 0.0 < obj["visible_fraction"] <= 1.0
        assert labels["timing_s"]["total"] > 0
        for name in ("image.jpg", "mask.png", "shadow.exr", "placement_bev.png"):
            assert (sunny_insert / name).is_file(), name

    def test_image_mask_and_label_agree(self, sunny_insert):
        reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
        view = reader.sample(reader.sample_tokens("sample-sunny")[0]).cameras["CAM_FRONT"]
        labels = json.loads((sunny_insert / "labels.json").read_text())
        (obj,) = labels["objects"]
        image = cv2.imread(str(sunny_insert / "image.jpg"))
        mask = cv2.imread(str(sunny_insert / "mask.png"), cv2.IMREAD_GRAYSCALE)
        assert image.shape[:2] == mask.shape == (view.height, view.width)
        # The mask's pixels lie inside the projected 3D box, and the 2D box is the mask's extent.
        uv, _ = project_points(view.K, box_corners_cam(obj["box_camera"]))
        x0, y0 = uv.min(axis=0)
        x1, y1 = uv.max(axis=0)
        ys, xs = np.nonzero(mask > 127)
        assert len(xs) > 100
        inside = (xs >= x0 - 1) & (xs <= x1 + 1) & (ys >= y0 - 1) & (ys <= y1 + 1)
        assert inside.mean() > 0.995
        bx0, by0, bx1, by1 = obj["bbox_2d"]
        assert bx0 <= xs.min() and bx1 >= xs.max() and by0 <= ys.min() and by1 >= ys.max()
        # The augmented image differs from the source where the car is, and not far away from it.
        source = view.image[..., ::-1].astype(int)
        diff = np.abs(image.astype(int) - source).max(axis=2)
        assert np.median(diff[mask > 200]) > 10
        far = np.ones_like(mask, bool)
        far[int(max(y0 - 150, 0)):int(y1 + 150), int(max(x0 - 300, 0)):int(x1 + 300)] = False
        # Far from the car only JPEG re-encoding (quality 95) changes pixels.
        assert np.mean(diff[far]) < 1.0 and np.percentile(diff[far], 99) <= 8

    def test_same_seed_same_output(self, sunny_insert, tmp_path):
        result = run("insert", "--scene", "sample-sunny", "--quality", "draft", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        a = json.loads((sunny_insert / "labels.json").read_text())["objects"]
        b = json.loads((tmp_path / "labels.json").read_text())["objects"]
        assert a == b
        assert (sunny_insert / "image.jpg").read_bytes() == (tmp_path / "image.jpg").read_bytes()

    def test_other_seed_other_placement(self, sunny_insert, tmp_path):
        result = run("insert", "--scene", "sample-sunny", "--quality", "draft", "--seed", "7", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        a = json.loads((sunny_insert / "labels.json").read_text())["objects"][0]["box_global"]
        b = json.loads((tmp_path / "labels.json").read_text())["objects"][0]["box_global"]
        assert a["translation"] != b["translation"]

    @pytest.mark.skipif(not REAL.is_dir(), reason=f"real nuScenes excerpt not found at {REAL}")
    def test_real_sample(self, tmp_path):
        result = run("insert", "--scene", "scene-0061", "--dataroot", REAL, "--version", "v1.0-mini",
                     "--camera", "CAM_FRONT", "--quality", "draft", "--no-match-camera", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        labels = json.loads((tmp_path / "labels.json").read_text())
        assert labels["lighting"]["sun_source"] == "ephemeris"
        assert labels["objects"] and labels["objects"][0]["box_global"]["translation"][2] == pytest.approx(0.9, abs=1.5)

        # The camera look (on by default): the same car and labels, blurred and noised like the photo (which has both), and
        # seen through the photo's veil, which also keeps the haze in front of its shadow; so only pixels at the car (its
        # box plus the blur's and the anti-aliasing's reach) and in its shadow (plus a JPEG block) change.
        matched = tmp_path / "matched"
        result = run("insert", "--scene", "scene-0061", "--dataroot", REAL, "--version", "v1.0-mini",
                     "--camera", "CAM_FRONT", "--quality", "draft", "--debug", "--out", matched)
        assert result.exit_code == 0, result.output
        assert json.loads((matched / "labels.json").read_text())["objects"] == labels["objects"]
        changed = np.abs(cv2.imread(str(matched / "image.jpg")).astype(int)
                         - cv2.imread(str(tmp_path / "image.jpg")).astype(int)).max(axis=2) > 0
        assert changed.sum() > 100
        x0, y0, x1, y1 = (int(round(v)) for v in labels["objects"][0]["bbox_2d"])
        allowed = np.zeros(changed.shape, np.uint8)
        allowed[max(y0 - 24, 0):y1 + 25, max(x0 - 24, 0):x1 + 25] = 1
        shadow = read_exr(matched / "shadow.exr")[..., 0] < 0.999
        allowed |= cv2.dilate(shadow.astype(np.uint8), np.ones((17, 17), np.uint8))
        assert not (changed & (allowed == 0)).any(), np.argwhere(changed & (allowed == 0))[:5]


class TestPredictLight:
    def test_sample_scene(self, tmp_path):
        result = run("predict-light", "--scene", "sample-overcast", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        light = json.loads((tmp_path / "lighting.json").read_text())
        assert light["schema"] == "streetaug.lighting/1"
        assert light["sun"]["source"] in ("ephemeris", "image", "none")
        env = read_exr(tmp_path / light["files"]["envmap_camera"])
        assert env.shape[0] >= 128 and env.shape[1] >= 256 and env.shape[2] == 3
        assert np.isfinite(env).all() and env.min() >= 0
        assert light["query_point_camera"][2] == pytest.approx(15.0)

    def test_negative_numbers_in_both_option_forms(self, tmp_path):
        for i, args in enumerate((["--at", "-2,1.5,12"], ["--at=-2,1.5,12"])):
            out = tmp_path / str(i)
            result = run("predict-light", "--scene", "sample-sunny", *args, "--out", out)
            assert result.exit_code == 0, result.output
            assert json.loads((out / "lighting.json").read_text())["query_point_camera"] == [-2.0, 1.5, 12.0]

    def test_single_image(self, tmp_path):
        image = sorted((bundled_dataroot() / "samples" / "CAM_FRONT").glob("*.jpg"))[0]
        result = run("predict-light", "--image", image, "--fov-deg", "64", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        assert json.loads((tmp_path / "lighting.json").read_text())["schema"] == "streetaug.lighting/1"


def _box_asset(path: Path, wlh=(1.8, 4.4, 1.5)) -> Path:
    """A box-shaped OBJ asset in the contract's axes (+Y up, front +Z), bottom at y = 0."""
    w, l, h = wlh
    mesh = trimesh.creation.box(extents=(w, h, l))
    mesh.apply_translation((0.0, h / 2, 0.0))
    mesh.export(path)
    return path


@pytest.fixture(scope="module")
def image_form_inputs(tmp_path_factory):
    """A 320x180 grey image, the ground plane's depth 1.5 m below the camera, a sky + sun env map, a box asset."""
    root = tmp_path_factory.mktemp("imageform")
    W, H, f = 320, 180, 200.0
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    cv2.imwrite(str(root / "in.png"), np.full((H, W, 3), 110, np.uint8))
    depth = ground_plane_depth(K, W, H, np.array([0.0, -1.0, 0.0]), 1.5)
    np.save(root / "depth.npy", depth.astype(np.float32))
    env = np.full((64, 128, 3), 0.4, np.float32)
    env[40:, :] = 0.15  # darker ground below the horizon
    env[12:14, 60:62] = 3000.0  # a small bright sun, up and ahead
    write_exr(root / "env.exr", env)
    return root, K, _box_asset(root / "box.obj")


class TestInsertImageForm:
    def test_pose_and_labels_are_exact(self, image_form_inputs, tmp_path):
        root, K, asset = image_form_inputs
        result = run("insert", "--image", root / "in.png", "--intrinsics", f"{K[0,0]},{K[1,1]},{K[0,2]},{K[1,2]}",
                     "--depth", root / "depth.npy", "--envmap", root / "env.exr", "--asset", asset,
                     "--pose-camera=-1,1.5,12,90", "--quality", "draft", "--debug", "--out", tmp_path)
        assert result.exit_code == 0, result.output
        labels = json.loads((tmp_path / "labels.json").read_text())
        assert labels["image"] == "image.png" and "box_global" not in labels["objects"][0]
        box = labels["objects"][0]["box_camera"]
        np.testing.assert_allclose(box["size_wlh"], [1.8, 4.4, 1.5], atol=1e-6)
        np.testing.assert_allclose(box["center"], [-1.0, 1.5 - 0.75, 12.0], atol=1e-6)
        assert box["yaw_deg"] == pytest.approx(90.0)
        mask = cv2.imread(str(tmp_path / "mask.png"), cv2.IMREAD_GRAYSCALE)
        ys, xs = np.nonzero(mask > 127)
        uv, _ = project_points(K, box_corners_cam(box))
        assert xs.min() >= uv[:, 0].min() - 1 and xs.max() <= uv[:, 0].max() + 1
        assert ys.min() >= uv[:, 1].min() - 1 and ys.max() <= uv[:, 1].max() + 1
        shadow = read_exr(tmp_path / "shadow.exr")
        assert shadow.min() < 0.9  # the box shades the ground somewhere
        assert np.isclose(shadow[0:5, 0:5], 1.0).all()  # the sky corner is untouched

    def test_missing_option_is_a_usage_error(self, image_form_inputs, tmp_path):
        root, _, _ = image_form_inputs
        result = run("insert", "--image", root / "in.png", "--out", tmp_path)
        assert result.exit_code == 2
        assert "--intrinsics" in result.output and "--pose-camera" in result.output


class TestBadInput:
    """Each case: non-zero exit and a message that names what is wrong."""

    def _form(self, root, K, **override):
        args = {"--image": root / "in.png", "--intrinsics": f"{K[0,0]},{K[1,1]},{K[0,2]},{K[1,2]}",
                "--depth": root / "depth.npy", "--envmap": root / "env.exr", "--asset": root / "box.obj",
                "--pose-camera": "0,1.5,12,0"}
        args.update(override)
        return ["insert", *[str(x) for kv in args.items() for x in kv], "--quality", "draft"]

    def test_missing_image_file(self, image_form_inputs, tmp_path):
        root, K, _ = image_form_inputs
        result = run(*self._form(root, K, **{"--image": tmp_path / "nope.png"}), "--out", tmp_path / "o")
        assert result.exit_code == 1 and "nope.png" in result.output and "not found" in result.output

    def test_corrupt_jpeg(self, image_form_inputs, tmp_path):
        root, K, _ = image_form_inputs
        bad = tmp_path / "broken.jpg"
        bad.write_bytes(b"\xff\xd8\xff\xe0" + bytes(200))
        result = run(*self._form(root, K, **{"--image": bad}), "--out", tmp_path / "o")
        assert result.exit_code == 1 and "broken.jpg" in result.output
        assert not (tmp_path / "o" / "labels.json").exists()

    def test_asset_without_faces(self, image_form_inputs, tmp_path):
        root, K, _ = image_form_inputs
        points_only = tmp_path / "points.obj"
        points_only.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
        result = run(*self._form(root, K, **{"--asset": points_only}), "--out", tmp_path / "o")
        assert result.exit_code == 1 and "points" in result.output and "face" in result.output

    def test_depth_of_wrong_size(self, image_form_inputs, tmp_path):
        root, K, _ = image_form_inputs
        np.save(tmp_path / "small.npy", np.ones((10, 10), np.float32))
        result = run(*self._form(root, K, **{"--depth": tmp_path / "small.npy"}), "--out", tmp_path / "o")
        assert result.exit_code == 1 and "depth" in result.output and "(180, 320)" in result.output

    def test_bad_pose_is_a_usage_error(self, image_form_inputs, tmp_path):
        root, K, _ = image_form_inputs
        result = run(*self._form(root, K, **{"--pose-camera": "1,2,x,4"}), "--out", tmp_path / "o")
        assert result.exit_code == 2 and "--pose-camera" in result.output

    def test_unknown_sample_token(self, tmp_path):
        result = run("insert", "--sample", "0123456789abcdef", "--out", tmp_path)
        assert result.exit_code == 1 and "0123456789abcdef" in result.output

    def test_unknown_scene(self, tmp_path):
        result = run("insert", "--scene", "no-such-scene", "--out", tmp_path)
        assert result.exit_code == 1 and "no-such-scene" in result.output

    def test_unknown_camera(self, tmp_path):
        result = run("insert", "--scene", "sample-sunny", "--camera", "CAM_NOPE", "--out", tmp_path)
        assert result.exit_code == 2 and "CAM_NOPE" in result.output and "CAM_FRONT" in result.output

    def test_dataroot_without_version(self, tmp_path):
        result = run("insert", "--scene", "x", "--dataroot", tmp_path, "--out", tmp_path / "o")
        assert result.exit_code == 2 and "--version" in result.output

    def test_dataset_with_a_missing_table(self, tmp_path):
        root = tmp_path / "data"
        shutil.copytree(bundled_dataroot() / BUNDLED_VERSION, root / BUNDLED_VERSION)
        (root / BUNDLED_VERSION / "ego_pose.json").unlink()
        result = run("insert", "--scene", "sample-sunny", "--dataroot", root, "--version", BUNDLED_VERSION,
                     "--out", tmp_path / "o")
        assert result.exit_code == 1 and "ego_pose.json" in result.output

    def test_installed_executable_exit_code_and_one_line_error(self, tmp_path):
        exe = Path(sys.executable).with_name("streetaug")
        if not exe.is_file():
            pytest.skip(f"streetaug executable not installed beside {sys.executable}")
        proc = subprocess.run([str(exe), "predict-light", "--image", str(tmp_path / "missing.jpg"), "--fov-deg", "60",
                               "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 1
        assert proc.stderr.strip().count("\n") == 0 and "missing.jpg" in proc.stderr
