"""The fast voxel look-up, interior fill, parameter assembly and sky carving against straightforward references.

The references are the earlier implementations (torch log projection, ``np.roll`` over the whole grid, dense
parameter tensors), kept here verbatim in spirit: the fast versions must give the same voxels and parameters
(exactly, or -- for the look-up, whose ``log1p`` now comes from numpy -- except for points within rounding of a
voxel boundary).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from streetaug.augment.lighting import build
from scipy import ndimage

from streetaug.augment.lighting.build import (
    ObservedVoxels,
    Surfaces,
    _propagate_inwards,
    assemble_params,
    observed_voxels,
    sky_carved,
    surfaces_and_normals,
)
from streetaug.augment.lighting.levels import L2_GRID, L3_GRID
from streetaug.augment.lighting.volume import CH_ALPHA, CH_AXIS, CH_COLOR, CH_SIGMA, N_CHANNELS, HybridLighting, LogGrid

TINY = LogGrid(shape=(6, 5, 4), half_extent_xy_m=10.0, z_min_m=-2.0, z_max_m=8.0, n_below=1,
               log_scale_xy_m=2.0, log_scale_z_m=1.0, centre_xy_m=(0.5, -0.3))
GRIDS = {"L3": L3_GRID, "L2": LogGrid(**{**L2_GRID.__dict__, "centre_xy_m": (7.5, -3.25)}), "tiny": TINY}


# ----------------------------------------------------------------------------- references (the old code)


def ref_axes(g: LogGrid, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    nx, ny, nz = g.shape
    cx, cy = g.centre_xy_m
    s, R = g.log_scale_xy_m, g.half_extent_xy_m
    k = 1.0 / math.log1p(R / s)

    def horiz(v, n):
        return 0.5 * n * (1.0 + torch.sign(v) * torch.log1p(v.abs() / s) * k)

    sz = g.log_scale_z_m
    z = points[..., 2]
    up = (nz - g.n_below) / math.log1p(g.z_max_m / sz) * torch.log1p(z.clamp(min=0.0) / sz)
    down = g.n_below / math.log1p(-g.z_min_m / sz) * torch.log1p((-z).clamp(min=0.0) / sz)
    return horiz(points[..., 0] - cx, nx), horiz(points[..., 1] - cy, ny), g.n_below + up - down


def ref_flat_index(g: LogGrid, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    inside = flat = None
    for a, n in zip(ref_axes(g, points), g.shape):
        a = torch.floor(a)
        ok = (a >= 0) & (a < n)
        inside = ok if inside is None else inside & ok
        a = a.clamp(0, n - 1)
        flat = a if flat is None else flat * n + a
    return flat.long(), inside


def ref_propagate_inwards(color, axis, known, occ, steps):
    color, axis, known = color.copy(), axis.copy(), known.copy()
    for _ in range(steps):
        todo = occ & ~known
        if not todo.any():
            break
        for a in range(3):
            for shift in (1, -1):
                src = np.roll(known, shift, axis=a)
                take = todo & src
                if take.any():
                    color[take] = np.roll(color, shift, axis=a)[take]
                    axis[take] = np.roll(axis, shift, axis=a)[take]
                    known |= take
                    todo &= ~take
    rest = occ & ~known
    if rest.any() and known.any():
        color[rest] = color[known].mean(axis=0)
        axis[rest] = (0.0, 0.0, 1.0)
    return color.reshape(-1, 3), axis.reshape(-1, 3)


def ref_assemble_params(grid, occ, obs, surf, shaded):
    n = grid.n_voxels
    params = torch.zeros((*grid.shape, N_CHANNELS), dtype=torch.float32)
    params[..., CH_ALPHA] = torch.from_numpy(occ.astype(np.float32))
    color = np.zeros((n, 3))
    color[surf.idx] = shaded
    obs_idx = np.flatnonzero(obs.observed.reshape(-1))
    color[obs_idx] = obs.obs_rgb[obs_idx]
    axis = np.zeros((n, 3))
    axis[surf.idx] = surf.normals
    vdir = obs.dir_sum[obs_idx] / np.maximum(np.linalg.norm(obs.dir_sum[obs_idx], axis=1, keepdims=True), 1e-9)
    axis[obs_idx] = vdir
    known = np.zeros(n, bool)
    known[surf.idx] = True
    known[obs_idx] = True
    color, axis = ref_propagate_inwards(color.reshape(*grid.shape, 3), axis.reshape(*grid.shape, 3),
                                        known.reshape(grid.shape), occ, steps=build.THICKEN_VOXELS + 1)
    flat_p = params.reshape(-1, N_CHANNELS)
    flat_p[:, CH_COLOR] = torch.from_numpy(color.astype(np.float32))
    axis = np.where(np.linalg.norm(axis, axis=1, keepdims=True) > 1e-6, axis, np.array([0.0, 0.0, 1.0]))
    flat_p[:, CH_AXIS] = torch.from_numpy(axis.astype(np.float32))
    flat_p[:, CH_SIGMA] = build.SIGMA_SURFACE
    return params


def ref_sky_carved(grid, observations, stride=build.SKY_CARVE_STRIDE, n_samples=build.SKY_CARVE_SAMPLES):
    carved = np.zeros(grid.n_voxels, bool)
    lo, hi = grid.bounds()
    frac = ((np.arange(n_samples) + 0.5) / n_samples) ** 2
    for o in observations:
        d = o.far_dirs[o.far_is_sky][::stride]
        if not len(d):
            continue
        c = np.asarray(o.camera_centre, np.float64)
        safe = np.where(np.abs(d) < 1e-12, 1e-12, d)
        t_exit = np.maximum((lo - c) / safe, (hi - c) / safe).min(axis=1).clip(min=0.0)
        pos = c[None, None] + (t_exit[:, None] * frac[None])[..., None] * d[:, None, :]
        flat, inside = ref_flat_index(grid, torch.from_numpy(pos.reshape(-1, 3)))
        carved[flat.numpy()[inside.numpy()]] = True
    return carved.reshape(grid.shape)


def ref_observed_voxels(grid, observations):
    X, Y, Z = grid.shape
    n = grid.n_voxels
    pts = np.concatenate([o.points for o in observations])
    rgb = np.concatenate([o.radiance for o in observations]).astype(np.float64)
    vd = np.concatenate([o.view_dirs for o in observations])
    cap = np.concatenate([o.capped for o in observations])
    pts = pts.copy()
    pts[pts[:, 2] < build.GROUND_SNAP_M, 2] = -0.05
    flat, inside = ref_flat_index(grid, torch.from_numpy(pts))
    flat, inside = flat.numpy(), inside.numpy()
    flat, rgb, vd = flat[inside], rgb[inside], vd[inside]
    count = np.bincount(flat, minlength=n).astype(np.float64)
    col_sum = np.stack([np.bincount(flat, rgb[:, c], minlength=n) for c in range(3)], axis=1)
    dir_sum = np.stack([np.bincount(flat, vd[:, c], minlength=n) for c in range(3)], axis=1)
    cam_top = np.full((X, Y), -np.inf)
    cam_capped = np.zeros((X, Y), bool)
    cf = flat // Z
    np.maximum.at(cam_top.reshape(-1), cf, pts[inside, 2])
    cam_capped.reshape(-1)[cf[cap[inside]]] = True
    return ObservedVoxels((count > 0).reshape(grid.shape), col_sum / np.maximum(count, 1)[:, None], dir_sum, cam_top,
                          cam_capped)


def ref_surfaces_and_normals(grid, occ):
    free = ~occ
    nb_free = np.zeros_like(occ)
    for a in range(3):
        nb_free |= np.roll(free, 1, axis=a) | np.roll(free, -1, axis=a)
    surface = occ & nb_free
    surface[:, :, : grid.n_below - 1] = False
    blurred = ndimage.gaussian_filter(occ.astype(np.float32), 1.0)
    sizes = [np.diff(e) for e in grid.axis_edges()]
    g = np.gradient(blurred)
    normal = -np.stack([g[0] / sizes[0][:, None, None], g[1] / sizes[1][None, :, None], g[2] / sizes[2][None, None, :]],
                       -1)
    normal[:, :, : grid.n_below] = (0.0, 0.0, 1.0)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-9)
    return surface, normal


# ----------------------------------------------------------------------------- helpers


def _points(g: LogGrid, n: int, rng: np.random.Generator) -> np.ndarray:
    """Points around and beyond the grid, dense near its centre, some exactly on z = 0 and on the centre lines."""
    lo, hi = g.bounds()
    cx, cy = g.centre_xy_m
    R = g.half_extent_xy_m
    p = np.concatenate([rng.normal([cx, cy, 1.0], [R / 5, R / 5, 5.0], (n // 2, 3)),
                        rng.uniform(lo - 0.2 * R, hi + 0.2 * R, (n - n // 2, 3))])
    p[:50, 2] = 0.0
    p[50:80, 0] = cx
    p[80:110, 1] = cy
    return p


def _near_boundary(g: LogGrid, p: np.ndarray, tol: float) -> np.ndarray:
    """(N,) bool: some axis' exact (float64) continuous index lies within ``tol`` of an integer."""
    idx = ref_axes(g, torch.from_numpy(p.astype(np.float64)))
    return np.any([np.abs(a.numpy() - np.round(a.numpy())) < tol for a in idx], axis=0)


