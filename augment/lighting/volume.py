"""The hybrid lighting representation of the paper: an HDR sky dome + a volumetric spherical-Gaussian (VSG) volume.

Everything here lives in one z-up *volume frame* (metres; in practice the ego frame of the reference camera,
shifted so that the origin is on the ground under that camera: x forward, y left, z up, ground at z = 0).
Radiance is linear RGB on one radiometric scale (the reference image's).

Two backends, chosen by what :class:`HybridLighting` is built from (numpy in, numpy out; tensors in, tensors
out): numpy float32 arrays (what the pipeline builds; :class:`NumpyBackend`, no torch import), or torch tensors
(:mod:`.volume_torch`, imported only then), differentiable with respect to the sky dome, the sun irradiance and
the volume parameters. Both give the same radiance to float32 rounding (tests/lighting/test_volume_numpy_backend.py).

* **Sky dome** ``sky_world``: (H, W, 3) equirect map in the world (z-up) convention of
  :mod:`streetaug.augment.core` (``lon = atan2(dy, dx)``, ``lat = asin(dz)``), sun disc excluded; the
  sun is analytic (direction, irradiance, angular radius) and added by the radiance query where a ray
  falls inside its disc.
* **VSG volume** ``params``: (X, Y, Z, 8) channels-last array, per voxel ``[c_r, c_g, c_b, mu_x, mu_y, mu_z,
  sigma, alpha]``: the lobe ``G(l) = c exp(-(1 - l . mu / |mu|) / sigma^2)`` (c: RGB amplitude, mu: axis,
  sigma: sharpness, larger = broader) and the occupancy ``alpha`` in [0, 1].
* **Log-projected grid** (:class:`LogGrid`): voxel i along x spans ``[i, i + 1)`` of the continuous index
  ``n/2 (1 + sign(x') log(1 + |x'|/s) / log(1 + R/s))``, ``x' = x - centre_x`` (dense near the centre, as
  the paper's 256 x 256 x 64 grid over 300 x 300 x 80 m); along z the same with separate log ramps below and
  above z = 0, so that z = 0 (the ground) is exactly a voxel boundary.
* **Radiance query** (paper Eq. 1): K equi-spaced samples at ``t_k = (k - 1/2) t_exit / K`` between the
  point and where the ray leaves the grid, nearest-neighbour voxel lookup, alpha compositing, then the sky:
  ``L(x, l) = sum_k tau_{k-1} alpha_k G(-l; xi_k) + tau_K L_env(l)``, ``tau_k = prod_{i<=k} (1 - alpha_i)``.
* **Seen surfaces** ``seen`` (optional, :mod:`.seen_surfaces`): the input cameras' depth meshes textured with
  their pixels. A ray that hits one takes the hit's pixel radiance; only the rays that miss every mesh go
  through Eq. 1 (the mesh is the precise geometry of what was seen: on scene-0916 letting voxels in front of
  the hit still block -- 25 % or 50 % of the hit distance -- lost 0.2-0.8 dB on the novel view and 1-7 dB on
  the self view). The mesh radiance is a constant; the rest stays differentiable.
  A camera's sky mesh (its sky pixels at 10 km, :mod:`.seen_surfaces`) is the exception: it replaces the dome
  behind the volume along the ray, and is blended in front of it by how near the ray's origin is to that camera
  (:func:`sky_preempt_weight`).
  :meth:`HybridLighting.transmittance` (sun visibility, shadows) is the volume's alone.
"""

from __future__ import annotations

import functools
import math
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core import (
    InputError,
    camera_envmap_directions,
    check_rays,
    check_shape,
    equirect_pixel_lonlat,
    lonlat_to_world_dir,
    read_exr,
    read_json,
    write_bytes_atomic,
    write_exr,
    write_json_atomic,
)
from .seen_surfaces import SeenSurfaces
from .sky_preempt import SKY_HIT_FRACTION, SKY_PREEMPT_BASELINE_M, sky_preempt_weight, through_volume  # noqa: F401
from .view_blur import uncertainty_blurred_equirect
from .volume_channels import CH_ALPHA, CH_AXIS, CH_COLOR, CH_SIGMA, N_CHANNELS  # noqa: F401 (re-exported)

if TYPE_CHECKING:
    import torch

DEFAULT_SAMPLES = 128
ENVMAP_CACHE_SIZE = 32  # local env maps kept per HybridLighting (a sample has a handful of objects)
CHUNK_RAYS = 16384
INDEX_CHUNK = 65536  # points per block of the voxel look-up (fits the cache)
MARCH_BLOCK = 16  # samples per ray marched at a time by the numpy backend (then finished rays are dropped)
TOP_MARGIN_M = 0.01  # a sample this far above the highest occupied layer is certainly in empty space
VOLUME_SCHEMA = "streetaug.hybrid_lighting/1"


def sky_blend(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray, include_sun: bool, hit: np.ndarray,
              t: np.ndarray, mesh_rgb: np.ndarray, spread: np.ndarray, volume_chunk) -> np.ndarray:
    """numpy radiance (N, 3) of rays after the seen-surface trace (hit, t, mesh_rgb, spread: its results): the seen
    surface where one is hit; elsewhere Eq. 1 (``volume_chunk``), behind which a sky-mesh hit's pixel replaces the
    dome, blended with that pixel in front by :func:`sky_preempt_weight`."""
    to_volume, sky = through_volume(hit, t)
    out = mesh_rgb.copy()
    miss = np.flatnonzero(to_volume)
    if len(miss):
        vol = np.asarray(volume_chunk(h, points[miss], dirs[miss], include_sun, (sky[miss], mesh_rgb[miss])))
        w = sky_preempt_weight(sky[miss], t[miss], spread[miss])[:, None]
        out[miss] = w * mesh_rgb[miss] + (1.0 - w) * vol
    return out


