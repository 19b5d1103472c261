"""Hybrid lighting representation: log grid, Eq. 1 radiance query, gradients, env-map conventions, files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from streetaug.augment.core import (
    camera_envmap_directions,
    equirect_pixel_lonlat,
    lonlat_to_world_dir,
    sample_equirect,
    world_dir_to_lonlat,
)
from streetaug.augment.core import InputError
from streetaug.augment.lighting.volume import (
    CH_ALPHA,
    N_CHANNELS,
    HybridLighting,
    LogGrid,
    empty_params,
    world_envmap_directions,
)

TINY = LogGrid(shape=(6, 5, 4), half_extent_xy_m=10.0, z_min_m=-2.0, z_max_m=8.0, n_below=1,
               log_scale_xy_m=2.0, log_scale_z_m=1.0, centre_xy_m=(0.5, -0.3))


def _dome(h: int = 8, w: int = 16, dtype=torch.float64) -> torch.Tensor:
    """A smooth, direction-dependent world-convention dome: colour = (d + 1) / 2 + 0.1."""
    return torch.from_numpy(world_envmap_directions(h, w) * 0.5 + 0.6).to(dtype)


def _random_params(grid: LogGrid, rng: np.random.Generator, occupancy: float = 0.4, dtype=torch.float64) -> torch.Tensor:
    p = np.zeros((*grid.shape, N_CHANNELS))
    p[..., :3] = rng.uniform(0.1, 2.0, size=(*grid.shape, 3))
    p[..., 3:6] = rng.normal(size=(*grid.shape, 3))
    p[..., 6] = rng.uniform(0.3, 2.0, size=grid.shape)
    p[..., 7] = np.where(rng.uniform(size=grid.shape) < occupancy, rng.uniform(0.05, 0.95, size=grid.shape), 0.0)
    return torch.from_numpy(p).to(dtype)


def _np_index(grid: LogGrid, p: np.ndarray) -> np.ndarray:
    """The log projection written out from the module docstring (reference for the torch version)."""
    nx, ny, nz = grid.shape
    s, R = grid.log_scale_xy_m, grid.half_extent_xy_m
    cx, cy = grid.centre_xy_m
    ix = nx / 2 * (1 + np.sign(p[0] - cx) * np.log1p(abs(p[0] - cx) / s) / np.log1p(R / s))
    iy = ny / 2 * (1 + np.sign(p[1] - cy) * np.log1p(abs(p[1] - cy) / s) / np.log1p(R / s))
    sz = grid.log_scale_z_m
    if p[2] >= 0:
        iz = grid.n_below + (nz - grid.n_below) * np.log1p(p[2] / sz) / np.log1p(grid.z_max_m / sz)
    else:
        iz = grid.n_below - grid.n_below * np.log1p(-p[2] / sz) / np.log1p(-grid.z_min_m / sz)
    return np.array([ix, iy, iz])


def _brute_force(h: HybridLighting, point: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Eq. 1 for one ray with plain Python loops."""
    lo, hi = h.grid.bounds()
    t_exit = min(max((lo[a] - point[a]) / d[a], (hi[a] - point[a]) / d[a]) if abs(d[a]) > 1e-12 else np.inf
                 for a in range(3))
    params = h.params.detach().numpy()
    out = np.zeros(3)
    trans = 1.0
    K = h.n_samples
    for k in range(1, K + 1):
        x = point + (k - 0.5) / K * t_exit * d
        idx = np.floor(_np_index(h.grid, x)).astype(int)
        if np.any(idx < 0) or np.any(idx >= np.array(h.grid.shape)):
            continue
        v = params[tuple(idx)]
        mu = v[3:6] / np.linalg.norm(v[3:6])
        lobe = v[:3] * np.exp(-(1.0 - (-d) @ mu) / v[6] ** 2)
        out += trans * v[7] * lobe
        trans *= 1.0 - v[7]
    lon, lat = world_dir_to_lonlat(d)
    env = sample_equirect(h.sky_world.numpy(), np.array(lon), np.array(lat))
    return out + trans * env


