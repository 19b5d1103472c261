"""The numpy backend of the hybrid lighting (what the pipeline runs, no torch) against the torch backend (the
differentiable reference): same radiance, transmittance, local env maps and lifted points to float32 rounding,
on random volumes and on the volumes the L2/L3 levels build for the bundled scenes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from streetaug.augment.lighting.levels import L2_GRID
from streetaug.augment.lighting.volume import (
    CH_ALPHA,
    N_CHANNELS,
    HybridLighting,
    LogGrid,
    NumpyBackend,
    empty_params,
    sample_world_equirect,
    world_envmap_directions,
    world_to_frame_envmap,
)
from streetaug.augment.lighting.volume_torch import TorchBackend
from streetaug.augment.lighting.volume_torch import sample_world_equirect as sample_world_equirect_torch

TINY = LogGrid(shape=(6, 5, 4), half_extent_xy_m=10.0, z_min_m=-2.0, z_max_m=8.0, n_below=1,
               log_scale_xy_m=2.0, log_scale_z_m=1.0, centre_xy_m=(0.5, -0.3))
RTOL, ATOL = 2e-5, 1e-6  # float32: a few ulps of the summed lobes


def _random_volume(grid: LogGrid, rng: np.random.Generator, occupancy: float = 0.3) -> dict:
    p = np.zeros((*grid.shape, N_CHANNELS), np.float32)
    p[..., :3] = rng.uniform(0.1, 2.0, size=(*grid.shape, 3))
    p[..., 3:6] = rng.normal(size=(*grid.shape, 3))
    p[..., 6] = rng.uniform(0.3, 2.0, size=grid.shape)
    p[..., CH_ALPHA] = np.where(rng.uniform(size=grid.shape) < occupancy, rng.uniform(0.05, 1.0, size=grid.shape), 0)
    sky = (world_envmap_directions(16, 32) * 0.5 + 0.6).astype(np.float32)
    return dict(sky_world=sky, sun_dir=np.array([0.3, -0.2, 0.8]), sun_irradiance=np.array([40.0, 35.0, 30.0]),
                sun_half_angle_rad=0.05, grid=grid, params=p)


def _both(**fields) -> tuple[HybridLighting, HybridLighting]:
    """The same lighting on the numpy and on the torch backend."""
    tensors = {k: torch.from_numpy(np.array(v, np.float32)) for k, v in fields.items()
               if k in ("sky_world", "sun_irradiance", "params") and v is not None}
    return HybridLighting(**fields), HybridLighting(**{**fields, **tensors})


def _rays(rng: np.random.Generator, n: int, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:5] = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [0.6, 0.8, 0.0]]  # axis-parallel
    return rng.uniform(lo, hi, size=(n, 3)), d


def _assert_same(a: np.ndarray, b: torch.Tensor) -> None:
    assert isinstance(a, np.ndarray) and isinstance(b, torch.Tensor) and a.dtype == np.float32
    np.testing.assert_allclose(a, b.numpy(), rtol=RTOL, atol=ATOL)


def test_backend_follows_the_inputs_and_numpy_arrays_are_read_only():
    h_np, h_t = _both(**_random_volume(TINY, np.random.default_rng(0)))
    assert h_np._ops is NumpyBackend and h_t._ops is TorchBackend
    assert isinstance(h_np.radiance(np.zeros((2, 3)), np.eye(3)[:2]), np.ndarray)
    assert isinstance(h_t.radiance(np.zeros((2, 3)), np.eye(3)[:2]), torch.Tensor)
    with pytest.raises(ValueError, match="read-only"):
        h_np.params[..., CH_ALPHA] = 1.0
    mixed = HybridLighting(torch.from_numpy(h_np.sky_world.copy()), grid=TINY, params=np.array(h_np.params))
    assert mixed._ops is TorchBackend and isinstance(mixed.params, torch.Tensor)  # any tensor: all tensors


@pytest.mark.parametrize("grid, n_samples", [(TINY, 24), (L2_GRID, 128)])
def test_radiance_and_transmittance_match_the_torch_backend(grid, n_samples):
    rng = np.random.default_rng(1)
    fields = _random_volume(grid, rng, occupancy=0.3 if grid is TINY else 0.02)
    h_np, h_t = _both(**fields, n_samples=n_samples)
    lo, hi = grid.bounds()
    pts, d = _rays(rng, 3000, lo * 0.6, hi * 0.6)
    pts[:, 2] = np.abs(pts[:, 2])
    d[5] = h_np.sun_dir  # straight into the sun's disc
    for include_sun in (True, False):
        a, b = h_np.radiance(pts, d, include_sun), h_t.radiance(pts, d, include_sun)
        _assert_same(a, b)
    assert a.shape == (3000, 3) and np.abs(a - h_np.env_radiance(d, False)).max() > 0.1  # the volume did something
    _assert_same(h_np.transmittance(pts, d), h_t.transmittance(pts, d))
    _assert_same(h_np.env_radiance(d), h_t.env_radiance(torch.from_numpy(d)))
    for p in pts[:20]:
        assert h_np.sun_transmittance(p) == pytest.approx(h_t.sun_transmittance(p), abs=1e-6)
        np.testing.assert_array_equal(h_np.lift_out_of_solid(p), h_t.lift_out_of_solid(p))
    _assert_same(h_np.radiance(np.zeros((0, 3)), np.zeros((0, 3))), h_t.radiance(np.zeros((0, 3)), np.zeros((0, 3))))


def test_local_envmaps_match_and_the_cache_sees_new_arrays():
    rng = np.random.default_rng(2)
    h_np, h_t = _both(**_random_volume(TINY, rng))
    p = np.array([1.0, 0.5, 1.2])
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, -1.0, 0.0]])
    for rot in (None, R):
        a, b = h_np.envmap_at(p, 32, 64, rot), h_t.envmap_at(p, 32, 64, rot)
        assert a.dtype == b.dtype == np.float32 and a.shape == (32, 64, 3)
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL)
    first = h_np.envmap_at_cached(p, 32, 64)
    assert h_np.envmap_at_cached(p, 32, 64) is first
    h_np.params = np.array(h_np.params) * np.float32(2.0)  # a new array: a new version
    h_np.__post_init__()
    second = h_np.envmap_at_cached(p, 32, 64)
    assert second is not first and not np.allclose(second, first)
    assert len(h_np._envmap_cache) == 1  # the stale map (and the old array) dropped


def test_equirect_lookup_and_rotation_match_the_torch_version():
    rng = np.random.default_rng(3)
    env = rng.uniform(0, 5, (16, 32, 3)).astype(np.float32)
    d = rng.normal(size=(5000, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:3] = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]]  # poles, the seam
    got = sample_world_equirect(env, d)
    want = sample_world_equirect_torch(torch.from_numpy(env), torch.from_numpy(d)).numpy()
    assert isinstance(got, np.ndarray) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert isinstance(sample_world_equirect(torch.from_numpy(env), d), torch.Tensor)  # a tensor: the torch version
    R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    np.testing.assert_array_equal(world_to_frame_envmap(env, R, 8, 16), world_to_frame_envmap(torch.from_numpy(env), R,
                                                                                                8, 16))


def test_save_and_load_into_either_backend(tmp_path):
    h_np, h_t = _both(**_random_volume(TINY, np.random.default_rng(4)), n_samples=33)
    h_np.save(tmp_path)
    back_np, back_t = HybridLighting.load(tmp_path, as_tensors=False), HybridLighting.load(tmp_path)
    assert back_np._ops is NumpyBackend and back_t._ops is TorchBackend
    pts, d = _rays(np.random.default_rng(5), 200, -3, 3)
    _assert_same(back_np.radiance(pts, d), back_t.radiance(pts, d))
    np.testing.assert_allclose(back_np.radiance(pts, d), h_np.radiance(pts, d), rtol=5e-3, atol=5e-3)  # float16 file
    assert isinstance(empty_params(TINY, as_tensor=False), np.ndarray) and isinstance(empty_params(TINY), torch.Tensor)


# ----------------------------------------------------------------------------- the volumes the levels build


@pytest.fixture(scope="module")
def bundled_hybrids():
    from streetaug.augment.lighting.api import estimate_views_lighting
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    out = {}
    for scene, level in (("sample-sunny", "L2"), ("sample-lowsun", "L3")):
        s = reader.sample(reader.sample_tokens(scene)[0])
        est = estimate_views_lighting([s.cameras["CAM_FRONT"]], s.location, level, lidar=s.lidar, boxes=s.boxes)
        out[scene] = (est.hybrid, est.for_view(s.cameras["CAM_FRONT"]))
    return out


@pytest.mark.parametrize("scene", ["sample-sunny", "sample-lowsun"])
def test_the_levels_volumes_give_the_same_light_on_both_backends(bundled_hybrids, scene):
    hybrid, est = bundled_hybrids[scene]
    assert hybrid is not None and hybrid.params is not None and hybrid.seen is not None
    fields = {f.name: getattr(hybrid, f.name) for f in dataclasses.fields(hybrid) if f.init}
    arrays = {k: np.array(v.detach().numpy() if torch.is_tensor(v) else v) for k, v in fields.items()
              if k in ("sky_world", "sun_irradiance", "params") and v is not None}
    h_np, h_t = _both(**{**fields, **arrays})
    rng = np.random.default_rng(6)
    for p_cam in (np.array([0.0, 1.5, 12.0]), np.array([3.0, 1.5, 20.0]), np.array([-4.0, 1.0, 8.0])):
        p_vol = est.T_vol_from_cam[:3, :3] @ p_cam + est.T_vol_from_cam[:3, 3]
        q = h_np.lift_out_of_solid(p_vol)
        np.testing.assert_array_equal(q, h_t.lift_out_of_solid(p_vol))
        a, b = h_np.envmap_at(q, 64, 128), h_t.envmap_at(q, 64, 128)
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL * float(np.abs(b).max()))
        assert h_np.sun_transmittance(q) == pytest.approx(h_t.sun_transmittance(q), abs=1e-6)
    pts, d = _rays(rng, 20000, [-30, -30, 0.2], [30, 30, 8])
    _assert_same(h_np.transmittance(pts, d), h_t.transmittance(pts, d))
    a, b = h_np.radiance(pts, d), h_t.radiance(pts, d)
    np.testing.assert_allclose(a, b.numpy(), rtol=RTOL, atol=ATOL * float(np.abs(b.numpy()).max()))


# ----------------------------------------------------------------------------- the shading fit without scipy.optimize


def test_two_variable_nnls_equals_scipy():
    from scipy.optimize import nnls

    from streetaug.augment.lighting.build import nnls_2

    rng = np.random.default_rng(7)
    active = 0
    for trial in range(300):
        n = int(rng.integers(2, 60))
        X = np.abs(rng.normal(size=(n, 2))) * rng.uniform(0.1, 3.0, 2)
        if trial % 10 == 0:
            X[:, 1] = X[:, 0] * 0.5 + 1e-3 * rng.normal(size=n)  # nearly collinear
        y = X @ rng.normal(0.3, 1.0, 2) + 0.1 * rng.normal(size=n)
        want, _ = nnls(X, y)
        got = nnls_2(X, y)
        active += int(np.any(want == 0))
        assert np.all(got >= 0)
        # the same optimum: equal residuals (unique minimiser for full-rank X)
        r_got, r_want = np.sum((X @ got - y) ** 2), np.sum((X @ want - y) ** 2)
        assert r_got <= r_want * (1 + 1e-9) + 1e-12, trial
        if trial % 10:
            np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)
    assert 30 < active < 270  # both the interior and the constrained cases were exercised
    assert np.array_equal(nnls_2(np.zeros((5, 2)), np.ones(5)), [0.0, 0.0])


# ----------------------------------------------------------------------------- the blockwise march


def _dense_volume_chunk(h: HybridLighting, points: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1 over all (N, K) samples at once (the numpy backend before it marched in blocks): (radiance, tau_K)."""
    env = NumpyBackend.env_radiance(h, dirs, True)
    flat, alpha, _ = NumpyBackend.march(h, points, dirs)
    trans = np.cumprod(1.0 - alpha, axis=1)
    weight = alpha.copy()
    weight[:, 1:] *= trans[:, :-1]
    ray, k = np.nonzero(weight > 0)
    out = trans[:, -1:] * env
    vox = h.params.reshape(-1, N_CHANNELS)[flat[ray, k]]
    axis = vox[:, 3:6] / np.maximum(np.sqrt(np.einsum("ij,ij->i", vox[:, 3:6], vox[:, 3:6])), 1e-9)[:, None]
    cosang = -np.einsum("ij,ij->i", dirs[ray], axis)
    lobe = vox[:, :3] * np.exp(-(1.0 - cosang) / np.maximum(np.square(vox[:, 6]), 1e-6))[:, None]
    lobe *= weight[ray, k][:, None]
    first = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]])
    if len(ray):
        out[ray[first]] += np.add.reduceat(lobe, first, axis=0)
    return out, trans[:, -1]