# ----------------------------------------------------------------------------- grid


@dataclass(frozen=True)
class LogGrid:
    """A log-projected voxel grid in the volume frame.

    Attributes:
        shape: (X, Y, Z) voxels.
        half_extent_xy_m: the grid covers ``centre +- half_extent`` in x and y.
        z_min_m, z_max_m: vertical extent (z_min < 0 < z_max; z = 0 is the ground).
        n_below: voxel layers below z = 0.
        log_scale_xy_m, log_scale_z_m: distance s where the projection turns from linear to logarithmic.
        centre_xy_m: (x, y) of the grid's densest point.
    """

    shape: tuple[int, int, int] = (128, 128, 32)
    half_extent_xy_m: float = 150.0
    z_min_m: float = -4.0
    z_max_m: float = 76.0
    n_below: int = 2
    log_scale_xy_m: float = 4.0
    log_scale_z_m: float = 2.0
    centre_xy_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        nx, ny, nz = self.shape
        if min(nx, ny) < 2 or nz < self.n_below + 1 or self.n_below < 1:
            raise ValueError(f"LogGrid: shape {self.shape} too small for n_below={self.n_below}")
        if not self.z_min_m < 0.0 < self.z_max_m or self.half_extent_xy_m <= 0:
            raise ValueError(f"LogGrid: need z_min < 0 < z_max and a positive extent, got {self}")

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.shape))

    def to_index(self, points: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
        """Continuous voxel coordinates (..., 3) of points (..., 3) in the volume frame (voxel i spans [i, i+1)).

        Not differentiable (numpy; the points' dtype is kept, float64 for non-float input); a tensor for a
        tensor, else a numpy array."""
        p = _coordinates(points)
        q = p.reshape(-1, 3)
        return _like(points, np.stack(self._axes(q[:, 0], q[:, 1], q[:, 2]), axis=-1).reshape(p.shape))

    def _axes(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Continuous voxel coordinates along x, y, z (new arrays) of coordinate arrays of one shape and float dtype.

        numpy, in place on fresh arrays: its vectorised ``log1p`` is ~10x torch's on the CPU (voxel look-ups of
        a million points are the volume build's and the ray march's main cost)."""
        nx, ny, nz = self.shape
        cx, cy = self.centre_xy_m
        s, R = self.log_scale_xy_m, self.half_extent_xy_m
        k = 1.0 / math.log1p(R / s)

        def horiz(v: np.ndarray, centre: float, n: int) -> np.ndarray:
            v = np.subtract(v, centre, dtype=v.dtype)
            a = np.abs(v)
            a /= s
            np.log1p(a, out=a)
            np.copysign(a, v, out=a)
            a *= k
            a += 1.0
            a *= 0.5 * n
            return a

        sz = self.log_scale_z_m
        # one log ramp above z = 0 and one below: n_below + up_k max(l, 0) + down_k min(l, 0), l = +-log1p(|z| / sz)
        up_k = (nz - self.n_below) / math.log1p(self.z_max_m / sz)
        down_k = self.n_below / math.log1p(-self.z_min_m / sz)
        az = np.abs(z)
        az /= sz
        np.log1p(az, out=az)
        np.copysign(az, z, out=az)
        up = np.maximum(az, 0.0)
        up *= up_k
        np.minimum(az, 0.0, out=az)
        az *= down_k
        az += up
        az += self.n_below
        return horiz(x, cx, nx), horiz(y, cy, ny), az

    def flat_index(self, points: np.ndarray | torch.Tensor) -> tuple[np.ndarray, np.ndarray] | tuple[torch.Tensor, torch.Tensor]:
        """Nearest-neighbour voxel of points (..., 3): (flat index (...) int64, inside mask (...) bool).

        Points outside the grid get a clamped (valid) index and ``inside = False``. Tensors for a tensor, else
        numpy arrays.
        """
        p = _coordinates(points)
        q = p.reshape(-1, 3)
        flat, inside = self.flat_index_xyz(q[:, 0], q[:, 1], q[:, 2])
        return _like(points, flat.reshape(p.shape[:-1])), _like(points, inside.reshape(p.shape[:-1]))

    def flat_index_xyz(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`flat_index` of points given as three numpy coordinate arrays of one shape (saves stacking
        them): numpy arrays."""
        dtype = np.float64 if self.n_voxels >= 2**24 else np.result_type(x.dtype, np.float32)  # exact integers
        shape = np.shape(x)
        x, y, z = (np.asarray(v, dtype=dtype).reshape(-1) for v in (x, y, z))
        flat = np.empty(len(x), np.int64)
        inside = np.empty(len(x), bool)
        for i in range(0, len(x), INDEX_CHUNK):  # cache-sized blocks
            part = slice(i, i + INDEX_CHUNK)
            f, ok = None, None
            for a, n in zip(self._axes(x[part], y[part], z[part]), self.shape):
                np.floor(a, out=a)
                c = np.clip(a, 0, n - 1)
                ok = c == a if ok is None else np.logical_and(ok, c == a, out=ok)
                if f is None:
                    f = c
                else:
                    f *= n
                    f += c
            flat[part] = f
            inside[part] = ok
        return flat.reshape(shape), inside.reshape(shape)

    def index_to_point(self, index: np.ndarray) -> np.ndarray:
        """Volume-frame points (..., 3) at continuous voxel coordinates (..., 3) (inverse of :meth:`to_index`)."""
        index = np.asarray(index, dtype=np.float64)
        nx, ny, nz = self.shape
        s, R = self.log_scale_xy_m, self.half_extent_xy_m

        def horiz(i: np.ndarray, n: int) -> np.ndarray:
            u = 2.0 * i / n - 1.0
            return np.sign(u) * s * np.expm1(np.abs(u) * np.log1p(R / s))

        sz = self.log_scale_z_m
        iz = index[..., 2]
        up = sz * np.expm1((iz - self.n_below) / (nz - self.n_below) * np.log1p(self.z_max_m / sz))
        down = -sz * np.expm1((self.n_below - iz) / self.n_below * np.log1p(-self.z_min_m / sz))
        z = np.where(iz >= self.n_below, up, down)
        cx, cy = self.centre_xy_m
        return np.stack([horiz(index[..., 0], nx) + cx, horiz(index[..., 1], ny) + cy, z], axis=-1)

    def voxel_centres(self) -> np.ndarray:
        """(X, Y, Z, 3) float64 volume-frame centres of all voxels (centre of the index cell); read-only, cached."""
        return _voxel_centres(self)

    def axis_edges(self) -> list[np.ndarray]:
        """Voxel boundaries along x, y, z: three arrays of lengths X+1, Y+1, Z+1 (metres)."""
        out = []
        for a, n in enumerate(self.shape):
            idx = np.zeros((n + 1, 3))
            idx[:, a] = np.arange(n + 1)
            idx[:, [b for b in range(3) if b != a]] = np.array([self.shape[b] / 2 for b in range(3) if b != a])
            out.append(self.index_to_point(idx)[:, a])
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo (3,), hi (3,)) of the grid's box, metres."""
        cx, cy = self.centre_xy_m
        R = self.half_extent_xy_m
        return np.array([cx - R, cy - R, self.z_min_m]), np.array([cx + R, cy + R, self.z_max_m])

    def to_json(self) -> dict:
        d = asdict(self)
        d["shape"] = list(self.shape)
        d["centre_xy_m"] = list(self.centre_xy_m)
        return d

    @staticmethod
    def from_json(d: dict) -> "LogGrid":
        d = dict(d)
        d["shape"] = tuple(int(v) for v in d["shape"])
        d["centre_xy_m"] = tuple(float(v) for v in d["centre_xy_m"])
        return LogGrid(**d)