# ----------------------------------------------------------------------------- look-up


@pytest.mark.parametrize("name", sorted(GRIDS))
def test_flat_index_float64_matches_the_torch_reference(name):
    g = GRIDS[name]
    p = _points(g, 200_000, np.random.default_rng(1))
    flat, inside = g.flat_index(torch.from_numpy(p))
    rf, ri = ref_flat_index(g, torch.from_numpy(p))
    assert flat.dtype == torch.int64 and inside.dtype == torch.bool and flat.shape == (len(p),)
    diff = (flat != rf).numpy() | (inside != ri).numpy()
    assert diff.sum() <= 2  # a log1p ulp apart, only where a point sits on a voxel boundary
    assert np.all(_near_boundary(g, p[diff], 1e-9))
    assert int(flat.max()) < g.n_voxels and int(flat.min()) >= 0
    assert inside.sum() > 0.5 * len(p) and (~inside).sum() > 1000


@pytest.mark.parametrize("name", sorted(GRIDS))
def test_flat_index_float32_matches_the_torch_reference(name):
    g = GRIDS[name]
    p = _points(g, 200_000, np.random.default_rng(2)).astype(np.float32)
    flat, inside = g.flat_index(torch.from_numpy(p))
    rf, ri = ref_flat_index(g, torch.from_numpy(p))
    diff = (flat != rf).numpy() | (inside != ri).numpy()
    assert diff.sum() <= 20
    assert np.all(_near_boundary(g, p[diff], 1e-4))


