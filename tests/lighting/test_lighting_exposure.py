"""Cameras' relative exposure from shared LiDAR points, and the shared lighting following it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.core import hdr_to_ldr, hdr_to_ldr_uint8, ldr_uint8_to_hdr
from streetaug.augment.lighting.exposure import auto_exposure_ev, exposure_ratios
from streetaug.augment.lighting.api import estimate_views_lighting
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "nuscenes-real"
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_BACK")


@pytest.fixture(scope="module")
def sunny():
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    return sample, [sample.cameras[c] for c in CAMERAS]


def exposed(view, factor: float):
    """The view as if its camera had let in ``factor`` times the light (clipping included)."""
    image = hdr_to_ldr_uint8(ldr_uint8_to_hdr(np.asarray(view.image)) * factor)
    return view.with_image(image)


def test_one_exposure_is_found_equal(sunny):
    sample, views = sunny  # the generator renders every camera with the same exposure
    ratios, info = exposure_ratios(views, sample.lidar.points_global)
    assert ratios["CAM_FRONT"] == 1.0 and ratios["CAM_FRONT_LEFT"] == pytest.approx(1.0, rel=0.02)
    assert "shared with CAM_FRONT" in info["per_camera"]["CAM_FRONT_LEFT"]
    assert ratios["CAM_BACK"] == 1.0 and "no overlap" in info["per_camera"]["CAM_BACK"]  # no shared points


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_a_brighter_or_darker_neighbour_is_measured(sunny, factor):
    sample, views = sunny
    ratios, _ = exposure_ratios([views[0], exposed(views[1], factor), views[2]], sample.lidar.points_global)
    assert ratios["CAM_FRONT_LEFT"] == pytest.approx(factor, rel=0.08)
    # the reference's choice only rescales: FRONT_LEFT as reference puts FRONT at 1 / factor
    ratios, _ = exposure_ratios([exposed(views[1], factor), views[0]], sample.lidar.points_global)
    assert ratios["CAM_FRONT"] == pytest.approx(1 / factor, rel=0.08)


def test_without_lidar_one_exposure_is_assumed(sunny):
    _, views = sunny
    ratios, info = exposure_ratios(views, None)
    assert set(ratios.values()) == {1.0} and "no LiDAR" in info["method"]


def test_shared_lighting_follows_each_cameras_exposure(sunny):
    """A camera exposed 2x gets the same volume (its pixels are divided back) and 2x the light."""
    sample, views = sunny
    kw = dict(location=sample.location, level="L2", lidar=sample.lidar, boxes=sample.boxes)
    base = estimate_views_lighting(views[:2], **kw)
    bright_view = exposed(views[1], 2.0)
    bright = estimate_views_lighting([views[0], bright_view], **kw)
    assert bright.exposure_ratio["CAM_FRONT_LEFT"] == pytest.approx(2.0, rel=0.08)
    env_base = base.for_view(views[1]).light_cam.envmap
    env_bright = bright.for_view(bright_view).light_cam.envmap
    ratio = float(np.median(env_bright / np.maximum(env_base, 1e-9)))
    # 2x clips more of the sky, and a clipped pixel only proves the saturation level: the dome it shares keeps
    # a little less of that camera's sky (measured 1.77); a map that ignored the exposure would give 1.0
    assert ratio == pytest.approx(bright.exposure_ratio["CAM_FRONT_LEFT"], rel=0.15)
    # the reference camera keeps its exposure: its map moves only through what the shared dome lost to the other
    # camera's clipping (its unseen directions shrink towards the pooled mean colour; measured 0.89), not 2x
    env_ref = bright.for_view(views[0]).light_cam.envmap
    assert float(np.median(env_ref / np.maximum(base.for_view(views[0]).light_cam.envmap, 1e-9))) == pytest.approx(
        1.0, rel=0.15)


@pytest.mark.skipif(not REAL.is_dir(), reason=f"real nuScenes excerpt not found at {REAL}")
def test_real_cameras_differ_in_exposure():
    """scene-0061: CAM_FRONT_LEFT records the surfaces it shares with CAM_FRONT several times brighter."""
    reader = NuScenesReader(REAL, "v1.0-mini")
    sample = reader.sample(reader.sample_tokens()[0])
    ratios, info = exposure_ratios([sample.cameras[c] for c in CAMERAS], sample.lidar.points_global)
    assert ratios["CAM_FRONT_LEFT"] > 3.0
    assert info["pairs"]["CAM_FRONT/CAM_FRONT_LEFT"]["points"] >= 100


def test_auto_exposure_meters_to_the_target_mean_and_follows_the_scene():
    rng = np.random.default_rng(0)
    radiance = rng.lognormal(-2.0, 1.0, size=(40, 60, 3))
    ev = auto_exposure_ev(radiance, 0.43)
    assert abs(hdr_to_ldr(radiance, ev).mean() - 0.43) < 1e-3
    # a scene 4x brighter is metered 2 stops down; a brighter target mean needs more exposure
    assert auto_exposure_ev(4.0 * radiance, 0.43) == pytest.approx(ev - 2.0, abs=1e-3)
    assert auto_exposure_ev(radiance, 0.6) > ev + 0.5
    with pytest.raises(ValueError, match="target_mean_ldr"):
        auto_exposure_ev(radiance, 1.2)
