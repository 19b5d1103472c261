"""CLI guards (issue 21): numbers checked at parse time (exit 2 naming the option), the resource-limit options,
exit codes in --help, insert never writing into its source."""

from __future__ import annotations

import os

import numpy as np
import pytest
from click.testing import CliRunner, Result

from streetaug.augment.core import write_exr
from streetaug.augment.core.limits import ResourceLimits
from streetaug.cli.main import main
from streetaug.datasets.bundled import bundled_dataroot

LIMIT_VARS = ("STREETAUG_MAX_IMAGE_PIXELS", "STREETAUG_MAX_TEXTURE_SIDE", "STREETAUG_MAX_TEXTURE_PIXELS",
              "STREETAUG_MAX_TRIANGLES", "STREETAUG_MAX_MEMORY_MB")


@pytest.fixture(autouse=True)
def no_limit_env(monkeypatch):
    """The --max-* options write os.environ: restore it after each test."""
    for var in LIMIT_VARS:
        monkeypatch.setenv(var, "1")  # recorded first, so that teardown restores the original (also: unset)
        monkeypatch.delenv(var)


def run(*args) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def image_form(tmp_path, side: int = 64, **over) -> list[str]:
    import cv2

    cv2.imwrite(str(tmp_path / "img.png"), np.full((side, side, 3), 90, np.uint8))
    np.save(tmp_path / "depth.npy", np.full((side, side), 10.0, np.float32))
    write_exr(tmp_path / "env.exr", np.ones((16, 32, 3), np.float32))
    args = {"--image": tmp_path / "img.png", "--intrinsics": f"{side},{side},{side / 2},{side / 2}",
            "--depth": tmp_path / "depth.npy", "--envmap": tmp_path / "env.exr", "--asset": tmp_path / "none.glb",
            "--pose-camera": "0,1.5,15,0", "--out": tmp_path / "out", **over}
    return ["insert", *[x for kv in args.items() for x in kv]]


class TestNumbersAtParseTime:
    @pytest.mark.parametrize("option, value", [("--ev", "inf"), ("--ev", "-21"), ("--yaw-sigma", "-1"),
                                               ("--yaw-sigma", "181"), ("--asset-length", "0"),
                                               ("--asset-length", "nan"), ("--asset-length", "1e9")])
    def test_insert_and_batch_options(self, tmp_path, option, value):
        for command in ("insert", "batch"):
            result = run(command, option, value, "--out", tmp_path / "o")
            assert result.exit_code == 2, result.output
            assert option in result.output
        assert not (tmp_path / "o").exists()

    @pytest.mark.parametrize("option, value", [("--pose-camera", "0,1.5,nan,0"), ("--pose-camera", "0,1.5,20000,0"),
                                               ("--pose-camera", "0,1.5,15,1e9"), ("--intrinsics", "1e308,1,1,1"),
                                               ("--intrinsics", "1,2,3")])
    def test_insert_image_form_lists(self, tmp_path, option, value):
        result = run(*image_form(tmp_path, **{option: value}))
        assert result.exit_code == 2 and option in result.output, result.output

    @pytest.mark.parametrize("args, option", [(["--fov-deg", "nan"], "--fov-deg"), (["--fov-deg", "0"], "--fov-deg"),
                                              (["--fov-deg", "180"], "--fov-deg"), (["--at", "0,1,1e5"], "--at"),
                                              (["--at", "0,inf,1"], "--at")])
    def test_predict_light(self, tmp_path, args, option):
        result = run("predict-light", "--image", tmp_path / "x.png", *args, "--out", tmp_path / "o")
        assert result.exit_code == 2 and option in result.output, result.output

    def test_negative_list_values_still_parse(self, tmp_path):
        result = run(*image_form(tmp_path, **{"--pose-camera": "-0.5,1.5,15,-90"}))
        assert result.exit_code == 1 and "none.glb" in result.output, result.output  # got past parsing


class TestResourceLimits:
    def test_help_states_the_options_and_their_defaults(self):
        defaults = ResourceLimits()
        for command in ("insert", "batch", "predict-light"):
            text = run(command, "--help").output
            for option, value in (("--max-image-pixels", defaults.max_image_pixels),
                                  ("--max-texture-side", defaults.max_texture_side),
                                  ("--max-triangles", defaults.max_triangles),
                                  ("--max-memory-mb", defaults.max_memory_mb)):
                assert option in text and str(value) in text, (command, option)
            assert "STREETAUG_MAX_IMAGE_PIXELS" in text

    def test_an_option_sets_the_environment_for_workers(self, tmp_path):
        result = run(*image_form(tmp_path), "--max-image-pixels", "1000")
        assert result.exit_code == 1 and "img.png" in result.output and "limit" in result.output, result.output
        assert os.environ["STREETAUG_MAX_IMAGE_PIXELS"] == "1000"
        assert ResourceLimits.from_env().max_image_pixels == 1000

    def test_the_memory_estimate_refuses_before_decoding(self, tmp_path):
        result = run(*image_form(tmp_path, side=256), "--max-memory-mb", "300")
        assert result.exit_code == 1 and "would need about" in result.output and "256 x 256" in result.output

    def test_a_bad_limit_is_a_usage_error(self, tmp_path):
        result = run("insert", "--max-triangles", "0", "--out", tmp_path / "o")
        assert result.exit_code == 2 and "--max-triangles" in result.output


class TestExitCodesDocumented:
    @pytest.mark.parametrize("command", [[], ["batch"]])
    def test_help_names_exit_code_3(self, command):
        text = run(*command, "--help").output
        assert "3" in text and "failed" in text and "Exit codes" in text


class TestInsertOutOfTheSource:
    def test_out_containing_the_dataroot_is_refused(self, tmp_path):
        import shutil

        root = tmp_path / "data" / "root"
        shutil.copytree(bundled_dataroot(), root, ignore=shutil.ignore_patterns("ground_truth"))
        result = run("insert", "--dataroot", root, "--version", "v1.0-samples", "--scene", "sample-sunny",
                     "--quality", "draft", "--out", tmp_path / "data")
        assert result.exit_code == 1 and "contains the source dataset" in result.output
        assert not (tmp_path / "data" / "image.jpg").exists() and not (tmp_path / "data" / "labels.json").exists()