class TestLogGrid:
    def test_index_round_trip_and_ground_boundary(self):
        g = LogGrid()
        idx = np.random.default_rng(0).uniform(0, 1, size=(500, 3)) * np.array(g.shape)
        back = g.to_index(torch.from_numpy(g.index_to_point(idx))).numpy()
        assert np.allclose(back, idx, atol=1e-9)
        # z = 0 (the ground) is exactly the boundary between layer n_below - 1 and n_below
        iz = g.to_index(torch.tensor([[3.0, -2.0, 0.0], [3.0, -2.0, -1e-6]], dtype=torch.float64))[:, 2]
        assert iz[0].item() == g.n_below and iz[1].item() < g.n_below
        assert g.axis_edges()[2][g.n_below] == pytest.approx(0.0, abs=1e-12)

    def test_dense_near_the_centre(self):
        ex = LogGrid().axis_edges()[0]
        sizes = np.diff(ex)
        assert sizes[len(sizes) // 2] < 0.5 < 5.0 < sizes[0]
        assert ex[0] == pytest.approx(-150.0) and ex[-1] == pytest.approx(150.0)

    def test_outside_points_flagged(self):
        flat, inside = TINY.flat_index(torch.tensor([[0.5, -0.3, 1.0], [50.0, 0.0, 1.0], [0.0, 0.0, 9.0]],
                                                    dtype=torch.float64))
        assert inside.tolist() == [True, False, False]
        assert int(flat.max()) < TINY.n_voxels

    def test_rejects_bad_shape(self):
        with pytest.raises(ValueError, match="n_below"):
            LogGrid(shape=(4, 4, 1), n_below=2)


class TestRadianceQuery:
    @pytest.mark.parametrize("n_samples", [7, 24])
    def test_eq1_matches_brute_force(self, n_samples):
        rng = np.random.default_rng(3)
        h = HybridLighting(_dome(), grid=TINY, params=_random_params(TINY, rng), n_samples=n_samples)
        pts = rng.uniform([-6, -6, -1.5], [6, 6, 6], size=(40, 3))
        d = rng.normal(size=(40, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        got = h.radiance(pts, d).numpy()
        want = np.array([_brute_force(h, p, v) for p, v in zip(pts, d)])
        assert np.allclose(got, want, rtol=1e-10, atol=1e-12)
        # the volume did something on most rays
        assert np.mean(np.abs(want - h.env_radiance(torch.from_numpy(d)).numpy()).sum(1) > 1e-6) > 0.5

    def test_empty_volume_returns_the_sky_exactly(self):
        rng = np.random.default_rng(4)
        h = HybridLighting(_dome(), np.array([0.2, 0.3, 0.9]), torch.tensor([5.0, 5.0, 5.0], dtype=torch.float64),
                           grid=TINY, params=empty_params(TINY).double())
        d = torch.from_numpy(rng.normal(size=(200, 3)))
        d = d / d.norm(dim=1, keepdim=True)
        d[0] = torch.from_numpy(h.sun_dir)  # one ray straight into the sun's disc
        pts = torch.from_numpy(rng.uniform(-5, 5, size=(200, 3)))
        assert torch.equal(h.radiance(pts, d), h.env_radiance(d))
        assert h.radiance(pts[:1], d[:1])[0, 0] > 1000  # the sun is in it
        assert torch.equal(h.transmittance(pts, d), torch.ones(200, dtype=torch.float64))

    def test_opaque_wall_returns_its_lobe_and_blocks_the_sun(self):
        g = LogGrid(shape=(16, 16, 8), half_extent_xy_m=20.0, z_min_m=-2.0, z_max_m=18.0)
        p = empty_params(g).double()
        ix = int(torch.floor(g.to_index(torch.tensor([6.0, 0.0, 0.0]))[0]).item())
        p[ix:, :, g.n_below :, CH_ALPHA] = 1.0  # a solid block from x = 6 m on
        p[ix, :, :, :3] = torch.tensor([0.3, 0.5, 0.7], dtype=torch.float64)
        p[ix, :, :, 3:6] = torch.tensor([-1.0, 0.0, 0.0], dtype=torch.float64)  # facing the origin
        p[ix, :, :, 6] = 0.8
        p[ix + 1 :, :, :, :3] = 100.0  # behind the face: must never be seen
        sun = np.array([1.0, 0.0, 0.4])
        h = HybridLighting(_dome(), sun, torch.tensor([1e3, 1e3, 1e3], dtype=torch.float64), grid=g, params=p,
                           n_samples=256)
        origin = np.array([[0.0, 0.0, 2.0]])
        l = np.array([[1.0, 0.0, 0.0]])
        assert np.allclose(h.radiance(origin, l).numpy(), [[0.3, 0.5, 0.7]], rtol=1e-12)  # G(-l) at its axis = c
        l2 = np.array([[0.9, 0.1, 0.2]]) / np.linalg.norm([0.9, 0.1, 0.2])
        cos = float(-l2[0] @ np.array([-1.0, 0.0, 0.0]))
        want = np.array([0.3, 0.5, 0.7]) * np.exp(-(1 - cos) / 0.8**2)
        assert np.allclose(h.radiance(origin, l2).numpy()[0], want, rtol=1e-12)
        assert h.sun_transmittance(origin[0]) == 0.0
        assert h.sun_transmittance(np.array([0.0, 0.0, 17.5])) == 1.0  # above the block

    def test_gradients_reach_sky_sun_and_volume(self):
        rng = np.random.default_rng(5)
        params = _random_params(TINY, rng, occupancy=0.5).requires_grad_(True)
        sky = _dome().requires_grad_(True)
        sun_e = torch.tensor([50.0, 40.0, 30.0], dtype=torch.float64, requires_grad=True)
        h = HybridLighting(sky, np.array([0.0, 0.3, 1.0]), sun_e, sun_half_angle_rad=0.2, grid=TINY,
                           params=params, n_samples=16)
        d = rng.normal(size=(64, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d[0] = h.sun_dir
        pts = np.tile([0.5, -0.3, 7.5], (64, 1))  # near the top: some rays reach the sky and the sun
        loss = h.radiance(pts, d).sum()
        loss.backward()
        for name, g in (("params", params.grad), ("sky", sky.grad), ("sun", sun_e.grad)):
            assert torch.isfinite(g).all(), name
            assert g.abs().sum() > 0, name
        # every VSG channel receives gradient somewhere
        assert (params.grad.reshape(-1, N_CHANNELS).abs().sum(0) > 0).all()

    def test_gradcheck_float64(self):
        grid = LogGrid(shape=(2, 2, 2), half_extent_xy_m=4.0, z_min_m=-2.0, z_max_m=4.0, n_below=1)
        rng = np.random.default_rng(6)
        base = _random_params(grid, rng, occupancy=1.0)
        d = rng.normal(size=(4, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts = rng.uniform(-1, 1, size=(4, 3))

        def f(params, sky):
            return HybridLighting(sky, grid=grid, params=params, n_samples=5).radiance(pts, d)

        assert torch.autograd.gradcheck(f, (base.requires_grad_(True), _dome(2, 4).requires_grad_(True)),
                                        eps=1e-6, atol=1e-5)


class TestEnvmapConventions:
    def test_world_and_camera_frame_maps(self):
        h = HybridLighting(_dome(32, 64), grid=TINY, params=empty_params(TINY).double())
        p = np.array([0.0, 0.0, 1.0])
        world = h.envmap_at(p, 16, 32)
        want = sample_equirect(h.sky_world.numpy(), *equirect_pixel_lonlat(16, 32))
        assert np.allclose(world, want, atol=1e-6)
        # camera frame (x right, y down, z forward) looking along volume +x: R_vol_from_cam
        R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        cam = h.envmap_at(p, 16, 32, R_vol_from_frame=R)
        d_vol = camera_envmap_directions(16, 32).reshape(-1, 3) @ R.T
        want = sample_equirect(h.sky_world.numpy(), *world_dir_to_lonlat(d_vol)).reshape(16, 32, 3)
        assert np.allclose(cam, want, atol=1e-6)
        # camera straight ahead = volume +x; camera up (-y) = volume +z
        assert np.allclose(camera_envmap_directions(16, 32)[8, 16] @ R.T, [1.0, 0.0, 0.0], atol=0.2)

    def test_round_trip_through_a_bright_voxel(self):
        """A bright voxel seen from a point lands at the camera-frame pixel of its direction."""
        g = LogGrid(shape=(32, 32, 16), half_extent_xy_m=20.0, z_min_m=-2.0, z_max_m=18.0)
        p = empty_params(g)
        target = np.array([8.0, 3.0, 4.0])  # volume frame
        i = np.floor(g.to_index(torch.from_numpy(target)).numpy()).astype(int)
        p[i[0], i[1], i[2], :3] = 50.0
        p[i[0], i[1], i[2], CH_ALPHA] = 1.0
        h = HybridLighting(torch.zeros(8, 16, 3), grid=g, params=p, n_samples=512)
        R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # R_vol_from_cam
        env = h.envmap_at(np.zeros(3) + [0.0, 0.0, 1.0], 64, 128, R_vol_from_frame=R)
        j, k = np.unravel_index(np.argmax(env[..., 0]), env.shape[:2])
        d_cam = camera_envmap_directions(64, 128)[j, k]
        d_true = R.T @ (g.index_to_point(i + 0.5) - [0.0, 0.0, 1.0])
        d_true /= np.linalg.norm(d_true)
        assert np.degrees(np.arccos(np.clip(d_cam @ d_true, -1, 1))) < 6.0


class TestFiles:
    def test_save_load_round_trip(self, tmp_path):
        rng = np.random.default_rng(7)
        h = HybridLighting(_dome(8, 16, torch.float32), np.array([0.1, 0.2, 0.9]), torch.tensor([9.0, 8.0, 7.0]),
                           grid=TINY, params=_random_params(TINY, rng, dtype=torch.float32), n_samples=33)
        doc = h.save(tmp_path)
        assert doc["schema"] == "streetaug.hybrid_lighting/1" and (tmp_path / "volume.npz").is_file()
        back = HybridLighting.load(tmp_path)
        assert back.grid == h.grid and back.n_samples == 33
        assert np.allclose(back.sun_dir, h.sun_dir) and torch.allclose(back.sun_irradiance, h.sun_irradiance)
        assert torch.allclose(back.sky_world, h.sky_world)
        occ = h.params[..., CH_ALPHA] > 0
        assert torch.equal(back.params[..., CH_ALPHA] > 0, occ)
        assert torch.allclose(back.params[occ], h.params[occ], rtol=2e-3, atol=2e-3)  # float16 storage
        d = rng.normal(size=(30, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts = rng.uniform(-3, 3, size=(30, 3))
        assert np.allclose(back.radiance(pts, d).numpy(), h.radiance(pts, d).numpy(), rtol=5e-3, atol=5e-3)

    def test_bad_schema_is_an_input_error(self, tmp_path):
        (tmp_path / "hybrid.json").write_text('{"schema": "nope"}')
        with pytest.raises(InputError, match="schema"):
            HybridLighting.load(tmp_path)


def test_lift_out_of_solid_ground():
    g = LogGrid(shape=(16, 16, 8), half_extent_xy_m=20.0, z_min_m=-2.0, z_max_m=18.0, n_below=2)
    p = empty_params(g)
    p[:, :, : g.n_below, CH_ALPHA] = 1.0
    h = HybridLighting(torch.ones(4, 8, 3), grid=g, params=p)
    assert np.allclose(h.lift_out_of_solid(np.array([3.0, 1.0, 0.5])), [3.0, 1.0, 0.5])  # free: unchanged
    lifted = h.lift_out_of_solid(np.array([3.0, 1.0, -0.7]))
    assert 0.0 <= lifted[2] < 1.0
    # from the lifted point the upper hemisphere is open sky
    up = lonlat_to_world_dir(np.array([0.3]), np.array([1.2]))
    assert np.allclose(h.radiance(lifted[None], up).numpy(), 1.0)


def test_cached_envmap_is_traced_once_and_rotates_into_any_frame(monkeypatch):
    """An object seen by several cameras: its local map is traced once (world convention) and each camera gets it
    rotated; the rotation matches tracing the camera's map directly; changed parameters invalidate the cache."""
    from streetaug.augment.lighting.volume import world_to_frame_envmap

    rng = np.random.default_rng(3)
    h = HybridLighting(_dome(16, 32, torch.float32), grid=TINY, params=_random_params(TINY, rng, dtype=torch.float32))
    calls = []
    traced = HybridLighting.envmap_at
    monkeypatch.setattr(HybridLighting, "envmap_at", lambda self, *a, **k: calls.append(a) or traced(self, *a, **k))
    p = np.array([1.0, 0.5, 1.2])
    first = h.envmap_at_cached(p, 32, 64)
    assert h.envmap_at_cached(p + 1e-5, 32, 64) is first and len(calls) == 1  # the same point to the millimetre
    c, s = np.cos(0.7), np.sin(0.7)
    R_vol_from_cam = np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, -1.0, 0.0]])  # a level camera looking 40 deg left
    rotated = world_to_frame_envmap(first, R_vol_from_cam, 32, 64)
    direct = traced(h, p, 32, 64, R_vol_from_frame=R_vol_from_cam)
    assert np.abs(rotated - direct).mean() / np.abs(direct).mean() < 0.05
    with torch.no_grad():
        h.params[..., :3] *= 2.0  # in place: a new version of the tensor
    assert h.envmap_at_cached(p, 32, 64) is not first and len(calls) == 2
