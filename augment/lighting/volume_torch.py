"""The torch backend of :class:`.volume.HybridLighting`: Eq. 1 on tensors, differentiable with respect to the sky
dome, the sun irradiance and the VSG parameters (fitting, gradient tests).

A :class:`~.volume.HybridLighting` built from tensors uses this module (imported then, and only then); one built
from numpy arrays uses the numpy backend in :mod:`.volume`, which gives the same results to float32 rounding
(tests/lighting/test_volume_numpy_backend.py) without importing torch. Same functions, same signatures as
:class:`.volume.NumpyBackend`.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..core import check_rays
from .sky_preempt import sky_preempt_weight, through_volume
from .volume_channels import CH_ALPHA, CH_AXIS, CH_COLOR, CH_SIGMA, N_CHANNELS


def sample_world_equirect(env: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Bilinear lookup (N, C) of a world-convention (H, W, C) map at unit directions (N, 3); wraps in longitude."""
    H, W = env.shape[:2]
    lon = torch.atan2(dirs[:, 1], dirs[:, 0])
    lat = torch.asin(dirs[:, 2].clamp(-1.0, 1.0))
    x = torch.remainder(lon / (2 * math.pi) + 0.5, 1.0) * W - 0.5
    y = ((0.5 - lat / math.pi) * H - 0.5).clamp(0.0, H - 1.0)
    x0 = torch.floor(x)
    y0 = torch.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.long()
    y0 = y0.long()
    y1 = (y0 + 1).clamp(max=H - 1)
    x0w = torch.remainder(x0, W)
    x1w = torch.remainder(x0 + 1, W)
    top = env[y0, x0w] * (1 - fx) + env[y0, x1w] * fx
    bottom = env[y1, x0w] * (1 - fx) + env[y1, x1w] * fx
    return top * (1 - fy) + bottom * fy


