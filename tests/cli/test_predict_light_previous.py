"""``streetaug predict-light --previous-keyframe`` on the bundled sequence scene (5 keyframes, 3 cameras)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenEXR
from click.testing import CliRunner

from streetaug.cli.main import main
from streetaug.datasets.nuscenes import NuScenesReader

SEQUENCE = Path(__file__).resolve().parents[2] / "examples" / "nuscenes-sequence"
VERSION = "v1.0-sequence"


def _predict(tmp_path: Path, token: str, *extra: str) -> tuple[str, dict, np.ndarray]:
    out = tmp_path / f"{token[:8]}{'_prev' if extra else ''}"
    result = CliRunner().invoke(main, ["predict-light", "--dataroot", str(SEQUENCE), "--version", VERSION,
                                       "--sample", token, "--camera", "CAM_FRONT", "--level", "L3",
                                       "--out", str(out), *extra], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    with OpenEXR.File(str(out / "envmap_camera.exr")) as f:
        channels = f.channels()
        env = np.stack([channels[c].pixels for c in ("R", "G", "B")], -1) if "R" in channels else \
            np.asarray(next(iter(channels.values())).pixels)
    return result.output, json.loads((out / "lighting.json").read_text()), env


def test_previous_keyframe_is_used_and_named(tmp_path):
    tokens = NuScenesReader(SEQUENCE, VERSION).sample_tokens()
    _, plain, env_plain = _predict(tmp_path, tokens[2])
    _, with_prev, env_prev = _predict(tmp_path, tokens[2], "--previous-keyframe")
    assert plain["params"]["instant"]["previous_keyframe"] is None
    assert with_prev["params"]["instant"]["previous_keyframe"] == tokens[1]
    assert "previous keyframe" in with_prev["reason"]
    # its cameras' surfaces fill directions the instant's left open: the map changes, somewhere
    assert env_prev.shape == env_plain.shape and not np.allclose(env_prev, env_plain)


def test_first_keyframe_has_none_and_says_so(tmp_path):
    tokens = NuScenesReader(SEQUENCE, VERSION).sample_tokens()
    output, doc, _ = _predict(tmp_path, tokens[0], "--previous-keyframe")
    assert "no previous keyframe" in output
    assert doc["params"]["instant"]["previous_keyframe"] is None


def test_previous_keyframe_needs_a_sample(tmp_path):
    result = CliRunner().invoke(main, ["predict-light", "--image", str(tmp_path / "x.jpg"), "--fov-deg", "70",
                                       "--previous-keyframe", "--out", str(tmp_path / "o")])
    assert result.exit_code != 0 and "--previous-keyframe needs a dataset sample" in result.output
