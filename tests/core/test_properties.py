"""Property-based tests (hypothesis) of the shared math: transforms, projection, equirect maps at the
poles and the seam, the camera response.  Each property holds for every input hypothesis can find."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from streetaug.augment import core as cv

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False)
latitude = st.floats(-np.pi / 2, np.pi / 2, allow_nan=False)
unit_quat = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=200, deadline=None)
@given(q=unit_quat, t=st.tuples(finite, finite, finite), p=st.tuples(finite, finite, finite))
def test_rigid_transform_inverse_and_distance_preserving(q, t, p):
    T = cv.make_transform(np.asarray(q), t)
    R = T[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) > 0.999
    np.testing.assert_allclose(T @ cv.invert_transform(T), np.eye(4), atol=1e-9)
    pts = np.array([p, [0.0, 0.0, 0.0]])
    moved = cv.transform_points(T, pts)
    assert np.isclose(np.linalg.norm(moved[0] - moved[1]), np.linalg.norm(pts[0]), rtol=1e-9, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(yaw=st.floats(-179.9, 179.9), x=finite, y=finite, z=finite)
def test_pose_camera_round_trip(yaw, x, y, z):
    T = cv.pose_camera_to_transform(x, y, z, yaw)
    origin, yaw_back = cv.transform_to_pose_camera(T)
    np.testing.assert_allclose(origin, [x, y, z])
    assert abs((yaw_back - yaw + 180) % 360 - 180) < 1e-9
    np.testing.assert_allclose(T[:3, 2], [0, -1, 0], atol=1e-12)  # object up = camera up


@settings(max_examples=200, deadline=None)
@given(u=st.floats(-500, 2100), v=st.floats(-500, 1400), depth=st.floats(0.05, 500.0), f=st.floats(100, 3000))
def test_project_unproject_round_trip(u, v, depth, f):
    K = np.array([[f, 0, 800.0], [0, f * 1.01, 450.0], [0, 0, 1]])
    p = cv.unproject_depth(K, np.array([[u, v]]), np.array([depth]))
    uv, z = cv.project_points(K, p)
    np.testing.assert_allclose(uv[0], [u, v], atol=1e-7 * max(abs(u), abs(v), 1))
    assert np.isclose(z[0], depth)
    ray = cv.pixel_rays(K, np.array([[u, v]]))[0]
    np.testing.assert_allclose(ray, p[0] / np.linalg.norm(p[0]), atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(lon=angle, lat=latitude, h=st.integers(2, 64))
def test_equirect_uv_in_range_and_constant_map_is_constant(lon, lat, h):
    w = 2 * h
    u, v = cv.lonlat_to_uv(lon, lat, h, w)
    assert 0.0 <= u < w and 0.0 <= v <= h
    env = np.full((h, w, 3), 2.5)
    value = cv.sample_equirect(env, np.array(lon), np.array(lat))
    np.testing.assert_allclose(value, 2.5)  # poles and the seam included: no NaN, no leakage


@settings(max_examples=200, deadline=None)
@given(lat=st.floats(-1.4, 1.4), eps=st.floats(1e-9, 1e-4), seed=st.integers(0, 1000))
def test_equirect_lookup_is_continuous_across_the_seam(lat, eps, seed):
    env = np.random.default_rng(seed).random((16, 32, 3))
    left = cv.sample_equirect(env, np.array(np.pi - eps), np.array(lat))
    right = cv.sample_equirect(env, np.array(-np.pi + eps), np.array(lat))
    # Bilinear interpolation is Lipschitz: the jump is bounded by the gradient times the gap.
    assert np.abs(left - right).max() <= 2 * eps * 32 / (2 * np.pi) + 1e-9


@settings(max_examples=300, deadline=None)
@given(lon=angle, lat=latitude)
def test_camera_and_world_direction_round_trips(lon, lat):
    assume(abs(lat) < np.pi / 2 - 1e-6)  # longitude is undefined exactly at the poles
    for to_dir, to_lonlat in ((cv.lonlat_to_camera_dir, cv.camera_dir_to_lonlat),
                              (cv.lonlat_to_world_dir, cv.world_dir_to_lonlat)):
        d = to_dir(np.array(lon), np.array(lat))
        assert np.isclose(np.linalg.norm(d), 1.0)
        lon2, lat2 = to_lonlat(d)
        assert np.isclose(lat2, lat, atol=1e-9)
        assert abs((lon2 - lon + np.pi) % (2 * np.pi) - np.pi) < 1e-6


@settings(max_examples=50, deadline=None)
@given(h=st.integers(1, 300), w=st.integers(1, 600))
def test_solid_angles_cover_the_sphere(h, w):
    omega = cv.equirect_solid_angles(h, w)
    assert (omega > 0).all() and np.isclose(omega.sum(), 4 * np.pi)


@settings(max_examples=300, deadline=None)
@given(a=st.floats(0, 1e4), b=st.floats(0, 1e4), ev=st.floats(-4, 4))
def test_camera_response_monotone_bounded_and_invertible(a, b, ev):
    lo, hi = sorted((a, b))
    ldr_lo, ldr_hi = cv.hdr_to_ldr(np.array(lo), ev), cv.hdr_to_ldr(np.array(hi), ev)
    assert 0.0 <= ldr_lo <= ldr_hi <= 1.0
    assert ldr_hi < 1.0 or hi * 2**ev > 5.0  # only very bright values saturate to 1 in float64
    if ldr_lo < 0.99:  # the inverse is well conditioned below the shoulder's flat end
        assert np.isclose(cv.ldr_to_hdr(ldr_lo, ev), lo, rtol=1e-6, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(x=st.floats(0, 10), tau=st.floats(0.5, 0.99))
def test_softclip_continuous_with_unit_slope_at_tau(x, tau):
    eps = 1e-7
    assert abs(cv.softclip(tau + eps, tau) - cv.softclip(tau - eps, tau)) < 3 * eps
    assert cv.softclip(x, tau) <= min(x, 1.0) + 1e-12


# ----------------------------------------------------------------------------- lighting volume: log projection


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-149, 149), y=st.floats(-149, 149), z=st.floats(-3.9, 75.9))
def test_log_projection_round_trips_and_stays_in_the_grid(x, y, z):
    import torch

    from streetaug.augment.lighting.volume import LogGrid

    grid = LogGrid()
    idx = grid.to_index(torch.tensor([[x, y, z]], dtype=torch.float64)).numpy()
    assert np.all(idx >= 0) and np.all(idx <= np.array(grid.shape))
    np.testing.assert_allclose(grid.index_to_point(idx)[0], [x, y, z], atol=1e-6)
    flat, inside = grid.flat_index(torch.tensor([[x, y, z]], dtype=torch.float64))
    assert bool(inside[0]) and 0 <= int(flat[0]) < grid.n_voxels


@settings(max_examples=100, deadline=None)
@given(a=st.floats(-149, 149), b=st.floats(-149, 149))
def test_log_projection_is_monotone(a, b):
    import torch

    from streetaug.augment.lighting.volume import LogGrid

    assume(a != b)
    lo, hi = sorted((a, b))
    idx = LogGrid().to_index(torch.tensor([[lo, lo, lo / 2], [hi, hi, hi / 2]], dtype=torch.float64)).numpy()
    assert np.all(idx[0] <= idx[1])


# ----------------------------------------------------------------------------- the shadow ratio under extreme light


@settings(max_examples=12, deadline=None)
@given(sky=st.sampled_from([0.0, 1e-6, 0.3, 50.0]), sun=st.sampled_from([0.0, 1e-6, 1.0, 1e5]),
       elevation=st.floats(1.0, 89.0), azimuth=st.floats(-180, 180))
def test_shadow_ratio_finite_and_bounded_for_any_light(sky, sun, elevation, azimuth):
    """Zero, tiny and huge sky/sun irradiance: the ratio map's denominators never produce NaN/Inf or negatives."""
    from streetaug.augment.assets.procedural import procedural_car
    from streetaug.augment.lighting.light import DistantLight, SunLight
    from streetaug.augment.core.depth import ground_plane_depth
    from streetaug.augment.render import render_insertion

    W, H, f = 96, 64, 60.0
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    env = np.full((16, 32, 3), sky, np.float32)
    el, az = np.radians(elevation), np.radians(azimuth)
    direction = np.array([np.cos(el) * np.sin(az), -np.sin(el), np.cos(el) * np.cos(az)])
    light = DistantLight(env, SunLight(direction, np.full(3, sun)) if sun > 0 else None)
    depth = ground_plane_depth(K, W, H, np.array([0.0, -1.0, 0.0]), 1.5)
    image = np.full((H, W, 3), 120, np.uint8)
    T = cv.pose_camera_to_transform(0.0, 1.5, 9.0, 30.0)
    ins = render_insertion(image, K, depth, light, procedural_car(0), T, quality="draft")
    assert np.isfinite(ins.shadow_ratio).all() and ins.shadow_ratio.min() >= 0.0 and ins.shadow_ratio.max() <= 1.5
    assert np.isfinite(ins.mask).all() and ins.image.dtype == np.uint8
