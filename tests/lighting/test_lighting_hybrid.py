"""Building the hybrid lighting from a scene: facades, sky dome, canyon prior, levels, multi-view, outputs."""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import replace

import numpy as np
import pytest

from streetaug.augment.core import (
    camera_envmap_directions,
    hdr_to_ldr_uint8,
    intrinsics_from_fov,
    luminance,
    make_transform,
    pixel_rays,
    transform_points,
    world_dir_to_lonlat,
    yaw_to_quat,
)
from streetaug.augment.core import InputError, read_exr
from streetaug.augment.lighting.api import (
    estimate_lighting,
    estimate_lighting_from_image,
    estimate_sample_lighting,
    estimate_views_lighting,
)
from streetaug.augment.lighting.build import structure_heights
from streetaug.augment.lighting.levels import L3_GRID, HeightMap, choose_level, predicted_errors, region_points
from streetaug.augment.lighting.observe import ViewObservation, extend_facades
from streetaug.augment.lighting.outputs import write_lighting_outputs
from streetaug.augment.lighting.sky import make_sky_light
from streetaug.augment.lighting.sky_prior import censored_sky_log_gain
from streetaug.augment.lighting.skydome import build_sky_dome
from streetaug.augment.lighting.sun import sun_direction_global
from streetaug.augment.lighting.volume import HybridLighting
from streetaug.datasets.sample import CameraView, LidarSweep

W_IMG, H_IMG = 400, 225
LOCATION = "singapore-onenorth"
NOON = int(dt.datetime(2018, 7, 24, 4, 0, tzinfo=dt.timezone.utc).timestamp() * 1e6)  # 12:00 local
NIGHT = int(dt.datetime(2018, 7, 24, 15, 0, tzinfo=dt.timezone.utc).timestamp() * 1e6)  # 23:00 local
T_EGO_FROM_CAM = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [1.0, 0.0, 1.5])
T_GLOBAL_FROM_EGO = make_transform(yaw_to_quat(np.radians(20.0)), [300.0, 500.0, 0.0])


# ----------------------------------------------------------------------------- unit pieces


def test_extend_facades_up_to_the_sky():
    depth = np.full((6, 3), np.inf)
    depth[4:, :] = 10.0  # ground / wall bottom known in the two lowest rows
    sky = np.zeros((6, 3), bool)
    sky[:2, 0] = True  # column 0: sky above row 2
    sky[:, 2] = False
    out, capped = extend_facades(depth, sky)
    assert np.all(out[2:, 0] == 10.0) and np.all(np.isinf(out[:2, 0]))
    assert np.all(out[:, 1] == 10.0) and capped.tolist() == [False, True, True]


def _obs(dirs, rgb, sky, sat=None) -> ViewObservation:
    n = len(dirs)
    return ViewObservation("CAM", np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros((0, 3)), np.zeros(0, bool),
                           np.asarray(dirs, float), np.asarray(rgb, np.float32), np.asarray(sky, bool),
                           np.zeros(n, bool) if sat is None else np.asarray(sat, bool), np.zeros(3))