@pytest.mark.parametrize("grid", [TINY, L2_GRID])
def test_blockwise_march_equals_compositing_all_samples(grid):
    """Dropping the rays that entered a solid voxel or climbed above the occupied layers changes nothing."""
    rng = np.random.default_rng(8)
    fields = _random_volume(grid, rng, occupancy=0.05)
    p = fields["params"]
    p[:, :, : grid.n_below, CH_ALPHA] = 1.0  # solid ground, as the levels build it
    p[:, :, grid.shape[2] // 2 :, CH_ALPHA] = 0.0  # nothing in the upper half
    h = HybridLighting(**fields, n_samples=100)  # K not a multiple of the block
    lo, hi = grid.bounds()
    pts, d = _rays(rng, 4000, [lo[0] * 0.5, lo[1] * 0.5, 0.1], [hi[0] * 0.5, hi[1] * 0.5, 0.3 * hi[2]])
    got, want = NumpyBackend.volume_chunk(h, pts.astype(np.float32), d.astype(np.float32), True), None
    want, tau_dense = _dense_volume_chunk(h, pts.astype(np.float32), d.astype(np.float32))
    np.testing.assert_array_equal(got, want)  # the same sums in the same order
    tau = h.transmittance(pts, d)
    np.testing.assert_allclose(tau, tau_dense, rtol=1e-6, atol=0)
    assert (tau == 0).mean() > 0.3 and (tau == 1).mean() > 0.2  # both early exits were taken
