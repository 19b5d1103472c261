"""Lighting on the real dev scene (../shared/data/nuscenes-seq, scene-0916): maps on the image's scale at every
level, one estimate per instant, the written map's level chosen by its error, unreadable cameras.

Skips with the reason when the shared data is absent (it is there in CI).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SHARED_DATA
from streetaug.augment.evaluation.novel_view import constant_colour_scores, real_view, score_lighting, view_scores
from streetaug.augment.lighting.api import estimate_instant_lighting, estimate_views_lighting, view_estimate
from streetaug.augment.lighting.levels import L3_GRID
from streetaug.augment.lighting.parametric import view_inputs
from streetaug.augment.lighting.predicted_view import view_rays
from streetaug.cli.main import main
from streetaug.datasets.nuscenes import NuScenesReader

SEQ = SHARED_DATA / "nuscenes-seq"
pytestmark = pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file(),
                                reason=f"real nuScenes dev scene not found at {SEQ}")
KEYFRAME = 8
FAST_L3 = L3_GRID.__class__(shape=(96, 96, 24), half_extent_xy_m=L3_GRID.half_extent_xy_m, z_min_m=L3_GRID.z_min_m,
                            z_max_m=L3_GRID.z_max_m)


@pytest.fixture(scope="module")
def reader():
    return NuScenesReader(SEQ, "v1.0-mini")


@pytest.fixture(scope="module")
def sample(reader):
    return reader.sample(reader.sample_tokens("scene-0916")[KEYFRAME])


@pytest.mark.parametrize("level", ["L0", "L1", "L2", "L3"])
def test_every_level_self_view_is_on_the_image_scale(sample, level):
    """The map rendered from the camera's own centre matches the image's exposure: PSNR within 1 dB of si-PSNR."""
    view = sample.cameras["CAM_FRONT"]
    sl = estimate_views_lighting([view], sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                 grid=FAST_L3 if level == "L3" else None)
    s = score_lighting(sl, view)
    assert s["si_psnr"] - s["psnr"] <= 1.0, s
    const = constant_colour_scores([view.image], real_view(view))
    if level == "L0":
        assert abs(s["psnr"] - const["psnr"]) < 0.3  # L0 is the image's mean colour
    else:
        assert s["psnr"] > const["psnr"] + 3.0, (s, const)  # and the map carries the image's layout


def test_l1_self_view_was_off_scale_with_the_model_sky_alone(sample):
    """The same check fails for the uncorrected sky model (what L1 wrote before): the test can fail."""
    view = sample.cameras["CAM_FRONT"]
    est = view_estimate(view_inputs(view, sample.location, {}, sample.boxes, sample.lidar), {})
    rays, h = view_rays(view)
    rad = est.light_cam.radiance(np.zeros_like(rays), rays).reshape(h, -1, 3)
    s = view_scores(rad, real_view(view))
    assert s["psnr"] < 16.0


def test_one_estimate_per_instant(sample):
    """Every camera of a sample reports the same sun (global direction, visibility) and sky cloud cover."""
    ests = {c: estimate_instant_lighting(sample, c, "L1") for c in ("CAM_FRONT", "CAM_BACK_LEFT", "CAM_BACK")}
    vis = {c: e.sun_visibility for c, e in ests.items()}
    assert max(vis.values()) - min(vis.values()) < 1e-9, vis
    dirs = [sample.cameras[c].T_global_from_cam[:3, :3] @ e.sun_dir_cam for c, e in ests.items()]
    assert all(np.allclose(d, dirs[0], atol=1e-9) for d in dirs)
    for c, e in ests.items():
        assert e.params["instant"]["cameras"][0] == c and len(e.params["instant"]["cameras"]) == 6
    # each camera's map is on its own exposure: its self view matches its image
    for c, e in ests.items():
        view = sample.cameras[c]
        rays, h = view_rays(view)
        s = view_scores(e.light_cam.radiance(np.zeros_like(rays), rays).reshape(h, -1, 3), real_view(view))
        assert s["si_psnr"] - s["psnr"] <= 1.5 and s["psnr"] > 17.0, (c, s)


def test_night_timestamp_gives_no_sun(sample):
    # 15:4x local time + 8 h = 23:4x: the sun well below the horizon in Singapore
    night = sample.evolve(cameras={c: replace(v, timestamp_us=v.timestamp_us + 8 * 3600 * 10**6)
                                   for c, v in sample.cameras.items()})
    est = estimate_instant_lighting(night, "CAM_FRONT", "L1")
    assert est.sun_source == "none" or est.light_cam.sun is None, est.reason
    assert est.sun_visibility == 0.0


def _dataroot_with_broken_image(tmp_path, sample, channel: str, how: str):
    """A copy of the dev scene (tables, map, the files of ``sample``; temporary, never kept) with ``channel``'s
    image of ``sample`` truncated or removed. Copies, not links: links out of a dataroot are refused."""
    root = tmp_path / "seq"
    shutil.copytree(SEQ / "v1.0-mini", root / "v1.0-mini")
    shutil.copytree(SEQ / "maps", root / "maps")
    rows = json.loads((SEQ / "v1.0-mini" / "sample_data.json").read_text())
    for row in rows:
        if row["sample_token"] == sample.token:
            (root / row["filename"]).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(SEQ / row["filename"], root / row["filename"])
    broken = root / os.path.relpath(sample.cameras[channel].image_path, SEQ)
    if how == "corrupt":
        broken.write_bytes(broken.read_bytes()[:2000])
    else:
        broken.unlink()
    return root, broken


@pytest.mark.parametrize("how", ["corrupt", "missing"])
def test_unreadable_camera_image(tmp_path, reader, sample, how):
    root, broken = _dataroot_with_broken_image(tmp_path, sample, "CAM_BACK", how)
    runner = CliRunner()
    base = ["predict-light", "--dataroot", str(root), "--version", "v1.0-mini", "--sample", sample.token,
            "--level", "L1"]
    # the broken camera itself: a clear error naming the file, non-zero exit
    r = runner.invoke(main, base + ["--camera", "CAM_BACK", "--out", str(tmp_path / "back")])
    assert r.exit_code != 0 and broken.name in r.output, r.output
    assert not (tmp_path / "back" / "lighting.json").exists()
    # another camera still works, and says which camera it left out
    r = runner.invoke(main, base + ["--camera", "CAM_FRONT", "--out", str(tmp_path / "front")])
    assert r.exit_code == 0, r.output
    lj = json.loads((tmp_path / "front" / "lighting.json").read_text())
    text = json.dumps(lj)
    assert "CAM_BACK" in text and broken.name in text
    assert "left out" in lj["reason"]


def test_auto_for_the_map_never_keeps_a_worse_level(sample):
    """predict-light's auto: the level it keeps has a map no further from the images than the next level's."""
    est = estimate_instant_lighting(sample, "CAM_FRONT", "auto", for_map=True)
    psnr = est.params["auto_map_psnr_db"]
    order = [lv for lv in ("L1", "L2", "L3") if lv in psnr]
    k = order.index(est.level)
    assert len(order) >= 2 and est.level in order
    if k + 1 < len(order):
        assert psnr[est.level] > psnr[order[k + 1]]
    for lower in order[:k]:
        assert psnr[lower] <= psnr[order[order.index(lower) + 1]]
    assert est.reason.startswith("auto (map)")


def test_pooled_metadata_matches_the_light(sample):
    """Each camera's reported fit scale is the reference's times its exposure ratio (what its light carries)."""
    sl = estimate_views_lighting([sample.cameras[c] for c in ("CAM_FRONT", "CAM_BACK", "CAM_FRONT_LEFT")],
                                 sample.location, "L1", lidar=sample.lidar, boxes=sample.boxes)
    ref = sl.per_view["CAM_FRONT"]
    for c in ("CAM_BACK", "CAM_FRONT_LEFT"):
        e = sl.per_view[c]
        k = sl.exposure_ratio[c]
        assert e.params["scale"] == pytest.approx(ref.params["scale"] * k, rel=1e-9)
        assert e.fit.scale == pytest.approx(ref.fit.scale * k, rel=1e-9)
        assert e.params["cloud_cover"] == ref.params["cloud_cover"]
        assert "own_fit" in e.params


def test_exposed_to_mean_ldr_hits_the_target():
    """The exposure search brings a view's mean LDR value to the target, from far under or over it."""
    from streetaug.augment.core import hdr_to_ldr
    from streetaug.augment.lighting.predicted_view import exposed_to_mean_ldr
    rng = np.random.default_rng(0)
    rad = rng.lognormal(-1.0, 1.2, size=(30, 40, 3))
    for scale, target in ((1e-3, 0.42), (1e2, 0.30), (1.0, 0.55)):
        out = exposed_to_mean_ldr(rad * scale, target)
        assert abs(float(hdr_to_ldr(out).mean()) - target) < 1e-3
        ratio = out / (rad * scale)
        assert np.allclose(ratio, ratio.flat[0])  # one exposure for the whole view: the layout is kept


