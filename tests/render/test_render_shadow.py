"""Shadow ratio map details: cone sampling, the object's bounce light, the ground shadow seen from the object."""

import cv2
import numpy as np

from render_fixtures import primitive_car, sunny_light
from streetaug.augment.core import PinholeCamera, camera_envmap_directions, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render.bounce import BounceLight, ground_radiance_below
from streetaug.augment.render.environment import environment_tables
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.render import RenderSettings, footprint, prepare_asset
from streetaug.augment.render.shadow import GroundShadow, render_shadow

W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])


def _uniform_sky(level=1.0, ground=0.2):
    d = camera_envmap_directions(32, 64)
    env = np.where((d @ UP > 0)[..., None], level, ground).astype(np.float32) * np.ones(3, np.float32)
    return DistantLight(env, None)


def _shadow(light, car, T, settings=None, bounce=None, seed=0):
    prep = prepare_asset(car)
    depth = ground_plane_depth(K, W, H, UP, 1.5)
    bounce = bounce or BounceLight.build(light, prep, T, UP)
    settings = settings or RenderSettings()
    box = footprint(CAMERA, car, T, light, settings).shadow_box
    return render_shadow(CAMERA, box, depth, light, prep, T, UP, settings, np.random.default_rng(seed), bounce)


def test_sky_occlusion_matches_a_dense_lattice():
    """Cone sampling with a few directions agrees with many directions (far points are not under-sampled)."""
    light = _uniform_sky()
    car = primitive_car()
    T = pose_camera_to_transform(0.0, 1.5, 10.0, 60.0)
    few = _shadow(light, car, T, RenderSettings(shadow_sky_dirs=16, shadow_factor=2))
    many = _shadow(light, car, T, RenderSettings(shadow_sky_dirs=256, shadow_factor=2))
    a, b = few.ratio_rgb.mean(axis=2), many.ratio_rgb.mean(axis=2)
    assert b.min() < 0.6  # a real shadow
    assert np.abs(a - b).mean() < 0.01 and np.percentile(np.abs(a - b), 99) < 0.08


def test_ground_radiance_below_the_horizon():
    light = _uniform_sky(1.0, 0.3)
    np.testing.assert_allclose(ground_radiance_below(environment_tables(light.envmap), UP), 0.3, rtol=1e-6)


def test_bounce_light_back_faces_are_interior_and_undersides_see_the_shadow():
    light = _uniform_sky(1.0, 0.3)
    car = primitive_car()
    T = pose_camera_to_transform(0.0, 1.5, 10.0, 0.0)
    prep = prepare_asset(car)
    b = BounceLight.build(light, prep, T, UP)
    # Rays from under the car straight up hit the body's underside (a front face seen from below).
    o = np.array([[0.0, 0.0, 0.05], [0.5, 0.2, 0.05]])
    d = np.tile([0.0, 0.0, 1.0], (2, 1))
    hits = prep.scene.intersect(o, d)
    assert hits.hit.all()
    A, B = b.radiance(hits.face, d)
    assert np.all(B > 0)  # it sees the ground below it ...
    np.testing.assert_allclose(A, 0.0, atol=1e-5)  # ... and nothing else (no sky, no sun)
    # From inside the body a ray hits a back face: the dark interior.
    o_in = np.array([[0.0, 0.0, 0.6]])
    hits = prep.scene.intersect(o_in, d[:1])
    A, B = b.radiance(hits.face, d[:1])
    assert np.all(A == 0) and np.all(B == 0)


def test_foot_ratio_is_dark_under_the_car():
    sh = _shadow(sunny_light(), primitive_car(), pose_camera_to_transform(0.0, 1.5, 10.0, 60.0))
    assert sh.foot_ratio is not None and np.all(sh.foot_ratio < 0.3)


def test_ground_shadow_seen_from_the_object():
    """Rays from the car going down land in its shadow (ratio < 1); rays going up or off the map see 1."""
    light = sunny_light()
    car = primitive_car()
    T = pose_camera_to_transform(0.0, 1.5, 10.0, 60.0)
    sh = _shadow(light, car, T)
    g = GroundShadow(sh, CAMERA, T, T[:3, :3].T @ UP)
    o = np.array([[0.0, 0.0, 0.2], [0.0, 0.0, 0.2], [0.0, 0.0, 0.2], [0.0, 0.0, 0.2]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [1.0, 0.0, -0.002], [-0.01, 0.0, -0.9999]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = g.ratio_along(o, d)
    assert np.all(r[0] < 0.5)  # straight under the car
    np.testing.assert_array_equal(r[1], 1.0)  # upwards: no ground
    np.testing.assert_array_equal(r[2], 1.0)  # lands 100 m ahead, off the ratio map
    np.testing.assert_allclose(r[3], r[0], atol=0.05)


def test_sun_shadow_edge_is_sharp():
    """Full-resolution sun visibility: a crisp edge (at most a few pixels of penumbra), not a blurred one."""
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    light = DistantLight(np.zeros_like(light.envmap), light.sun)  # sun only
    sh = _shadow(light, primitive_car(), pose_camera_to_transform(0.0, 1.5, 12.0, 90.0),
                 RenderSettings(shadow_factor=6))

    r = sh.ratio_rgb.mean(axis=2)
    dark = (r < 0.1).astype(np.uint8)
    assert dark.sum() > 200
    outline = (cv2.dilate(dark, np.ones((3, 3), np.uint8)) - dark).sum()  # pixels around the dark core
    partial = ((r > 0.1) & (r < 0.9)).sum()
    assert partial < 1.5 * outline  # a penumbra about a pixel wide (a 6-pixel grid blurred would give ~6x)