def test_flat_index_keeps_the_shape_and_takes_numpy_and_axes():
    g = TINY
    p = _points(g, 600, np.random.default_rng(3)).reshape(20, 30, 3)
    flat, inside = g.flat_index(p)  # numpy in, numpy out
    rf, ri = ref_flat_index(g, torch.from_numpy(p))
    assert isinstance(flat, np.ndarray) and flat.dtype == np.int64 and inside.dtype == bool
    assert flat.shape == (20, 30) and np.array_equal(flat, rf.numpy()) and np.array_equal(inside, ri.numpy())
    f2, i2 = g.flat_index_xyz(p[..., 0], p[..., 1], p[..., 2])
    assert np.array_equal(f2, flat) and np.array_equal(i2, inside)
    single, ok = g.flat_index(torch.tensor([0.5, -0.3, 1.0], dtype=torch.float64))
    assert single.shape == () and bool(ok)


def test_flat_index_in_blocks_equals_one_block(monkeypatch):
    g = L3_GRID
    p = _points(g, 10_000, np.random.default_rng(4))
    whole = g.flat_index(p)
    monkeypatch.setattr("streetaug.augment.lighting.volume.INDEX_CHUNK", 777)
    blocks = g.flat_index(p)
    assert np.array_equal(whole[0], blocks[0]) and np.array_equal(whole[1], blocks[1])