@functools.lru_cache(maxsize=4)
def _voxel_centres(grid: LogGrid) -> np.ndarray:
    grids = np.meshgrid(*[np.arange(n) + 0.5 for n in grid.shape], indexing="ij")
    out = grid.index_to_point(np.stack(grids, axis=-1))
    out.flags.writeable = False
    return out


# ----------------------------------------------------------------------------- sky


@functools.lru_cache(maxsize=8)
def world_envmap_directions(height: int, width: int) -> np.ndarray:
    """Unit z-up direction (H, W, 3) float64 of every pixel centre of a world-convention equirect map; read-only,
    cached (the sky dome, its irradiance and every local env map use the same few sizes)."""
    lon, lat = equirect_pixel_lonlat(height, width)
    out = lonlat_to_world_dir(lon, lat)
    out.flags.writeable = False
    return out


def world_to_frame_envmap(env_world: np.ndarray | torch.Tensor, R_vol_from_frame: np.ndarray, height: int,
                          width: int) -> np.ndarray:
    """A world-convention (H, W, C) map resampled (bilinear) into the camera-convention map (height, width, C) of
    the frame whose directions rotate into the volume frame by ``R_vol_from_frame`` (float32, numpy)."""
    d = camera_envmap_directions(height, width).reshape(-1, 3) @ np.asarray(R_vol_from_frame, np.float64).T
    env = np.asarray(as_numpy(env_world), np.float32)
    out = sample_world_equirect(env, d.astype(np.float32))
    return out.reshape(height, width, -1).astype(np.float32, copy=False)


