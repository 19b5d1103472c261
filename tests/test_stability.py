"""Stability: bounded reactions to perturbed inputs, and explicit fallbacks in the failure modes.

Every failure-mode case is built from a bundled sample scene by changing one thing (time of day,
location, LiDAR, map, calibration, image).  Each must give a correct result or an explicit fallback
(no sun, lower confidence, a skip with a reason), never NaN/Inf, never a car floating or in a wall.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json

import numpy as np
import pytest
from click.testing import CliRunner

from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.io import InputError
from streetaug.augment.lighting.sun import sun_direction_global
from streetaug.augment.pipeline import InsertOptions, insert_into_view
from streetaug.augment.stability import FAMILIES, measure, run_once
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

OPTIONS = InsertOptions(quality="draft", seed=0)


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
def baseline(sunny, car):
    sample, view = sunny
    return run_once(sample, view, [car], OPTIONS)


# ----------------------------------------------------------------------------- perturbation bounds


@pytest.mark.parametrize("family,strength,min_psnr_db", [
    ("exposure", -1.0, 32.0), ("exposure", 1.0, 32.0), ("noise", 5.0, 28.0), ("jpeg", 50.0, 26.0),
])
def test_image_perturbations_move_nothing_but_the_pixels(sunny, car, baseline, family, strength, min_psnr_db):
    sample, view = sunny
    row = measure(sample, view, [car], OPTIONS, FAMILIES[family], strength, baseline)
    assert row["sun_change_deg"] is not None and row["sun_change_deg"] <= 3.0
    if row["image_path_sun_change_deg"] is not None:
        assert row["image_path_sun_change_deg"] <= 3.0
    assert row["placed"] and row["placement_change_m"] == 0.0  # placement never looks at the pixels
    # The inserted car reacts like the image does: its composite matches the perturbed baseline composite.
    assert row["composite_psnr_db"] >= min_psnr_db
    assert row["finite"]
    if family != "exposure":  # the env map follows the image's exposure by design; noise must not move it
        assert row["envmap_change"] <= 0.03


def test_calibration_error_moves_the_sun_by_exactly_that_much(sunny, car, baseline):
    sample, view = sunny
    row = measure(sample, view, [car], OPTIONS, FAMILIES["calibration"], 1.0, baseline)
    assert row["sun_change_deg"] == pytest.approx(1.0, abs=0.02)
    assert row["placed"] and row["placement_change_m"] < 0.3


@pytest.mark.parametrize("family,strength,max_move_m", [
    ("depth_bias", 5.0, 0.2), ("depth_bias", -5.0, 0.2), ("depth_noise", 0.05, 0.05),
    ("lidar_dropout", 50.0, 0.1), ("focal", 2.0, 0.15),
])
def test_geometry_perturbations_move_the_placement_a_little(sunny, car, baseline, family, strength, max_move_m):
    sample, view = sunny
    row = measure(sample, view, [car], OPTIONS, FAMILIES[family], strength, baseline)
    assert row["placed"] and row["placement_change_m"] <= max_move_m
    assert row["finite"]


def test_stability_command_writes_report(tmp_path):
    from streetaug.cli.main import main

    result = CliRunner().invoke(main, ["stability", "--scene", "sample-sunny", "--families", "jpeg",
                                       "--out", str(tmp_path)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "stability.json").read_text())
    assert [r["strength"] for r in report["rows"]] == list(FAMILIES["jpeg"].strengths)
    assert (tmp_path / "stability.png").stat().st_size > 1000


# ----------------------------------------------------------------------------- failure modes


def _at_time(sample, view, when_utc: dt.datetime, location: str | None = None):
    us = int(when_utc.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6)
    new_view = dataclasses.replace(view, timestamp_us=us)
    cams = dict(sample.cameras, **{view.channel: new_view})
    return dataclasses.replace(sample, timestamp_us=us, cameras=cams, location=location or sample.location), new_view


def _time_with_elevation(location: str, day: dt.date, elevation_deg: float, rising: bool = False) -> dt.datetime:
    """The UTC time on ``day`` when the sun crosses ``elevation_deg`` (in the afternoon unless ``rising``)."""
    start = dt.datetime(day.year, day.month, day.day) - dt.timedelta(hours=12)
    times = [start + dt.timedelta(minutes=10 * i) for i in range(6 * 48)]  # 48 h around the day: any time zone
    elev = np.array([sun_direction_global(location, int(t.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6))
                     .elevation_deg for t in times])
    peak = 6 * 12 + int(np.argmax(elev[6 * 12:6 * 36]))  # the day's highest sun
    idx = range(peak, 0, -1) if rising else range(peak, len(times) - 1)
    for i in idx:
        j = i - 1 if rising else i + 1
        if (elev[i] - elevation_deg) * (elev[j] - elevation_deg) <= 0:
            lo, hi = sorted((times[i], times[j]))
            for _ in range(20):  # bisection to ~1 s
                mid = lo + (hi - lo) / 2
                e = sun_direction_global(location, int(mid.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6))
                if (e.elevation_deg > elevation_deg) != rising:
                    lo = mid
                else:
                    hi = mid
            return lo
    raise AssertionError(f"the sun never crosses {elevation_deg} deg at {location} on {day}")


def _assert_sane(result, sample=None):
    assert np.isfinite(result.lighting.light_cam.envmap).all()
    assert np.isfinite(result.shadow_ratio).all() and np.isfinite(result.mask).all()
    assert result.image.dtype == np.uint8
    if result.objects:
        assert all(np.isfinite(o["box_camera"]["center"]).all() for o in result.objects)
    else:
        assert result.skipped_reason


def test_night_gives_no_sun_and_still_renders(sunny, car):
    sample, view = sunny
    when = _time_with_elevation(sample.location, dt.date(2018, 8, 1), -20.0)
    s, v = _at_time(sample, view, when)
    result = insert_into_view(s, v, [car], OPTIONS)
    assert result.lighting.sun_source == "none" and result.lighting.sun_dir_cam is None
    assert "horizon" in result.lighting.reason
    _assert_sane(result)


@pytest.mark.parametrize("elevation_deg", [-0.5, 0.5])
def test_sun_just_below_and_just_above_the_horizon(sunny, car, elevation_deg):
    sample, view = sunny
    when = _time_with_elevation(sample.location, dt.date(2018, 8, 1), elevation_deg)
    s, v = _at_time(sample, view, when)
    result = insert_into_view(s, v, [car], OPTIONS)
    _assert_sane(result)
    if elevation_deg < 0:
        assert result.lighting.sun_dir_cam is None
    else:
        assert result.lighting.sun_source == "ephemeris" and result.lighting.sun_dir_cam is not None


def test_sun_at_the_zenith(sunny, car):
    sample, view = sunny
    # Singapore (1.3 deg N) at the March equinox's solar noon: the sun is within ~2 deg of the zenith.
    location = "singapore-onenorth"
    times = [dt.datetime(2018, 3, 20, 3, 0) + dt.timedelta(minutes=m) for m in range(0, 150, 2)]
    elev = [sun_direction_global(location, int(t.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6)).elevation_deg
            for t in times]
    when = times[int(np.argmax(elev))]
    assert max(elev) > 87.0
    s, v = _at_time(sample, view, when, location)
    result = insert_into_view(s, v, [car], OPTIONS)
    _assert_sane(result)
    up = -np.asarray(v.T_cam_from_ego)[:3, 2]
    assert result.lighting.sun_dir_cam @ -up > np.cos(np.radians(4.0))  # straight up (camera up = -ego z... sign)


def test_sun_behind_the_camera(sunny, car):
    sample, view = sunny
    s, v = _at_time(sample, view, _time_with_elevation(sample.location, dt.date(2018, 8, 1), 30.0))
    d = s.cameras[v.channel].T_cam_from_global[:3, :3] @ sun_direction_global(s.location, v.timestamp_us).direction_global
    # Rotate the ego by 180 deg in yaw if needed so that the sun is behind this camera.
    if d[2] > 0:
        flip = np.diag([-1.0, -1.0, 1.0, 1.0])
        v = dataclasses.replace(v, T_global_from_ego=v.T_global_from_ego @ flip)
    result = insert_into_view(s, v, [car], OPTIONS)
    _assert_sane(result)
    assert result.lighting.sun_dir_cam is not None and result.lighting.sun_dir_cam[2] < 0


def test_overcast_scene_has_a_weak_sun(reader, car):
    sample = reader.sample(reader.sample_tokens("sample-overcast")[0])
    result = insert_into_view(sample, sample.cameras["CAM_FRONT"], [car], OPTIONS)
    _assert_sane(result)
    assert result.lighting.sun_visibility <= 0.3
    assert result.objects
    # Only the soft sky shadow close around the car, no long hard sun shadow: every clearly shadowed pixel
    # lies within the car's 2D box grown by a quarter of its size.
    x0, y0, x1, y1 = result.objects[0]["bbox_2d"]
    gx, gy = 0.25 * (x1 - x0), 0.25 * (y1 - y0)
    ys, xs = np.nonzero(result.shadow_ratio < 0.7)
    assert len(xs) and ((xs >= x0 - gx) & (xs <= x1 + gx) & (ys >= y0 - gy) & (ys <= y1 + gy)).all()


def test_no_lidar_falls_back_to_the_map_and_ego_plane(sunny, car):
    sample, view = sunny
    s = dataclasses.replace(sample, _load_lidar=lambda: None)
    result = insert_into_view(s, s.cameras[view.channel], [car], OPTIONS)
    _assert_sane(result)
    assert result.objects, result.skipped_reason
    (p,) = result.extras["placement"].placements
    assert p.ground_source == "ego-plane"
    assert abs(p.T_global_from_object[2, 3] - view.T_global_from_ego[2, 3]) < 0.05  # on the ego's ground


def test_no_map_and_no_lidarseg_is_lower_confidence_or_a_reason(sunny, car):
    sample, view = sunny
    lidar = dataclasses.replace(sample.lidar, labels=None)
    s = dataclasses.replace(sample, drivable_area_global=None, _load_lidar=lambda: lidar)
    result = insert_into_view(s, s.cameras[view.channel], [car], OPTIONS)
    _assert_sane(result)
    placement = result.extras["placement"]
    if placement.placements:
        assert placement.placements[0].drivable_source == "lidar-ground"
        assert placement.placements[0].drivable_confidence in ("low", "medium")
    else:
        assert result.skipped_reason


def test_nothing_to_place_on_gives_a_skip_with_a_reason(sunny, car):
    sample, view = sunny
    s = dataclasses.replace(sample, drivable_area_global=None, _load_lidar=lambda: None)
    result = insert_into_view(s, s.cameras[view.channel], [car], OPTIONS)
    _assert_sane(result)
    assert not result.objects and result.skipped_reason
    assert np.array_equal(result.image, view.image)  # the image is left untouched


def test_camera_facing_a_wall_places_nothing_in_the_wall(sunny, car):
    """A wall 4 m ahead fills the view (image and LiDAR): no sky, and no car may be put inside or behind it."""
    sample, view = sunny
    rng = np.random.default_rng(0)
    wall_image = np.clip(rng.normal(120, 20, (view.height, view.width, 3)), 0, 255).astype(np.uint8)
    v = dataclasses.replace(view, _load_image=lambda: wall_image)
    # LiDAR: a dense vertical wall 4 m ahead of the camera (global frame), expressed in the sensor frame.
    lidar = sample.lidar
    T_gc = v.T_global_from_cam
    # Spacing like a 32-beam spinning LiDAR at 4 m: ~1.3 deg between beams, ~0.2 deg along a beam.
    xs, ys = np.meshgrid(np.arange(-30, 30, 0.014), np.arange(-3, 1.7, 0.093))
    wall_cam = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 4.0)], axis=1)
    wall_global = wall_cam @ T_gc[:3, :3].T + T_gc[:3, 3]
    T_sensor_from_global = np.linalg.inv(lidar.T_global_from_lidar)
    pts = np.concatenate([lidar.points_sensor, wall_global @ T_sensor_from_global[:3, :3].T + T_sensor_from_global[:3, 3]])
    walled = dataclasses.replace(lidar, points_sensor=pts, intensity=np.zeros(len(pts), np.float32),
                                 labels=None if lidar.labels is None else
                                 np.concatenate([lidar.labels, np.full(len(wall_cam), 28, lidar.labels.dtype)]))
    s = dataclasses.replace(sample, cameras=dict(sample.cameras, **{v.channel: v}), _load_lidar=lambda: walled)
    result = insert_into_view(s, v, [car], OPTIONS)
    _assert_sane(result)
    for obj in result.objects:  # anything placed must be in front of the wall and visible
        assert obj["box_camera"]["center"][2] < 4.0 or obj["visible_fraction"] > 0.5
    assert not result.objects, "a car was placed behind a wall that fills the view"


def test_wet_specular_road_stays_finite(sunny, car):
    """Mirror the upper image into the road (a wet road reflecting the sky and buildings)."""
    sample, view = sunny
    img = view.image.copy()
    h = view.height
    horizon = int(view.K[1, 2])
    n = min(horizon, h - horizon)
    img[horizon:horizon + n] = (0.4 * img[horizon:horizon + n] + 0.6 * img[horizon - n:horizon][::-1]).astype(np.uint8)
    v = dataclasses.replace(view, _load_image=lambda: img)
    s = dataclasses.replace(sample, cameras=dict(sample.cameras, **{v.channel: v}))
    result = insert_into_view(s, v, [car], OPTIONS)
    _assert_sane(result)
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