@pytest.mark.parametrize("name", sorted(GRIDS))
def test_to_index_matches_the_torch_reference(name):
    g = GRIDS[name]
    p = _points(g, 50_000, np.random.default_rng(5))
    new = g.to_index(torch.from_numpy(p))
    ref = torch.stack(ref_axes(g, torch.from_numpy(p)), dim=-1)
    assert new.dtype == torch.float64 and new.shape == p.shape
    np.testing.assert_allclose(new.numpy(), ref.numpy(), rtol=0, atol=1e-11)
    new32 = g.to_index(torch.from_numpy(p.astype(np.float32)))
    assert new32.dtype == torch.float32
    np.testing.assert_allclose(new32.numpy(), ref.numpy(), rtol=0, atol=1e-4)


def test_march_matches_the_reference_positions():
    g = L3_GRID
    rng = np.random.default_rng(6)
    params = torch.zeros((*g.shape, N_CHANNELS))
    params[..., CH_ALPHA] = torch.from_numpy((rng.uniform(size=g.shape) < 0.3).astype(np.float32))
    hl = HybridLighting(torch.ones(8, 16, 3), grid=g, params=params, n_samples=48)
    pts = torch.from_numpy(rng.normal([0, 0, 2], [20, 20, 3], (3000, 3)).astype(np.float32))
    d = torch.from_numpy(rng.normal(size=(3000, 3)).astype(np.float32))
    d = d / d.norm(dim=1, keepdim=True)
    d[:10] = torch.tensor([0.0, 0.0, 1.0])  # axis-parallel rays
    flat, alpha, inside = hl._march(pts, d)
    lo, hi = (torch.as_tensor(b, dtype=pts.dtype) for b in g.bounds())
    safe = torch.where(d.abs() < 1e-12, torch.full_like(d, 1e-12), d)
    t_exit = torch.maximum((lo - pts) / safe, (hi - pts) / safe).min(dim=1).values.clamp(min=0.0)
    t = t_exit[:, None] * ((torch.arange(48, dtype=pts.dtype) + 0.5) / 48)[None]
    pos = pts[:, None, :] + t[..., None] * d[:, None, :]
    rf, ri = ref_flat_index(g, pos)
    diff = (flat != rf) | (inside != ri)
    assert flat.shape == (3000, 48) and int(diff.sum()) <= 5
    assert torch.equal(alpha[~diff], (params.reshape(-1, N_CHANNELS)[:, CH_ALPHA][rf] * ri)[~diff])


# ----------------------------------------------------------------------------- interior fill, parameters, carving


@pytest.mark.parametrize("seed", range(6))
def test_propagate_inwards_equals_the_roll_reference(seed):
    rng = np.random.default_rng(seed)
    shape = [(9, 7, 5), (16, 16, 8), (3, 4, 2), (12, 10, 6), (20, 5, 4), (8, 8, 8)][seed]
    occ = rng.uniform(size=shape) < rng.uniform(0.3, 0.9)
    known = occ & (rng.uniform(size=shape) < rng.uniform(0.02, 0.4))
    if seed == 5:
        known[:] = False  # nothing known: nothing to copy, no mean colour
    known |= rng.uniform(size=shape) < 0.02  # some known voxels outside the occupancy
    color = rng.uniform(0, 3, (*shape, 3)) * known[..., None]
    axis = rng.normal(size=(*shape, 3)) * known[..., None]
    before = (color.copy(), axis.copy(), known.copy())
    for steps in (1, 3, 6):
        c, a = _propagate_inwards(color, axis, known, occ, steps)
        rc, ra = ref_propagate_inwards(color, axis, known, occ, steps)
        assert c.shape == (np.prod(shape), 3) and np.array_equal(c, rc) and np.array_equal(a, ra)
    assert all(np.array_equal(x, y) for x, y in zip(before, (color, axis, known)))  # inputs untouched