def sample_world_equirect(env: np.ndarray | torch.Tensor, dirs: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """Bilinear lookup (N, C) of a world-convention (H, W, C) map at unit directions (N, 3); wraps in longitude.

    numpy arrays (in the dtype of ``env`` and ``dirs``), or tensors (differentiable, :mod:`.volume_torch`) if
    either is one."""
    if _is_tensor(env) or _is_tensor(dirs):
        from .volume_torch import TorchBackend, sample_world_equirect as sample_torch

        return sample_torch(TorchBackend.array(env), TorchBackend.array(dirs))
    H, W = env.shape[:2]
    lon = np.arctan2(dirs[:, 1], dirs[:, 0])
    lat = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
    x = np.remainder(lon / (2 * math.pi) + 0.5, 1.0) * W - 0.5
    y = np.clip((0.5 - lat / math.pi) * H - 0.5, 0.0, H - 1.0)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    y1 = np.minimum(y0 + 1, H - 1)
    x0w = np.remainder(x0, W)
    x1w = np.remainder(x0 + 1, W)
    top = env[y0, x0w] * (1 - fx) + env[y0, x1w] * fx
    bottom = env[y1, x0w] * (1 - fx) + env[y1, x1w] * fx
    return top * (1 - fy) + bottom * fy


# ----------------------------------------------------------------------------- backends


class NumpyBackend:
    """Eq. 1 and the transmittance on numpy arrays (no gradients; same results as :mod:`.volume_torch` to float32
    rounding). Each function takes the :class:`HybridLighting` and a chunk of rays (N, 3) in its dtype."""

    is_tensor = False

    @staticmethod
    def array(x, dtype: np.dtype | None = None) -> np.ndarray:
        """``x`` as a numpy array (no copy where possible), of ``dtype`` if given."""
        return np.asarray(as_numpy(x), dtype=dtype)

    @staticmethod
    def rays(points, dirs, dtype: np.dtype) -> tuple[np.ndarray, np.ndarray]:
        """Points and directions (N, 3) as arrays of ``dtype`` (ValueError on other shapes)."""
        points, dirs = NumpyBackend.array(points, dtype), NumpyBackend.array(dirs, dtype)
        check_rays(points, dirs)
        return points, dirs

    @staticmethod
    def cat(parts: list[np.ndarray], empty_shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
        return np.concatenate(parts) if parts else np.zeros(empty_shape, dtype=dtype)

    @staticmethod
    def ones(n: int, dtype: np.dtype) -> np.ndarray:
        return np.ones(n, dtype=dtype)

    @staticmethod
    def env_radiance(h: "HybridLighting", dirs: np.ndarray, include_sun: bool) -> np.ndarray:
        rgb = sample_world_equirect(h.sky_world, dirs)
        if include_sun and h.sun_dir is not None:
            in_disc = (dirs @ h.sun_dir.astype(dirs.dtype)) >= math.cos(h.sun_half_angle_rad)
            rgb = rgb + in_disc[:, None] * (h.sun_irradiance / h.sun_solid_angle_sr)[None]
        return rgb

    @staticmethod
    def _sample_t(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t_exit (N,), frac (K,)): sample k of a ray lies at ``t_exit * frac[k]``."""
        lo, hi = (b.astype(points.dtype) for b in h.grid.bounds())
        safe = np.where(np.abs(dirs) < 1e-12, dirs.dtype.type(1e-12), dirs)
        t_hi = np.maximum((lo - points) / safe, (hi - points) / safe)
        t_exit = np.maximum(t_hi.min(axis=1), 0.0)  # (N,)
        K = h.n_samples
        return t_exit, (np.arange(K, dtype=points.dtype) + 0.5) / K

    @staticmethod
    def march(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t_exit, frac = NumpyBackend._sample_t(h, points, dirs)
        t = t_exit[:, None] * frac[None]
        flat, inside = h.grid.flat_index_xyz(*(points[:, a, None] + t * dirs[:, a, None] for a in range(3)))
        alpha = h._alpha_flat().take(flat)
        np.multiply(alpha, inside, out=alpha)
        return flat, alpha, inside

    @staticmethod
    def march_weights(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray,
                      need_weights: bool = True) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """Eq. 1's compositing along rays: (tau_K (N,), and the samples with a weight ``tau_{k-1} alpha_k > 0``:
        ray (M,), flat voxel (M,), weight (M,), sorted by ray then sample).

        The same numbers as compositing :meth:`march`'s (N, K) samples at once, computed in blocks of
        ``MARCH_BLOCK`` samples: a ray leaves the march once nothing after can add anything -- its transmittance
        is exactly 0 (it entered a solid voxel), or it climbs above the highest occupied layer (every later
        sample is empty: alpha 0, a factor of exactly 1)."""
        t_exit, frac = NumpyBackend._sample_t(h, points, dirs)
        alpha_flat, z_top = h._alpha_flat(), h._occupied_top_m() + TOP_MARGIN_M
        tau = np.ones(len(points), points.dtype)
        rising = dirs[:, 2] > 0
        active = np.arange(len(points))
        rays, flats, weights = [], [], []
        for k0 in range(0, len(frac), MARCH_BLOCK):
            if k0:  # drop the finished rays
                z_next = points[active, 2] + (t_exit[active] * frac[k0]) * dirs[active, 2]
                active = active[(tau[active] != 0) & ~(rising[active] & (z_next > z_top))]
            if not len(active):
                break
            t = t_exit[active, None] * frac[None, k0 : k0 + MARCH_BLOCK]
            p, d = points[active], dirs[active]
            flat, inside = h.grid.flat_index_xyz(*(p[:, a, None] + t * d[:, a, None] for a in range(3)))
            alpha = alpha_flat.take(flat)
            np.multiply(alpha, inside, out=alpha)
            trans = np.empty((len(active), alpha.shape[1] + 1), points.dtype)
            trans[:, 0] = tau[active]  # tau_{k0-1}: the product continues exactly as one cumprod over all K
            np.subtract(1.0, alpha, out=trans[:, 1:])
            np.cumprod(trans, axis=1, out=trans)
            tau[active] = trans[:, -1]
            if need_weights:
                alpha *= trans[:, :-1]  # the weights tau_{k-1} alpha_k
                sample = np.flatnonzero(alpha > 0)  # row-major: ray ascending, then k
                rays.append(active.take(sample // alpha.shape[1]))
                flats.append(flat.reshape(-1).take(sample))
                weights.append(alpha.reshape(-1).take(sample))
        if not need_weights:
            return tau, None, None, None
        ray = np.concatenate(rays) if rays else np.zeros(0, np.int64)
        order = np.argsort(ray, kind="stable")  # (ray, block, k) = (ray, k)
        cat = (lambda parts, dtype: np.concatenate(parts).take(order) if parts else np.zeros(0, dtype))
        return tau, ray.take(order), cat(flats, np.int64), cat(weights, points.dtype)

    @staticmethod
    def radiance_chunk(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray, include_sun: bool) -> np.ndarray:
        if h.seen is None:
            return NumpyBackend.volume_chunk(h, points, dirs, include_sun)
        hit, t, mesh_rgb, spread = h.seen.trace_spread(points, dirs)
        return sky_blend(h, points, dirs, include_sun, hit, t, mesh_rgb.astype(h.sky_world.dtype), spread,
                         NumpyBackend.volume_chunk)

    @staticmethod
    def volume_chunk(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray, include_sun: bool,
                     backdrop: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Eq. 1 along rays (N, 3); ``backdrop`` (which rays (N,) bool, radiance (N, 3)): those rays' sky behind
        the volume instead of the dome's (the sun's disc still added)."""
        env = NumpyBackend.env_radiance(h, dirs, include_sun)
        if backdrop is not None and backdrop[0].any():
            k = np.flatnonzero(backdrop[0])
            env[k] += backdrop[1][k].astype(env.dtype) - sample_world_equirect(h.sky_world, dirs[k])
        if h.params is None:
            return env
        tau, ray, flat, weight = NumpyBackend.march_weights(h, points, dirs)
        out = tau[:, None] * env
        if len(ray):
            vox = h.params.reshape(-1, N_CHANNELS).take(flat, axis=0)
            axis = vox[:, CH_AXIS]
            axis = axis / np.maximum(np.sqrt(np.einsum("ij,ij->i", axis, axis)), 1e-9)[:, None]
            cosang = -np.einsum("ij,ij->i", dirs.take(ray, axis=0), axis)  # G(-l): leaving the voxel to the point
            sigma2 = np.maximum(np.square(vox[:, CH_SIGMA]), 1e-6)
            lobe = vox[:, CH_COLOR] * np.exp(-(1.0 - cosang) / sigma2)[:, None]
            lobe *= weight[:, None]
            first = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]])  # each ray's first sample
            out[ray[first]] += np.add.reduceat(lobe, first, axis=0)
        return out

    @staticmethod
    def transmittance_chunk(h: "HybridLighting", points: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        return NumpyBackend.march_weights(h, points, dirs, need_weights=False)[0]

    @staticmethod
    def version(x: np.ndarray | None) -> int:
        """The array's identity: :class:`HybridLighting` keeps its numpy arrays read-only, so a change is a new
        array (the local env-map cache's key)."""
        return -1 if x is None else id(x)


# ----------------------------------------------------------------------------- hybrid lighting


@dataclass
class HybridLighting:
    """Sky dome + analytic sun + optional VSG volume, in the volume frame (see module doc).

    Built from numpy arrays it stays numpy (read-only views of them; queries return numpy arrays, torch is not
    imported); if any of ``sky_world``, ``sun_irradiance``, ``params`` is a tensor, all three become tensors and
    the queries return (differentiable) tensors.

    Attributes:
        sky_world: (H, W, 3) float32 array or tensor, world-convention equirect sky radiance, sun excluded.
        sun_dir: (3,) float64 unit vector towards the sun (volume frame), or None (night / no sun).
        sun_irradiance: (3,) irradiance of the sun on a surface facing it (clouds applied), the dtype of the sky.
        sun_half_angle_rad: angular radius of the sun disc.
        grid: the volume's grid, or None (sky only).
        params: (X, Y, Z, 8) float32 VSG parameters (see module doc), or None.
        n_samples: K of Eq. 1.
        seen: the input cameras' seen surfaces at image resolution, or None (volume and sky only).
    """

    sky_world: np.ndarray | torch.Tensor
    sun_dir: np.ndarray | None = None
    sun_irradiance: np.ndarray | torch.Tensor | None = None
    sun_half_angle_rad: float = float(np.radians(0.2665))
    grid: LogGrid | None = None
    params: np.ndarray | torch.Tensor | None = None
    n_samples: int = DEFAULT_SAMPLES
    seen: SeenSurfaces | None = None
    _envmap_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _ops: type = field(default=NumpyBackend, init=False, repr=False, compare=False)
    _alpha: tuple = field(default=(None, None), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if any(_is_tensor(x) for x in (self.sky_world, self.sun_irradiance, self.params)):
            from .volume_torch import TorchBackend

            self._ops = TorchBackend
            self.sky_world = TorchBackend.array(self.sky_world)
            dtype = self.sky_world.dtype
            self.params = None if self.params is None else TorchBackend.array(self.params)
            if self.sun_irradiance is not None:
                self.sun_irradiance = TorchBackend.array(self.sun_irradiance, dtype)
        else:
            self.sky_world = _read_only(self.sky_world)
            self.params = None if self.params is None else _read_only(self.params)
            if self.sun_irradiance is not None:
                self.sun_irradiance = _read_only(np.asarray(self.sun_irradiance, self.sky_world.dtype))
        check_shape(self.sky_world, ("H", "W", 3), "sky_world")
        if (self.grid is None) != (self.params is None):
            raise ValueError("HybridLighting: give both grid and params, or neither")
        if self.params is not None:
            check_shape(self.params, (*self.grid.shape, N_CHANNELS), "params")
        if self.sun_dir is not None:
            d = np.asarray(self.sun_dir, dtype=np.float64)
            check_shape(d, (3,), "sun_dir")
            self.sun_dir = d / np.linalg.norm(d)
            if self.sun_irradiance is None:
                raise ValueError("HybridLighting: sun_dir given without sun_irradiance")

    def _alpha_flat(self) -> np.ndarray:
        """The occupancy channel (X*Y*Z,) of the numpy parameters, contiguous (cached per parameter array)."""
        if self._alpha[0] is not self.params:
            alpha = np.ascontiguousarray(self.params.reshape(-1, N_CHANNELS)[:, CH_ALPHA])
            layers = np.flatnonzero((alpha.reshape(self.grid.shape) != 0).any(axis=(0, 1)))
            top_m = self.grid.axis_edges()[2][layers[-1] + 1] if len(layers) else -np.inf
            self._alpha = (self.params, alpha, float(top_m))
        return self._alpha[1]

    def _occupied_top_m(self) -> float:
        """Upper edge (metres) of the highest voxel layer with any non-zero alpha (-inf if none)."""
        self._alpha_flat()
        return self._alpha[2]

    # ------------------------------------------------------------------ environment

    @property
    def sun_solid_angle_sr(self) -> float:
        return 2 * math.pi * (1 - math.cos(self.sun_half_angle_rad))

    def env_radiance(self, dirs: np.ndarray | torch.Tensor, include_sun: bool = True) -> np.ndarray | torch.Tensor:
        """``L_env(l)`` (N, 3): the sky dome (bilinear) plus, inside the sun's disc, the sun's radiance."""
        return self._ops.env_radiance(self, self._ops.array(dirs, self.sky_world.dtype), include_sun)

    # ------------------------------------------------------------------ Eq. 1

    def _march(self, points, dirs):
        """Sample the volume along rays: (flat voxel index (N, K), alpha (N, K), inside (N, K))."""
        return self._ops.march(self, points, dirs)

    def radiance(self, points: np.ndarray | torch.Tensor, dirs: np.ndarray | torch.Tensor,
                 include_sun: bool = True) -> np.ndarray | torch.Tensor:
        """Eq. 1: radiance (N, 3) arriving at points (N, 3) from unit directions (N, 3) (pointing away), batched;
        where a ray hits a seen surface, that surface's radiance."""
        ops, dtype = self._ops, self.sky_world.dtype
        points, dirs = ops.rays(points, dirs, dtype)
        outs = [ops.radiance_chunk(self, points[i : i + CHUNK_RAYS], dirs[i : i + CHUNK_RAYS], include_sun)
                for i in range(0, len(points), CHUNK_RAYS)]
        return ops.cat(outs, (0, 3), dtype)

    def radiance_spread(self, points: np.ndarray, dirs: np.ndarray,
                        include_sun: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`radiance` (N, 3) numpy and each ray's angular reprojection uncertainty (N,) radians: where the ray
        hits a seen surface, :meth:`.seen_surfaces.SeenSurfaces.trace_spread`'s; 0 elsewhere (the volume and the
        dome carry no image-resolution detail to misplace)."""
        if self.seen is None:
            return as_numpy(self.radiance(points, dirs, include_sun)), np.zeros(len(points))
        points, dirs = self._ops.rays(points, dirs, self.sky_world.dtype)  # as radiance() sees them
        rads, spreads = [], []
        for i in range(0, len(points), CHUNK_RAYS):
            p, d = points[i : i + CHUNK_RAYS], dirs[i : i + CHUNK_RAYS]
            hit, t, mesh_rgb, spread = self.seen.trace_spread(as_numpy(p), as_numpy(d))
            out = as_numpy(sky_blend(self, p, d, include_sun, hit, t,
                                     mesh_rgb.astype(as_numpy(self.sky_world).dtype), spread,
                                     lambda *a: as_numpy(self._ops.volume_chunk(*a))))
            rads.append(out)
            spreads.append(spread)
        return np.concatenate(rads), np.concatenate(spreads)

    def transmittance(self, points: np.ndarray | torch.Tensor, dirs: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
        """``tau_K`` (N,): the fraction of the distant light (sky, sun) that reaches points along directions."""
        ops, dtype = self._ops, self.sky_world.dtype
        points, dirs = ops.rays(points, dirs, dtype)
        if self.params is None:
            return ops.ones(len(points), points.dtype)
        outs = [ops.transmittance_chunk(self, points[i : i + CHUNK_RAYS], dirs[i : i + CHUNK_RAYS])
                for i in range(0, len(points), CHUNK_RAYS)]
        return ops.cat(outs, (0,), dtype)

    def sun_transmittance(self, point: np.ndarray, n_rays: int = 7) -> float:
        """Mean transmittance towards the sun's disc from a point (3,): the centre and a ring of rays; 0 without sun."""
        if self.sun_dir is None:
            return 0.0
        if self.params is None:
            return 1.0
        s = self.sun_dir
        helper = np.array([0.0, 0.0, 1.0]) if abs(s[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        t1 = np.cross(s, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(s, t1)
        r = 0.7 * math.tan(self.sun_half_angle_rad)
        phi = 2 * np.pi * np.arange(max(n_rays - 1, 0)) / max(n_rays - 1, 1)
        dirs = [s] + [s + r * (np.cos(p) * t1 + np.sin(p) * t2) for p in phi]
        dirs = np.array(dirs)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        pts = np.repeat(np.asarray(point, dtype=np.float64)[None], len(dirs), axis=0)
        return float(as_numpy(self.transmittance(pts, dirs)).mean())

    # ------------------------------------------------------------------ local environment maps

    def envmap_at(self, point: np.ndarray, height: int = 128, width: int = 256,
                  R_vol_from_frame: np.ndarray | None = None) -> np.ndarray:
        """Local environment map (height, width, 3) float32 at a volume-frame point (3,), sun excluded; away from
        the input cameras' centres, the expected map: blurred per pixel by how uncertain the place of the seen
        surface it shows is (:func:`.view_blur.uncertainty_blurred_equirect`, as a predicted view is; ~0 at a
        camera's own centre, where its surfaces lie where they are drawn).

        Without ``R_vol_from_frame`` the map uses the world (z-up) equirect convention of the volume frame; with
        it, the camera-frame convention of the frame whose directions rotate into the volume frame by it.
        """
        p = np.asarray(point, dtype=np.float64)
        check_shape(p, (3,), "point")
        if R_vol_from_frame is None:
            d = world_envmap_directions(height, width).reshape(-1, 3)
        else:
            d = camera_envmap_directions(height, width).reshape(-1, 3) @ np.asarray(R_vol_from_frame).T
        rad, spread = self.radiance_spread(np.repeat(p[None], len(d), axis=0), d, include_sun=False)
        return uncertainty_blurred_equirect(rad.reshape(height, width, 3).astype(np.float32),
                                            spread.reshape(height, width))

    def envmap_at_cached(self, point: np.ndarray, height: int = 128, width: int = 256) -> np.ndarray:
        """World-convention :meth:`envmap_at`, remembered per point (to the millimetre) while the sky and volume
        are unchanged (the same tensors at the same version; the same numpy arrays): an object that several
        cameras see is traced once and then rotated into each camera (:func:`world_to_frame_envmap`; 0.4 % mean
        difference from tracing the camera's map directly)."""
        p = np.asarray(point, dtype=np.float64)
        anchors = (self.sky_world, self.params, self.seen)
        versions = (self._ops.version(self.sky_world), self._ops.version(self.params), id(self.seen))
        key = (tuple(np.round(p, 3).tolist()), height, width, versions)
        hit = self._envmap_cache.get(key)
        if hit is None or any(a is not b for a, b in zip(hit[0], anchors)):  # ids of live objects only
            # maps of replaced arrays are stale: dropped (they would keep the old arrays alive)
            self._envmap_cache = {k: v for k, v in self._envmap_cache.items()
                                  if all(a is b for a, b in zip(v[0], anchors))}
            if len(self._envmap_cache) >= ENVMAP_CACHE_SIZE:
                self._envmap_cache.pop(next(iter(self._envmap_cache)))
            hit = self._envmap_cache[key] = (anchors, self.envmap_at(p, height, width))
        return hit[1]

    def lift_out_of_solid(self, point: np.ndarray, max_steps: int = 64) -> np.ndarray:
        """The point (3,) moved straight up to the first voxel with alpha < 0.5 (unchanged if already free)."""
        p = np.asarray(point, dtype=np.float64).copy()
        if self.params is None:
            return p
        idx = np.floor(self.grid.to_index(p)).astype(np.int64)
        if np.any(idx[:2] < 0) or idx[0] >= self.grid.shape[0] or idx[1] >= self.grid.shape[1]:
            return p
        column = as_numpy(self.params[int(idx[0]), int(idx[1]), :, CH_ALPHA])
        k = int(np.clip(idx[2], 0, self.grid.shape[2] - 1))
        steps = 0
        while k < self.grid.shape[2] and column[k] >= 0.5 and steps < max_steps:
            k += 1
            steps += 1
        if k != idx[2] and k < self.grid.shape[2]:
            lo = self.grid.index_to_point(np.array([idx[0] + 0.5, idx[1] + 0.5, k]))[2]
            hi = self.grid.index_to_point(np.array([idx[0] + 0.5, idx[1] + 0.5, k + 1]))[2]
            p[2] = max(p[2], lo + 0.1 * (hi - lo))
        return p

    # ------------------------------------------------------------------ files

    def save(self, out_dir: str | Path, extra: dict | None = None) -> dict:
        """Write ``sky_world.exr`` (dome), ``volume.npz`` (occupied voxels only, float16), ``seen_surfaces.npz``
        (if any; :meth:`SeenSurfaces.save`) and ``hybrid.json``.

        Empty voxels (alpha 0) do not affect the radiance; they load back as :func:`empty_params` voxels.
        """
        out = Path(out_dir)
        write_exr(out / "sky_world.exr", as_numpy(self.sky_world).astype(np.float32))
        files = {"sky_world": "sky_world.exr"}
        if self.params is not None:
            flat = as_numpy(self.params).reshape(-1, N_CHANNELS)
            keep = np.flatnonzero(flat[:, CH_ALPHA] > 0)
            import io

            buf = io.BytesIO()
            np.savez_compressed(buf, shape=np.array(self.grid.shape), index=keep.astype(np.int32),
                                values=flat[keep].astype(np.float16))
            write_bytes_atomic(out / "volume.npz", buf.getvalue())
            files["volume"] = "volume.npz"
        if self.seen is not None:
            self.seen.save(out / "seen_surfaces.npz")
            files["seen_surfaces"] = "seen_surfaces.npz"
        doc = {
            "schema": VOLUME_SCHEMA,
            "frame": "volume frame: z up, metres (see streetaug.augment.lighting.volume)",
            "sky_convention": "world z-up equirect: lon = atan2(dy, dx), lat = asin(dz); sun excluded",
            "sun": None if self.sun_dir is None else {
                "direction": [float(v) for v in self.sun_dir],
                "irradiance_rgb": [float(v) for v in as_numpy(self.sun_irradiance)],
                "half_angle_rad": float(self.sun_half_angle_rad),
            },
            "grid": None if self.grid is None else self.grid.to_json(),
            "channels": ["c_r", "c_g", "c_b", "mu_x", "mu_y", "mu_z", "sigma", "alpha"],
            "n_samples": self.n_samples,
            "files": files,
        }
        if extra:
            doc.update(extra)
        write_json_atomic(out / "hybrid.json", doc)
        return doc

    @staticmethod
    def load(in_dir: str | Path, as_tensors: bool = True) -> "HybridLighting":
        """Read what :meth:`save` wrote (raises ``InputError`` naming the file and field on bad input): tensors, or
        numpy arrays with ``as_tensors=False`` (no torch import)."""
        d = Path(in_dir)
        doc = read_json(d / "hybrid.json")
        if doc.get("schema") != VOLUME_SCHEMA:
            raise InputError(f"{d / 'hybrid.json'}: field 'schema' is {doc.get('schema')!r}, expected {VOLUME_SCHEMA!r}")
        sky = read_exr(d / doc["files"]["sky_world"]).astype(np.float32)
        sun = doc.get("sun")
        grid = params = None
        if doc.get("grid") is not None:
            grid = LogGrid.from_json(doc["grid"])
            path = d / doc["files"]["volume"]
            try:
                with np.load(path) as z:
                    shape, index, values = tuple(z["shape"]), z["index"], z["values"]
            except (OSError, KeyError, ValueError) as e:
                raise InputError(f"{path}: cannot read the volume ({e}); expected arrays shape, index, values") from None
            if shape != grid.shape or values.shape[1:] != (N_CHANNELS,) or len(index) != len(values):
                raise InputError(f"{path}: volume of shape {shape} / values {values.shape} does not match grid {grid.shape}")
            params = empty_params(grid, as_tensor=False)
            params.reshape(-1, N_CHANNELS)[index.astype(np.int64)] = values.astype(np.float32)
        seen = SeenSurfaces.load(d / doc["files"]["seen_surfaces"]) if "seen_surfaces" in doc["files"] else None
        irradiance = None if sun is None else np.array(sun["irradiance_rgb"], dtype=np.float32)
        if as_tensors:
            from .volume_torch import TorchBackend

            sky = TorchBackend.array(sky)
            params = None if params is None else TorchBackend.array(params)
            irradiance = None if irradiance is None else TorchBackend.array(irradiance)
        return HybridLighting(
            sky_world=sky,
            sun_dir=None if sun is None else np.array(sun["direction"]),
            sun_irradiance=irradiance,
            sun_half_angle_rad=float(sun["half_angle_rad"]) if sun else float(np.radians(0.2665)),
            grid=grid, params=params, n_samples=int(doc.get("n_samples", DEFAULT_SAMPLES)), seen=seen,
        )


def _is_tensor(x) -> bool:
    """Whether ``x`` is a torch tensor, without importing torch (a tensor exists only once torch is loaded)."""
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, torch.Tensor)


def as_numpy(x) -> np.ndarray:
    """A tensor's values as a numpy array (detached, on the CPU; no copy there), or ``np.asarray(x)``."""
    return x.detach().cpu().numpy() if _is_tensor(x) else np.asarray(x)


def _like(like, values: np.ndarray):
    """``values`` as a tensor if ``like`` is one (shared memory), else unchanged."""
    if _is_tensor(like):
        from .volume_torch import TorchBackend

        return TorchBackend.array(values)
    return values


def _read_only(x) -> np.ndarray:
    """A read-only view of an array (the caller's array keeps its own flags)."""
    view = np.asarray(x).view()
    view.flags.writeable = False
    return view


def _coordinates(points: np.ndarray | torch.Tensor) -> np.ndarray:
    """Points (..., 3) as a float numpy array (float64 unless float32 or float64 already; no copy for a tensor)."""
    p = as_numpy(points)
    return p if p.dtype in (np.float32, np.float64) else p.astype(np.float64)


def empty_params(grid: LogGrid, as_tensor: bool = True) -> np.ndarray | torch.Tensor:
    """An all-empty (alpha 0) float32 parameter array (X, Y, Z, 8) with unit axes +z and sigma 1: a tensor, or a
    numpy array with ``as_tensor=False``."""
    p = np.zeros((*grid.shape, N_CHANNELS), dtype=np.float32)
    p[..., 5] = 1.0
    p[..., CH_SIGMA] = 1.0
    if as_tensor:
        from .volume_torch import TorchBackend

        return TorchBackend.array(p)
    return p
