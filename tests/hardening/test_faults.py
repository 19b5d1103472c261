"""Fault injection: corrupt and malicious inputs built from the bundled scenes (``tests/fault_cases.py``).

Each test asserts the whole outcome: the exit code, that the message names the culprit (file, row, field),
that nothing was written outside ``--out`` or into a source, and that the rest of the work still happened.
Exit codes (``streetaug --help``): 0 success, 1 bad input or runtime error, 2 bad arguments, 3 batch finished
but some items failed (counted in ``summary.json``).
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

import fault_cases as fc
from streetaug.cli.main import main

EXIT_SOME_FAILED = 3


def run(case: fc.FaultCase) -> Result:
    return CliRunner().invoke(main, case.argv, catch_exceptions=False)


def tree(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha1(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def log_rows(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "augment_log.jsonl").read_text().splitlines() if line.strip()]


def counts(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())["counts"]


class TestPaths:
    def test_same_basenames_in_different_folders_get_different_outputs(self, tmp_path):
        case = fc.case_basename_collision(tmp_path)
        result = run(case)
        assert result.exit_code == 0, result.output
        outputs = sorted(str(p.relative_to(case.out)) for p in (case.out / "samples" / "CAM_FRONT").rglob("*.jpg"))
        # sorted, the third (untouched) image "n900-..." comes before "sub0/": compare as a set
        assert len(outputs) == 3 and {"samples/CAM_FRONT/sub0/same.jpg", "samples/CAM_FRONT/sub1/same.jpg"} <= set(
            outputs), outputs
        table = json.loads((case.out / fc.VERSION / "sample_data.json").read_text())
        names = [r["filename"] for r in table if "/CAM_FRONT/" in r["filename"]]
        assert len(names) == len(set(names)) == 3

    def test_a_table_path_out_of_the_dataroot_fails_that_item_only(self, tmp_path):
        case = fc.case_filename_escapes_batch(tmp_path)
        private_before = case.watch["private"].read_bytes()
        result = run(case)
        assert result.exit_code == EXIT_SOME_FAILED, result.output
        assert counts(case.out) == {"ok": 2, "failed": 1}
        (failed,) = [r for r in log_rows(case.out) if r["status"] == "failed"]
        assert "sample_data.json" in failed["reason"] and "'filename'" in failed["reason"]
        assert "outside" in failed["reason"]
        assert case.watch["private"].read_bytes() == private_before
        assert len(list((case.out / "samples").rglob("*.jpg"))) == 2

    def test_insert_refuses_an_absolute_table_path(self, tmp_path):
        case = fc.case_filename_absolute_insert(tmp_path)
        result = run(case)
        assert result.exit_code == 1
        assert "sample_data.json" in result.output and "/etc/passwd" in result.output
        assert "absolute path" in result.output
        assert not case.out.exists()

    @pytest.mark.parametrize("sub", [".", fc.VERSION, "samples/CAM_FRONT"])
    def test_insert_never_writes_into_the_source(self, tmp_path, sub):
        case = fc.case_insert_out_is_source(tmp_path, sub)
        before = tree(case.watch["source"])
        result = run(case)
        assert result.exit_code == 1
        assert "inside the source dataset" in result.output
        assert tree(case.watch["source"]) == before


class TestResourceLimits:
    def test_a_texture_bomb_is_refused_before_decoding(self, tmp_path):
        case = fc.case_texture_bomb(tmp_path, 13000)
        t0 = time.perf_counter()
        result = run(case)
        assert result.exit_code == 1
        assert "paint.png" in result.output and "13000 x 13000" in result.output
        assert time.perf_counter() - t0 < 30

    def test_a_large_texture_is_downscaled_and_rendered(self, tmp_path):
        case = fc.case_texture_bomb(tmp_path, 9000, real=True)
        result = run(case)
        assert result.exit_code == 0, result.output
        labels = json.loads((case.out / "labels.json").read_text())
        assert labels["objects"], "nothing inserted"

    def test_an_oversized_input_image_is_refused(self, tmp_path):
        case = fc.case_huge_image(tmp_path, 20000)
        result = run(case)
        assert result.exit_code == 1
        assert "big.png" in result.output and "20000 x 20000" in result.output and "limit" in result.output


class TestExitCodes:
    def test_all_items_failed_is_not_success(self, tmp_path):
        case = fc.case_all_images_corrupt(tmp_path)
        result = run(case)
        assert result.exit_code == EXIT_SOME_FAILED
        assert counts(case.out) == {"failed": 3}
        assert "3 of 3" in result.output

    def test_a_corrupt_camera_fails_only_itself(self, tmp_path):
        case = fc.case_one_camera_corrupt(tmp_path)
        result = run(case)
        assert result.exit_code == EXIT_SOME_FAILED, result.output
        rows = log_rows(case.out)
        status = {r["camera"]: r["status"] for r in rows}
        # CAM_FRONT_LEFT of this sample has no valid placement of its own (drivable area) and sees no other
        # camera's car: "skipped" (done, image unchanged) is its correct outcome, as in a clean run.
        assert status == {"CAM_FRONT": "ok", "CAM_FRONT_LEFT": "skipped", "CAM_BACK": "failed"}, rows
        (failed,) = [r for r in rows if r["status"] == "failed"]
        assert "CAM_BACK" in failed["reason"] and "cannot decode" in failed["reason"]
        # the readable cameras got exactly what a run without CAM_BACK gives them
        clean = tmp_path / "clean"
        argv = [a if a != str(case.out) else str(clean) for a in case.argv]
        argv[argv.index("--cameras") + 1] = "CAM_FRONT,CAM_FRONT_LEFT"
        assert CliRunner().invoke(main, argv, catch_exceptions=False).exit_code == 0
        assert tree(case.out / "samples") == tree(clean / "samples")

    def test_a_broken_asset_in_the_folder_is_named_up_front(self, tmp_path):
        case = fc.case_broken_asset_in_folder(tmp_path)
        result = run(case)
        assert result.exit_code == 1
        assert "broken.glb" in result.output
        assert not (case.out / "augment_log.jsonl").exists()

    @pytest.mark.parametrize("args, option", [(["--ev", "nan"], "--ev"), (["--ev", "1e308"], "--ev"),
                                               (["--yaw-sigma", "nan"], "--yaw-sigma"),
                                               (["--asset-length", "-1"], "--asset-length")])
    def test_non_finite_or_absurd_numbers_are_usage_errors(self, tmp_path, args, option):
        result = run(fc.case_option(tmp_path, option, args))
        assert result.exit_code == 2
        assert option in result.output

    def test_an_infinite_pose_is_a_usage_error(self, tmp_path):
        result = CliRunner().invoke(main, ["insert", "--image", "x.png", "--intrinsics", "1,1,1,1", "--depth", "d.npy",
                                           "--envmap", "e.exr", "--asset", "a.glb", "--pose-camera", "0,1.5,1e308,0",
                                           "--out", str(tmp_path / "o")])
        assert result.exit_code == 2
        assert "--pose-camera" in result.output

    def test_duplicate_cameras_collapse(self, tmp_path):
        case = fc.case_duplicate_cameras(tmp_path)
        result = run(case)
        assert result.exit_code == 0, result.output
        rows = log_rows(case.out)
        assert [r["camera"] for r in rows] == ["CAM_FRONT"]
        annotations = json.loads((case.out / fc.VERSION / "sample_annotation.json").read_text())
        source = json.loads((fc.BUNDLED / fc.VERSION / "sample_annotation.json").read_text())
        assert len(annotations) - len(source) <= 1


class TestMessagesNameTheCulprit:
    def test_nan_in_lidar(self, tmp_path):
        case = fc.case_lidar_nan(tmp_path)
        result = run(case)
        assert result.exit_code == EXIT_SOME_FAILED
        reasons = {r["reason"] for r in log_rows(case.out) if r["status"] == "failed"}
        assert len(reasons) == 1 and ".pcd.bin" in next(iter(reasons)) and "non-finite" in next(iter(reasons))

    @pytest.mark.parametrize("name, expect", [
        ("annotation zero quaternion", ("sample_annotation.json", "'rotation'")),
        ("annotation NaN size", ("sample_annotation.json", "'size'")),
        ("non-numeric timestamp", ("sample_data.json", "'timestamp'", "yesterday")),
        ("image size differs from table", ("sample_data.json", "800 x 450", "1600 x 900")),
    ])
    def test_bad_rows_fail_their_items_with_the_table_row_and_field(self, tmp_path, name, expect):
        table, edit = fc.table_cases()[name]
        case = fc.case_table_field(tmp_path, name, table, edit)
        result = run(case)
        assert result.exit_code == EXIT_SOME_FAILED, result.output
        reasons = [r["reason"] for r in log_rows(case.out) if r["status"] == "failed"]
        assert reasons and all(all(e in reason for e in expect) for reason in reasons), reasons
        assert counts(case.out).get("ok", 0) >= 1

    def test_duplicated_tokens_are_refused_when_tables_are_read(self, tmp_path):
        table, edit = fc.table_cases()["duplicated token"]
        result = run(fc.case_table_field(tmp_path, "duplicated token", table, edit))
        assert result.exit_code == 1
        assert "sample_annotation.json" in result.output and "appears" in result.output

    @pytest.mark.parametrize("uri, expect", [("data:application/octet-stream;base64,@@@@", "base64"),
                                             ("data:application/octet-stream,abc", "base64")])
    def test_bad_data_uris(self, tmp_path, uri, expect):
        result = run(fc.case_data_uri(tmp_path, "x", uri))
        assert result.exit_code == 1
        assert "car.gltf" in result.output and "buffers[0]" in result.output and expect in result.output

    def test_a_too_deep_map_json(self, tmp_path):
        case = fc.case_deep_map(tmp_path)
        result = run(case)
        reasons = {r["reason"] for r in log_rows(case.out) if r["status"] == "failed"} if (
            case.out / "augment_log.jsonl").exists() else {result.output}
        assert result.exit_code in (1, EXIT_SOME_FAILED)
        assert all("nested too deeply" in r and ".json" in r for r in reasons), reasons


class TestOneRunPerOutput:
    def test_a_second_concurrent_batch_refuses(self, tmp_path):
        case = fc.case_concurrent_batches(tmp_path)
        cmd = [sys.executable, "-m", "streetaug.cli", *case.argv]
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)]
        deadline = time.time() + 60
        while not (case.out / ".streetaug.lock").exists():
            assert time.time() < deadline and procs[0].poll() is None, "the first run never took the lock"
            time.sleep(0.05)
        second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        first_out, first_err = procs[0].communicate(timeout=300)
        assert procs[0].returncode == 0, first_err
        assert second.returncode == 1 and "another streetaug batch is writing here" in second.stderr
        keys = [(r["sample_token"], r["camera"]) for r in log_rows(case.out)]
        assert len(keys) == len(set(keys)) == 3
        assert not (case.out / ".streetaug.lock").exists()

    def test_workers_die_with_a_killed_driver(self, tmp_path):
        psutil = pytest.importorskip("psutil")
        case = fc.case_concurrent_batches(tmp_path)
        argv = [a if a != "1" or case.argv[i - 1] != "--workers" else "2" for i, a in enumerate(case.argv)]
        driver = subprocess.Popen([sys.executable, "-m", "streetaug.cli", *argv], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
        deadline = time.time() + 60
        children = []
        while len(children) < 2:
            assert time.time() < deadline, "no workers started"
            children = [c for c in psutil.Process(driver.pid).children(recursive=True)]
            time.sleep(0.1)
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
        gone, alive = psutil.wait_procs(children, timeout=10)
        assert not alive, f"{len(alive)} worker processes outlived the driver"


class TestResume:
    def test_a_truncated_output_is_redone(self, tmp_path):
        case = fc.case_concurrent_batches(tmp_path)
        assert run(case).exit_code == 0
        images = sorted((case.out / "samples").rglob("*.jpg"))
        whole = images[0].read_bytes()
        images[0].write_bytes(whole[: len(whole) // 2])
        result = run(case)
        assert result.exit_code == 0, result.output
        assert images[0].read_bytes() == whole


class TestOutputsNeverReplaceInputs:
    def test_predict_light_never_writes_into_the_source(self, tmp_path):
        root = fc.copy_bundled(tmp_path / "data")
        before = tree(root)
        result = CliRunner().invoke(main, ["predict-light", "--dataroot", str(root), "--version", fc.VERSION,
                                           "--scene", "sample-sunny", "--out", str(root / "samples")])
        assert result.exit_code == 1
        assert "inside the source dataset" in result.output
        assert tree(root) == before

    def test_the_image_form_never_overwrites_its_input_image(self, tmp_path):
        case = fc.case_huge_image(tmp_path, 64, real=True)  # a small valid image with all the other inputs
        image = tmp_path / "image.png"
        (tmp_path / "big.png").rename(image)
        argv = [str(image) if a.endswith("big.png") else a for a in case.argv]
        argv[argv.index("--out") + 1] = str(tmp_path)
        before = image.read_bytes()
        result = CliRunner().invoke(main, argv)
        assert result.exit_code == 1, result.output
        assert "would overwrite the input --image" in result.output
        assert image.read_bytes() == before


def test_a_truncated_texture_names_the_asset(tmp_path):
    result = run(fc.case_texture_bomb(tmp_path, 9000))  # the header says 9000 x 9000, the data is cut short
    assert result.exit_code == 1
    assert "car.gltf" in result.output and "could not decode a texture" in result.output
