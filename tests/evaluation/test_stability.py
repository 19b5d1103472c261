"""Stability: bounded reactions to perturbed inputs, and explicit fallbacks in the failure modes.

Every failure-mode case is built from a bundled sample scene by changing one thing (time of day,
location, LiDAR, map, calibration, image).  Each must give a correct result or an explicit fallback
(no sun, lower confidence, a skip with a reason), never NaN/Inf, never a car floating or in a wall.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core import InputError
from streetaug.augment.evaluation.failure_modes import failure_cases
from streetaug.augment.evaluation.stability import FAMILIES, measure, run_once
from streetaug.augment.pipeline import InsertOptions, insert_into_view
from streetaug.cli.main import main
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

OPTIONS = InsertOptions(quality="draft", seed=0)  # the default lighting level: auto


@pytest.fixture(scope="module")
def lane_rules(tmp_path_factory):
    """The car placed with the table's fixed lane / kerb weights: the sunlit placement the bounds below were measured at.
    (By default the bundled scene's cars park, so the car parks with them under the trees, where the exposure
    moves the car more: L2 25.6 / 25.3 dB at -1 / +1 EV, L1 26.1 / 19.0, measured in session 8; issue #16; the
    default placement's own bounds: test_stability_kerb.py.)"""
    path = tmp_path_factory.mktemp("rules") / "lane_car.json"
    path.write_text(json.dumps({"schema": "streetaug.class_rules/1",
                                "classes": {"car": {"zones": {"lane": 0.6, "kerb": 0.4}, "zone_weights": "fixed"}}}))
    return str(path)


@pytest.fixture(scope="module")
def perturb_options(lane_rules):
    """Perturbations are measured at L2, the level auto takes for this placement: they measure the estimate,
    not auto's choice (at +1 EV auto may find a placement in a building's shade lit well enough by L0)."""
    return InsertOptions(quality="draft", seed=0, level="L2", class_rules=lane_rules)


@pytest.fixture(scope="module")
def reader():
    return NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)


@pytest.fixture(scope="module")
def sunny(reader):
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    return sample, sample.cameras["CAM_FRONT"]


@pytest.fixture(scope="module")
def car():
    return procedural_car(3)


@pytest.fixture(scope="module")
def baseline(sunny, car, perturb_options):
    sample, view = sunny
    return run_once(sample, view, [car], perturb_options)


# ----------------------------------------------------------------------------- perturbation bounds


@pytest.mark.parametrize("family,strength,min_psnr_db", [
    # +1 EV saturates sky and road pixels, which the scene volume reads: the car follows less exactly
    # (measured 29.7 dB at L2, 30.5 at L3; the distant sky alone, L1, stays above 32).
    ("exposure", -1.0, 32.0), ("exposure", 1.0, 28.0), ("noise", 5.0, 28.0), ("jpeg", 50.0, 26.0),
])
def test_image_perturbations_move_nothing_but_the_pixels(sunny, car, baseline, perturb_options, family, strength,
                                                        min_psnr_db):
    sample, view = sunny
    row = measure(sample, view, [car], perturb_options, FAMILIES[family], strength, baseline)
    assert row["sun_change_deg"] is not None and row["sun_change_deg"] <= 3.0
    if row["image_path_sun_change_deg"] is not None:
        assert row["image_path_sun_change_deg"] <= 3.0
    assert row["placed"] and row["placement_change_m"] == 0.0  # placement never looks at the pixels
    # The inserted car reacts like the image does: its composite matches the perturbed baseline composite.
    assert row["composite_psnr_db"] >= min_psnr_db
    assert row["finite"]
    if family != "exposure":  # the env map follows the image's exposure by design; noise must not move it
        assert row["envmap_change"] <= 0.03


def test_calibration_error_moves_the_sun_by_exactly_that_much(sunny, car, baseline, perturb_options):
    sample, view = sunny
    row = measure(sample, view, [car], perturb_options, FAMILIES["calibration"], 1.0, baseline)
    assert row["sun_change_deg"] == pytest.approx(1.0, abs=0.02)
    assert row["placed"] and row["placement_change_m"] < 0.3


@pytest.mark.parametrize("family,strength,max_move_m", [
    ("depth_bias", 5.0, 0.2), ("depth_bias", -5.0, 0.2), ("depth_noise", 0.05, 0.05),
    ("lidar_dropout", 50.0, 0.1), ("focal", 2.0, 0.15),
])
def test_geometry_perturbations_move_the_placement_a_little(sunny, car, baseline, perturb_options, family, strength,
                                                           max_move_m):
    sample, view = sunny
    row = measure(sample, view, [car], perturb_options, FAMILIES[family], strength, baseline)
    assert row["placed"] and row["placement_change_m"] <= max_move_m
    assert row["finite"]


def test_stability_command_writes_report(tmp_path):
    result = CliRunner().invoke(main, ["stability", "--scene", "sample-sunny", "--families", "jpeg",
                                       "--out", str(tmp_path)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "stability.json").read_text())
    assert [r["strength"] for r in report["rows"]] == list(FAMILIES["jpeg"].strengths)
    assert (tmp_path / "stability.png").stat().st_size > 1000


# ----------------------------------------------------------------------------- failure modes


@pytest.fixture(scope="module")
def cases(sunny):
    return failure_cases(*sunny)


def _run(cases, name, car):
    sample, view, _ = cases[name]
    result = insert_into_view(sample, view, [car], OPTIONS)
    assert np.isfinite(result.lighting.light_cam.envmap).all()
    assert np.isfinite(result.shadow_ratio).all() and np.isfinite(result.mask).all()
    assert result.image.dtype == np.uint8 and result.image.shape == view.image.shape
    if result.objects:
        assert all(np.isfinite(o["box_camera"]["center"]).all() for o in result.objects)
    else:
        assert result.skipped_reason
    return result, view