def test_sky_dome_pastes_observations_and_corrects_the_model():
    H, W = 16, 64
    model = np.full((H, W, 3), 1.0, np.float32)
    rng = np.random.default_rng(0)
    az = rng.uniform(-0.3, 0.3, 400)
    el = rng.uniform(0.1, 0.6, 400)
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    dome, stats = build_sky_dome(model, [_obs(dirs, np.full((400, 3), 2.0), np.ones(400, bool))])
    lon, lat = world_dir_to_lonlat(dirs[:1])
    col = int((lon[0] / (2 * np.pi) + 0.5) * W)
    row = int((0.5 - lat[0] / np.pi) * H)
    assert np.allclose(dome[row, col], 2.0)  # observed: pasted
    assert np.allclose(stats["sky_gain_rgb"], 2.0)
    assert np.allclose(dome[3, W // 2 + W // 4], 2.0, rtol=1e-3)  # unobserved sky: model x gain by elevation
    assert np.allclose(dome[H - 2], 1.0)  # below the horizon untouched
    # a clipped (saturated) observation is a lower bound: the sky never falls below it, and takes the expected
    # ratio given that bound under the prior of unclipped skies (.sky_prior; far below the model: the prior's)
    dome2, stats2 = build_sky_dome(model, [_obs(dirs, np.full((400, 3), 0.5), np.ones(400, bool), np.ones(400, bool))])
    assert np.all(dome2[: H // 2] >= 0.5 - 1e-6)
    expected = censored_sky_log_gain(np.full((1, 3), np.log(0.5)), np.ones((1, 3), bool))[0]
    np.testing.assert_allclose(np.log(stats2["sky_gain_rgb"]), expected, atol=1e-6)


def test_each_cameras_sky_corrects_the_dome_around_its_own_azimuth():
    H, W = 16, 64
    model = np.full((H, W, 3), 1.0, np.float32)
    rng = np.random.default_rng(0)
    el = rng.uniform(0.1, 0.6, 400)

    def dirs_at(az0):
        az = az0 + rng.uniform(-0.3, 0.3, 400)
        return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)

    front, back = _obs(dirs_at(0.0), np.full((400, 3), 2.0), np.ones(400, bool)), \
        _obs(dirs_at(np.pi), np.full((400, 3), 8.0), np.ones(400, bool))
    dome, _ = build_sky_dome(model, [front, back])
    col = lambda az: int((az / (2 * np.pi) + 0.5) * W) % W  # noqa: E731
    # unobserved sky above either camera's view follows that camera's correction, not one shared per row
    assert dome[2, col(0.0)] == pytest.approx(2.0, rel=0.05)
    assert dome[2, col(np.pi - 1e-3)] == pytest.approx(8.0, rel=0.05)
    assert 2.5 < dome[2, col(np.pi / 2), 0] < 7.5  # in between: in between
    # one camera: one correction per row, whatever the azimuth
    only, _ = build_sky_dome(model, [front])
    assert np.allclose(only[2], only[2, col(0.0)])


def test_a_bright_top_edge_does_not_brighten_the_sky_above_it():
    H, W = 32, 64
    model = np.full((H, W, 3), 1.0, np.float32)
    rng = np.random.default_rng(1)
    az = rng.uniform(-0.4, 0.4, 2000)
    el = rng.uniform(0.05, 0.5, 2000)  # the image's sky: 3-29 deg
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    rgb = np.full((2000, 3), 1.5)
    rgb[el > 0.47] = 9.0  # a glare along the image's top edge
    dome, _ = build_sky_dome(model, [_obs(dirs, rgb, np.ones(2000, bool))])
    # towards the zenith and opposite the camera: the camera's overall correction (1.5), not the top row's (9)
    assert dome[1, W // 2 + W // 4, 0] == pytest.approx(1.5, rel=0.05)
    assert dome[1, 2, 0] == pytest.approx(1.5, rel=0.05)


def test_structure_heights_raise_cut_columns_to_the_conditional_median():
    top = np.array([5.0, 6.0, 8.0, 12.0, 20.0, 30.0, 9.0, 11.0, 14.0, 18.0, 22.0, 2.0])
    cam_top = top.copy()
    cam_capped = np.zeros(12, bool)
    cam_capped[[0, 11]] = True  # two columns reach the top edge of the image
    r = np.full(12, 40.0)
    heights, stats = structure_heights(top, cam_top, cam_capped, r, np.ones(12, bool))
    seen = np.sort(top[1:11])
    assert heights[0] == np.sort(seen[seen > 5.0])[len(seen[seen > 5.0]) // 2]
    assert np.all(heights[1:11] == top[1:11]) and stats["seen_whole_columns"] == 10
    assert heights[11] > 2.0


def test_a_cut_structure_taller_than_every_seen_one_keeps_its_observed_top():
    top = np.array([5.0, 6.0, 8.0, 12.0, 20.0, 30.0, 9.0, 11.0, 14.0, 18.0, 22.0, 35.0])
    cam_capped = np.zeros(12, bool)
    cam_capped[11] = True  # the tallest reaches the image's top edge: 35 m is a lower bound, nothing seen is taller
    heights, _ = structure_heights(top, top.copy(), cam_capped, np.full(12, 40.0), np.ones(12, bool))
    assert heights[11] == 35.0  # not a guessed extrapolation above it


def test_height_map_blocking_and_level_choice():
    pts = np.array([[x, y, z] for x in np.arange(10.0, 12.0, 0.5) for y in np.arange(-20, 20, 0.5) for z in (5.0, 25.0)])
    hmap = HeightMap.from_points(pts)
    sun = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)  # 45 deg towards +x, behind the wall seen from x < 10
    shaded = region_points(np.array([2.0, 0.0]))
    open_field = region_points(np.array([-60.0, 0.0]))
    assert hmap.blocked(shaded, sun[None]).all() and not hmap.blocked(open_field, sun[None]).any()
    err_shade, ev = predicted_errors(hmap, shaded, sun, 10.0, 2.0, 5.0, np.array([0.0, 0.0]))
    assert ev["sun_blocked_fraction"] == 1.0 and err_shade["L1"] > 1.0 and err_shade["L2"] < 0.05
    assert choose_level(err_shade)[0] == "L2"
    err_open, _ = predicted_errors(hmap, open_field, sun, 10.0, 2.0, 5.0, np.array([-60.0, 0.0]))
    level, reason = choose_level(err_open)
    assert level == "L1" and reason.startswith("auto: L1") and "L0" in reason
    # the wall is outside L2's box (centred 60 m away): only L3 sees it
    err_far, _ = predicted_errors(hmap, shaded, sun, 10.0, 2.0, 5.0, np.array([-60.0, 0.0]))
    assert choose_level(err_far)[0] == "L3"


# ----------------------------------------------------------------------------- a synthetic street with a wall


def _wall_scene(timestamp_us: int):
    """A level camera on a ground plane, and a 25 m tall wall (LiDAR) between a test point and the sun."""
    K = intrinsics_from_fov(W_IMG, H_IMG, 70.0)
    sun = sun_direction_global(LOCATION, timestamp_us)
    R_ego_from_global = T_GLOBAL_FROM_EGO[:3, :3].T
    sun_ego = R_ego_from_global @ sun.direction_global
    horiz = sun_ego[:2] / np.linalg.norm(sun_ego[:2])
    shaded_ego = np.array([18.0, 0.0, 0.0])
    # the wall: 30 m wide, 6 m in front of the point towards the sun, 25 m tall, made of LiDAR returns
    centre = shaded_ego[:2] + 6.0 * horiz
    side = np.array([-horiz[1], horiz[0]])
    s, z = np.meshgrid(np.linspace(-15, 15, 121), np.linspace(0.3, 25, 100))
    wall = np.concatenate([(centre + side * s.reshape(-1, 1)), z.reshape(-1, 1)], axis=1)
    wall = np.concatenate([wall, wall + np.r_[horiz, 0.0] * 0.5])
    lit_ego = shaded_ego[:2] - 14.0 * horiz
    lidar = LidarSweep(wall, np.zeros(len(wall), np.float32), np.eye(4), T_GLOBAL_FROM_EGO, timestamp_us)
    # image: the sky above the horizon, grey ground below, the wall (where it is in view) grey too
    up_cam = np.array([0.0, -1.0, 0.0])
    sun_cam = (T_EGO_FROM_CAM[:3, :3].T @ sun_ego)
    light = make_sky_light(sun_cam, up_cam, cloud_cover=0.2, ground_albedo=0.15, scale=0.004)
    u, v = np.meshgrid(np.arange(W_IMG), np.arange(H_IMG))
    rays = pixel_rays(K, np.stack([u.ravel(), v.ravel()], 1))
    rad = light.radiance(np.zeros_like(rays), rays)
    rays_ego = rays @ T_EGO_FROM_CAM[:3, :3].T
    o_ego = T_EGO_FROM_CAM[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((centre - o_ego[:2]) @ horiz) / (rays_ego[:, :2] @ horiz)
    hit = o_ego[None] + t[:, None] * rays_ego
    on_wall = (t > 0) & (np.abs((hit[:, :2] - centre) @ side) <= 15.0) & (hit[:, 2] >= 0.0) & (hit[:, 2] <= 25.0)
    rad[(rays[:, 1] > 0.01) | on_wall] = 0.04
    image = hdr_to_ldr_uint8(rad.reshape(H_IMG, W_IMG, 3))
    view = CameraView("CAM_FRONT", "tok", "synthetic.png", K, W_IMG, H_IMG, T_EGO_FROM_CAM, T_GLOBAL_FROM_EGO,
                      timestamp_us).with_image(image)
    to_cam = np.linalg.inv(T_EGO_FROM_CAM)
    shaded_cam = transform_points(to_cam, np.array([[*shaded_ego[:2], 0.6]]))[0]
    lit_cam = transform_points(to_cam, np.array([[*lit_ego, 0.6]]))[0]
    wall_dir_cam = T_EGO_FROM_CAM[:3, :3].T @ np.r_[horiz, 0.0]
    return view, lidar, shaded_cam, lit_cam, wall_dir_cam


SMALL_L3 = replace(L3_GRID, shape=(80, 80, 24))  # the L3 extent at a coarser resolution: faster tests


@pytest.fixture(scope="module")
def wall_l3():
    view, lidar, shaded, lit, wall_dir = _wall_scene(NOON)
    est = estimate_views_lighting([view], LOCATION, "L3", lidar=lidar, grid=SMALL_L3).for_view(view)
    return view, lidar, est, shaded, lit, wall_dir


def test_l3_shadow_of_a_wall_and_the_wall_in_the_local_envmap(wall_l3):
    view, _, est, shaded, lit, wall_dir = wall_l3
    assert est.level == "L3" and est.sun_source == "ephemeris" and est.hybrid is not None
    l1 = estimate_lighting(view, LOCATION, "L1")
    assert np.allclose(est.sun_dir_cam, l1.sun_dir_cam, atol=1e-9)  # same ephemeris sun
    in_shadow, in_sun = est.light_at(shaded), est.light_at(lit)
    assert in_shadow.sun.visibility < 0.1 * l1.light_cam.sun.visibility
    assert in_sun.sun.visibility > 0.9 * l1.light_cam.sun.visibility
    # towards the wall (6 m away, 17 deg up) the shaded point sees the wall, not the sky
    d = camera_envmap_directions(128, 256).reshape(-1, 3)
    k = int(np.argmax(d @ (wall_dir + np.array([0.0, -0.3, 0.0]))))
    T = est.T_vol_from_cam
    p_vol = est.hybrid.lift_out_of_solid(T[:3, :3] @ shaded + T[:3, 3])
    assert est.hybrid.transmittance(p_vol[None], (T[:3, :3] @ d[k])[None]).item() == 0.0
    f = l1.fit  # the open sky there: L1's sky model (its map shows the wall where the camera saw it)
    sky = make_sky_light(f.sky_sun_dir_cam, f.up_cam, f.turbidity, f.cloud_cover, f.ground_albedo, 128, 256, f.scale)
    sky_there = sky.envmap.reshape(-1, 3)[k]
    assert abs(luminance(in_shadow.envmap.reshape(-1, 3)[k]) / luminance(sky_there) - 1.0) > 0.2
    # lit point: its upper hemisphere away from the wall is the sky dome
    assert np.all(np.isfinite(in_shadow.envmap)) and in_shadow.envmap.shape == (128, 256, 3)


def test_auto_picks_a_volume_level_in_shadow_and_l1_in_the_open(wall_l3):
    view, lidar, _, shaded, lit, _ = wall_l3
    est_shadow = estimate_lighting(view, LOCATION, "auto", lidar=lidar, query_point_cam=shaded)
    assert est_shadow.level in ("L2", "L3") and est_shadow.reason.startswith("auto:")
    assert est_shadow.params["auto"]["predicted_errors"]["L1"] > 0.5
    far_open = np.array([40.0, 1.5, -60.0])  # behind the camera, far from the wall
    est_open = estimate_lighting(view, LOCATION, "auto", lidar=lidar, query_point_cam=far_open)
    assert est_open.level == "L1" and est_open.hybrid is None and "auto: L1" in est_open.reason


def test_outputs_of_a_volume_level(wall_l3, tmp_path):
    view, _, est, shaded, lit, _ = wall_l3
    doc = write_lighting_outputs(est, tmp_path, view.image, query_point_cam=shaded)
    on_disk = json.loads((tmp_path / "lighting.json").read_text())
    assert on_disk["level"] == "L3" and on_disk["schema"] == "streetaug.lighting/1"
    assert on_disk["sun"]["direction_camera"] is not None and on_disk["sun"]["visibility"] < 0.1
    assert on_disk["sun"]["transmittance_at_query"] < 0.1 and doc["files"]["hybrid"] == "hybrid/hybrid.json"
    env = read_exr(tmp_path / "envmap_camera.exr")
    assert env.shape == (128, 256, 3) and np.allclose(env, est.light_at(shaded).to_envmap(128, 256), rtol=1e-5)
    back = HybridLighting.load(tmp_path / "hybrid")
    assert back.grid == est.hybrid.grid
    assert "local_envmap" in on_disk["timing_s"]


def test_night_at_l3_has_no_sun_and_no_error():
    view, lidar, shaded, _, _ = _wall_scene(NIGHT)
    est = estimate_views_lighting([view], LOCATION, "L3", lidar=lidar, grid=SMALL_L3).for_view(view)
    assert est.sun_source == "none" and est.sun_dir_cam is None and est.light_cam.sun is None
    assert "night" in est.reason and est.level == "L3"
    local = est.light_at(shaded)
    assert local.sun is None and np.all(np.isfinite(local.envmap))


def test_levels_without_lidar_and_without_metadata():
    view, _, shaded, _, _ = _wall_scene(NOON)
    l2 = estimate_lighting(view, LOCATION, "L2")
    assert l2.level == "L2" and "no LiDAR" in l2.reason and l2.hybrid.grid.half_extent_xy_m == 40.0
    est = estimate_lighting_from_image(view.image, view.K, level="L3")
    assert est.level == "L3" and est.sun_source == "none" and est.hybrid is not None
    assert np.all(np.isfinite(est.light_at(np.array([0.0, 1.5, 15.0])).envmap))
    with pytest.raises(ValueError, match="auto"):
        estimate_lighting(view, LOCATION, "L9")


# ----------------------------------------------------------------------------- multi-view on a bundled scene


@pytest.fixture(scope="module")
def bundled_sample():
    from streetaug.datasets.bundled import bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(bundled_dataroot(), "v1.0-samples")
    return reader.sample(reader.sample_tokens("sample-lowsun")[0])


def test_sample_lighting_shared_by_views(bundled_sample):
    s = bundled_sample
    sl = estimate_views_lighting([s.cameras["CAM_FRONT"], s.cameras["CAM_BACK"]], s.location, "L3", lidar=s.lidar,
                                 boxes=s.boxes, grid=SMALL_L3)
    front, back = sl.for_view(s.cameras["CAM_FRONT"]), sl.for_view(s.cameras["CAM_BACK"])
    assert front.hybrid is back.hybrid is sl.hybrid and sl.reference == "CAM_FRONT"
    sun_global = sun_direction_global(s.location, s.timestamp_us).direction_global
    for est, view in ((front, s.cameras["CAM_FRONT"]), (back, s.cameras["CAM_BACK"])):
        assert np.degrees(np.arccos(np.clip(view.T_global_from_cam[:3, :3] @ est.sun_dir_cam @ sun_global, -1, 1))) < 0.05
    # CAM_BACK looks the other way: its distant light is the same sky, rotated
    assert abs(front.sun_dir_cam[2] + back.sun_dir_cam[2]) < 0.05
    p_front = np.array([0.0, 1.5, 15.0])
    p_global = transform_points(s.cameras["CAM_FRONT"].T_global_from_cam, p_front[None])[0]
    p_back = transform_points(s.cameras["CAM_BACK"].T_cam_from_global, p_global[None])[0]
    e1, e2 = front.light_at(p_front), back.light_at(p_back)
    assert abs(e1.sun.visibility - e2.sun.visibility) < 1e-6
    assert abs(float(luminance(e1.envmap).mean()) - float(luminance(e2.envmap).mean())) < 0.02 * float(luminance(e1.envmap).mean())


def test_sample_lighting_l0_l1_and_bad_camera(bundled_sample):
    s = bundled_sample
    l1 = estimate_sample_lighting(s, ["CAM_FRONT", "CAM_FRONT_LEFT"], "L1")
    a, b = l1.for_view(s.cameras["CAM_FRONT"]), l1.for_view(s.cameras["CAM_FRONT_LEFT"])
    assert a.level == b.level == "L1" and a.params["cloud_cover"] == b.params["cloud_cover"]
    l0 = estimate_sample_lighting(s, ["CAM_FRONT"], "L0").for_view(s.cameras["CAM_FRONT"])
    assert l0.level == "L0" and l0.light_cam.sun is None
    with pytest.raises(InputError, match="CAM_FRONT_LEFT"):
        estimate_sample_lighting(s, ["CAM_SIDE"], "L1")
    with pytest.raises(ValueError):
        estimate_views_lighting([], None, "L1")


def test_a_camera_that_was_not_an_input_gets_the_reference_light_turned_into_its_frame(bundled_sample):
    s = bundled_sample
    l1 = estimate_sample_lighting(s, ["CAM_FRONT"], "L1")
    back = l1.for_view(s.cameras["CAM_BACK"])
    sun_global = sun_direction_global(s.location, s.timestamp_us).direction_global
    R_global_from_back = s.cameras["CAM_BACK"].T_global_from_cam[:3, :3]
    assert back.level == "L1" and back.sun_source == "ephemeris" and "not an input view" in back.reason
    assert np.degrees(np.arccos(np.clip(R_global_from_back @ back.sun_dir_cam @ sun_global, -1, 1))) < 0.05
    assert np.allclose(back.light_cam.sun.direction, back.sun_dir_cam)