class TorchBackend:
    """Eq. 1 and the transmittance on tensors (see :class:`.volume.NumpyBackend` for the contract)."""

    is_tensor = True

    @staticmethod
    def array(x, dtype: torch.dtype | None = None) -> torch.Tensor:
        """``x`` as a tensor (shared memory where possible: not with a read-only array), of ``dtype`` if given."""
        if not torch.is_tensor(x):
            x = np.asarray(x)
            x = x if x.flags.writeable else x.copy()
        return torch.as_tensor(x, dtype=dtype)

    @staticmethod
    def rays(points, dirs, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
        points, dirs = TorchBackend.array(points, dtype), TorchBackend.array(dirs, dtype)
        check_rays(points, dirs)
        return points, dirs

    @staticmethod
    def cat(parts: list[torch.Tensor], empty_shape: tuple[int, ...], dtype: torch.dtype) -> torch.Tensor:
        return torch.cat(parts) if parts else torch.zeros(empty_shape, dtype=dtype)

    @staticmethod
    def ones(n: int, dtype: torch.dtype) -> torch.Tensor:
        return torch.ones(n, dtype=dtype)

    @staticmethod
    def env_radiance(h, dirs: torch.Tensor, include_sun: bool) -> torch.Tensor:
        rgb = sample_world_equirect(h.sky_world, dirs)
        if include_sun and h.sun_dir is not None:
            sun = torch.as_tensor(h.sun_dir, dtype=dirs.dtype)
            in_disc = (dirs @ sun) >= math.cos(h.sun_half_angle_rad)
            rgb = rgb + in_disc[:, None].to(rgb.dtype) * (h.sun_irradiance / h.sun_solid_angle_sr)[None]
        return rgb

    @staticmethod
    def march(h, points: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        lo, hi = (torch.as_tensor(b, dtype=points.dtype) for b in h.grid.bounds())
        with torch.no_grad():
            safe = torch.where(dirs.abs() < 1e-12, torch.full_like(dirs, 1e-12), dirs)
            t_hi = torch.maximum((lo - points) / safe, (hi - points) / safe)
            t_exit = t_hi.min(dim=1).values.clamp(min=0.0)  # (N,)
        K = h.n_samples
        frac = (torch.arange(K, dtype=points.dtype) + 0.5) / K
        t = (t_exit[:, None] * frac[None]).numpy()
        p, d = points.detach().numpy(), dirs.detach().numpy()
        flat, inside = h.grid.flat_index_xyz(*(p[:, a, None] + t * d[:, a, None] for a in range(3)))
        flat, inside = torch.from_numpy(flat), torch.from_numpy(inside)
        alpha_col = h.params.reshape(-1, N_CHANNELS)[:, CH_ALPHA]
        alpha = alpha_col.index_select(0, flat.reshape(-1)).reshape(flat.shape) * inside  # faster than [flat]
        return flat, alpha, inside

    @staticmethod
    def radiance_chunk(h, points: torch.Tensor, dirs: torch.Tensor, include_sun: bool) -> torch.Tensor:
        if h.seen is None:
            return TorchBackend.volume_chunk(h, points, dirs, include_sun)
        hit, t, mesh_rgb, spread = h.seen.trace_spread(points.detach().numpy(), dirs.detach().numpy())
        to_volume, sky = through_volume(hit, t)  # as the numpy backend's volume.sky_blend
        miss_np = np.flatnonzero(to_volume)
        miss = torch.from_numpy(miss_np)
        out = torch.from_numpy(mesh_rgb).to(h.sky_world.dtype)
        if len(miss):
            vol = TorchBackend.volume_chunk(h, points[miss], dirs[miss], include_sun, (sky[miss_np], mesh_rgb[miss_np]))
            w = torch.from_numpy(sky_preempt_weight(sky[miss_np], t[miss_np], spread[miss_np])).to(out.dtype)[:, None]
            out = out.index_put((miss,), w * out[miss] + (1.0 - w) * vol)
        return out

    @staticmethod
    def volume_chunk(h, points: torch.Tensor, dirs: torch.Tensor, include_sun: bool,
                     backdrop: tuple[np.ndarray, np.ndarray] | None = None) -> torch.Tensor:
        """Eq. 1 along rays; ``backdrop`` (which rays (N,) bool, radiance (N, 3) numpy): those rays' sky behind
        the volume instead of the dome's (the sun's disc still added)."""
        env = TorchBackend.env_radiance(h, dirs, include_sun)
        if backdrop is not None and backdrop[0].any():
            k_np = np.flatnonzero(backdrop[0])
            k = torch.from_numpy(k_np)
            env = env.index_add(0, k, torch.from_numpy(backdrop[1][k_np]).to(env.dtype)
                                - sample_world_equirect(h.sky_world, dirs[k]))
        if h.params is None:
            return env
        flat, alpha, _ = TorchBackend.march(h, points, dirs)
        trans = torch.cumprod(1.0 - alpha, dim=1)  # tau_k
        trans_before = torch.cat([torch.ones_like(trans[:, :1]), trans[:, :-1]], dim=1)  # tau_{k-1}
        weight = trans_before * alpha
        ray, k = torch.nonzero(weight > 0, as_tuple=True)
        out = trans[:, -1:] * env
        if len(ray):
            vox = h.params.reshape(-1, N_CHANNELS)[flat[ray, k]]
            axis = vox[:, CH_AXIS]
            axis = axis / axis.norm(dim=1, keepdim=True).clamp(min=1e-9)
            cosang = -(dirs[ray] * axis).sum(dim=1)  # G(-l): radiance leaving the voxel towards the point
            sigma2 = vox[:, CH_SIGMA].square().clamp(min=1e-6)
            lobe = vox[:, CH_COLOR] * torch.exp(-(1.0 - cosang) / sigma2)[:, None]
            out = out.index_add(0, ray, weight[ray, k][:, None] * lobe)
        return out

    @staticmethod
    def transmittance_chunk(h, points: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        _, alpha, _ = TorchBackend.march(h, points, dirs)
        return torch.prod(1.0 - alpha, dim=1)

    @staticmethod
    def version(x: torch.Tensor | None) -> int:
        """Changes whenever the tensor is written in place (the local env-map cache's key)."""
        return -1 if x is None else x._version