def test_cameras_that_were_not_inputs_are_auto_exposed(reader, sample):
    """A camera that was not an input (another camera of the instant; the input camera 1.5 s later) is predicted
    at the exposure its auto-exposure holds (the inputs' mean image value); an input keeps its measured exposure."""
    from streetaug.augment.core import hdr_to_ldr
    from streetaug.augment.lighting.predicted_view import predicted_radiance
    front = sample.cameras["CAM_FRONT"]
    sl = estimate_views_lighting([front], sample.location, "L2", lidar=sample.lidar, boxes=sample.boxes)
    target = float(np.asarray(front.image).mean()) / 255.0
    assert abs(sl.input_mean_ldr["CAM_FRONT"] - target) < 0.01
    later = reader.sample(reader.sample_tokens("scene-0916")[KEYFRAME + 3]).cameras["CAM_FRONT"]
    for view in (sample.cameras["CAM_BACK"], later):
        assert abs(float(hdr_to_ldr(predicted_radiance(sl, view)).mean()) - sl.input_mean_ldr["CAM_FRONT"]) < 2e-3
    self_view = predicted_radiance(sl, front)
    assert abs(float(hdr_to_ldr(self_view).mean()) - float(real_view(front).mean())) < 0.03  # measured, not forced
    without = replace(sl, input_mean_ldr={})  # unknown: the reference exposure, as before
    assert not np.allclose(predicted_radiance(without, later), predicted_radiance(sl, later))