def test_night_gives_no_sun_and_a_car_as_dark_as_the_scene(cases, car):
    result, view = _run(cases, "night", car)
    assert result.lighting.sun_source == "none" and result.lighting.sun_dir_cam is None
    assert "horizon" in result.lighting.reason
    car_mean = result.image[result.mask > 0.9].mean()
    assert 0.3 * view.image.mean() < car_mean < 3.0 * view.image.mean() + 5  # not a glowing white car


def test_night_timestamp_on_a_daylight_image_is_flagged(cases, car):
    result, view = _run(cases, "night_timestamp_day_image", car)
    assert result.lighting.sun_dir_cam is None
    assert "check the timestamp" in result.lighting.reason
    assert result.image[result.mask > 0.9].mean() < 200  # diffusely lit, not blown out


def test_sun_just_below_and_just_above_the_horizon(cases, car):
    below, _ = _run(cases, "sun_below_horizon", car)
    above, _ = _run(cases, "sun_at_horizon", car)
    assert below.lighting.sun_dir_cam is None
    assert above.lighting.sun_source == "ephemeris" and above.lighting.sun_dir_cam is not None


def test_sun_at_the_zenith(cases, car):
    result, view = _run(cases, "sun_at_zenith", car)
    up_cam = view.T_cam_from_ego[:3, 2]  # ego +z (up) in the camera frame
    assert result.lighting.sun_dir_cam @ up_cam > np.cos(np.radians(4.0))


def test_sun_behind_the_camera(cases, car):
    result, _ = _run(cases, "sun_behind_camera", car)
    assert result.lighting.sun_dir_cam is not None and result.lighting.sun_dir_cam[2] < 0
    assert result.objects


def test_overcast_scene_has_a_weak_sun(reader, car):
    sample = reader.sample(reader.sample_tokens("sample-overcast")[0])
    result = insert_into_view(sample, sample.cameras["CAM_FRONT"], [car], OPTIONS)
    assert np.isfinite(result.shadow_ratio).all()
    assert result.lighting.sun_visibility <= 0.3
    assert result.objects
    # Only the soft sky shadow close around the car, no long hard sun shadow: every clearly shadowed pixel
    # lies within the car's 2D box grown by a quarter of its size.
    x0, y0, x1, y1 = result.objects[0]["bbox_2d"]
    gx, gy = 0.25 * (x1 - x0), 0.25 * (y1 - y0)
    ys, xs = np.nonzero(result.shadow_ratio < 0.7)
    assert len(xs) and ((xs >= x0 - gx) & (xs <= x1 + gx) & (ys >= y0 - gy) & (ys <= y1 + gy)).all()


def test_no_lidar_falls_back_to_the_map_and_ego_plane(cases, car):
    result, view = _run(cases, "no_lidar", car)
    assert result.objects, result.skipped_reason
    (p,) = result.placement.placements
    assert p.ground_source == "ego-plane"
    assert abs(p.T_global_from_object[2, 3] - view.T_global_from_ego[2, 3]) < 0.05  # on the ego's ground


def test_no_map_and_no_lidarseg_is_lower_confidence_or_a_reason(cases, car):
    result, _ = _run(cases, "no_map_no_lidarseg", car)
    placement = result.placement
    if placement.placements:
        assert placement.placements[0].drivable_source == "lidar-ground"
        assert placement.placements[0].drivable_confidence in ("low", "medium")


def test_nothing_to_place_on_gives_a_skip_with_a_reason(cases, car):
    result, view = _run(cases, "nothing_to_place_on", car)
    assert not result.objects and result.skipped_reason
    assert np.array_equal(result.image, view.image)  # the image is left untouched


def test_camera_facing_a_wall_places_nothing_in_or_behind_the_wall(cases, car):
    result, _ = _run(cases, "facing_a_wall", car)
    assert not result.objects, f"a car was placed in or behind a wall that fills the view: {result.objects}"


def test_wet_specular_road_stays_finite(cases, car):
    result, _ = _run(cases, "wet_road", car)
    assert result.objects


@pytest.mark.parametrize("field,value,needle", [
    ("camera_intrinsic", [[0, 0, 800], [0, 0, 450], [0, 0, 1]], "camera_intrinsic"),
    ("camera_intrinsic", [[float("nan"), 0, 800], [0, 1000, 450], [0, 0, 1]], "camera_intrinsic"),
    ("rotation", [0, 0, 0, 0], "rotation"),
])
def test_corrupt_calibration_is_a_clear_error(tmp_path, field, value, needle):
    import shutil

    root = tmp_path / "data"
    shutil.copytree(bundled_dataroot() / BUNDLED_VERSION, root / BUNDLED_VERSION)
    for sub in ("samples", "maps", "lidarseg"):
        if (bundled_dataroot() / sub).exists():
            (root / sub).symlink_to(bundled_dataroot() / sub)
    table = root / BUNDLED_VERSION / "calibrated_sensor.json"
    rows = json.loads(table.read_text())
    for row in rows:
        if row.get("camera_intrinsic"):
            row[field] = value
    table.write_text(json.dumps(rows).replace("NaN", "NaN"))
    r = NuScenesReader(root, BUNDLED_VERSION)
    with pytest.raises(InputError) as info:
        sample = r.sample(r.sample_tokens("sample-sunny")[0])
        _ = sample.cameras["CAM_FRONT"].K
    assert needle in str(info.value) and "calibrated_sensor" in str(info.value)