def _synthetic_scene(grid: LogGrid, rng: np.random.Generator):
    occ = rng.uniform(size=grid.shape) < 0.25
    occ[:, :, : grid.n_below] = True
    observed = occ & (rng.uniform(size=grid.shape) < 0.1)
    n = grid.n_voxels
    obs = ObservedVoxels(observed, rng.uniform(0, 2, (n, 3)) * observed.reshape(-1, 1),
                         rng.normal(size=(n, 3)) * observed.reshape(-1, 1), np.zeros(grid.shape[:2]),
                         np.zeros(grid.shape[:2], bool))
    surface = occ & (rng.uniform(size=grid.shape) < 0.3)
    idx = np.flatnonzero(surface.reshape(-1))
    normals = rng.normal(size=(len(idx), 3))
    normals[::7] = 0.0  # degenerate normals -> +z
    normals[1::7] *= 1e-8
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1.0)
    s = len(idx)
    surf = Surfaces(idx, normals, np.ones((s, 3)), np.zeros(s, bool), observed.reshape(-1)[idx], np.zeros(s),
                    np.zeros(s), np.zeros(s))
    return occ, obs, surf, rng.uniform(0, 1, (s, 3))


@pytest.mark.parametrize("grid", [TINY, LogGrid(shape=(24, 20, 10)), L2_GRID])
def test_assemble_params_equals_the_dense_reference(grid):
    occ, obs, surf, shaded = _synthetic_scene(grid, np.random.default_rng(7))
    new = assemble_params(grid, occ, obs, surf, shaded)
    ref = ref_assemble_params(grid, occ, obs, surf, shaded)
    assert new.dtype == np.float32 and new.shape == (*grid.shape, N_CHANNELS)
    assert np.array_equal(new, ref.numpy())


def test_sky_carved_equals_the_reference():
    g = L3_GRID
    rng = np.random.default_rng(8)
    obs = []
    for centre in ([0.0, 0.0, 1.8], [4.0, -1.0, 1.6]):
        d = rng.normal(size=(6000, 3))
        d[:, 2] = np.abs(d[:, 2]) + 0.05
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d[:4] = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.8, 0.0]]
        obs.append(SimpleNamespace(far_dirs=d, far_is_sky=rng.uniform(size=len(d)) < 0.8,
                                   camera_centre=np.array(centre)))
    obs.append(SimpleNamespace(far_dirs=np.zeros((0, 3)), far_is_sky=np.zeros(0, bool),
                               camera_centre=np.zeros(3)))
    new = sky_carved(g, obs)
    ref = ref_sky_carved(g, obs)
    assert new.shape == g.shape and new.sum() > 1000
    assert int((new != ref).sum()) <= 2  # at most a boundary voxel from a log1p ulp


@pytest.mark.parametrize("all_inside", [False, True])
def test_observed_voxels_equals_the_reference(all_inside):
    g = L3_GRID
    rng = np.random.default_rng(9)
    obs = []
    for m in (40_000, 7_000):
        p = _points(g, m, rng)
        if all_inside:
            p = p[ref_flat_index(g, torch.from_numpy(p))[1].numpy()]
        d = rng.normal(size=(len(p), 3))
        obs.append(SimpleNamespace(points=p, radiance=rng.uniform(0, 4, (len(p), 3)).astype(np.float32),
                                   view_dirs=d / np.linalg.norm(d, axis=1, keepdims=True),
                                   capped=rng.uniform(size=len(p)) < 0.1, free_points=None))
    new, ref = observed_voxels(g, obs), ref_observed_voxels(g, obs)
    assert new.observed.sum() > 1000
    for f in ("observed", "obs_rgb", "dir_sum", "cam_top_m", "cam_capped"):
        a, b = getattr(new, f), getattr(ref, f)
        assert a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b), f


@pytest.mark.parametrize("grid", [TINY, LogGrid(shape=(24, 20, 10)), L2_GRID])
def test_surfaces_and_normals_equal_the_reference(grid):
    rng = np.random.default_rng(10)
    occ = ndimage.binary_dilation(rng.uniform(size=grid.shape) < 0.05, iterations=1)
    occ[:, :, : grid.n_below] = True
    s, nrm = surfaces_and_normals(grid, occ)
    rs, rn = ref_surfaces_and_normals(grid, occ)
    assert np.array_equal(s, rs) and nrm.dtype == rn.dtype and nrm.shape == rn.shape
    # numpy's norm sums the squares in an order that depends on the array's size: equal to an ulp or two
    np.testing.assert_allclose(nrm, rn, rtol=0, atol=1e-15)
