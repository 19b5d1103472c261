"""Direction sampling: Fibonacci lattice, cosine hemisphere, environment-map importance, sun disc.

Directions are unit (N, 3) float64 vectors; pdfs are per steradian.  Local hemisphere samples are
z-up (rotate them with :func:`streetaug.augment.render.brdf.to_world`).  Environment maps use the
camera-frame equirectangular convention of :mod:`streetaug.augment.core`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..core import (
    camera_dir_to_lonlat,
    camera_envmap_directions,
    check_shape,
    equirect_solid_angles,
    lonlat_to_camera_dir,
    luminance,
)
from .brdf import to_world

GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def fibonacci_hemisphere(n: int) -> np.ndarray:
    """``n`` near-equal-area directions (n, 3) on the upper (z >= 0) hemisphere; each stands for 2 pi / n sr."""
    if n < 1:
        raise ValueError(f"fibonacci_hemisphere: need at least one direction, got {n}")
    k = np.arange(n) + 0.5
    z = 1.0 - k / n  # uniform in z = uniform in solid angle
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    phi = GOLDEN_ANGLE * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def cosine_hemisphere(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-weighted local directions (N, 3) (z-up) and their pdf cos / pi (N,)."""
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    z = np.sqrt(np.clip(1.0 - u1, 0.0, 1.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), z / np.pi


def sample_cone(axis: np.ndarray, half_angle_rad: float, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions (N, 3) uniform in solid angle inside the cone around unit ``axis`` (3,) (e.g. the sun disc)."""
    cos_max = np.cos(half_angle_rad)
    z = 1.0 - u1 * (1.0 - cos_max)
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    phi = 2.0 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return to_world(local, np.asarray(axis, dtype=np.float64))


@dataclass(frozen=True)
class EnvSampler:
    """Importance sampling of an equirect environment map by luminance x solid angle.

    Attributes:
        height, width: map size.
        cdf: (H*W,) float64 cumulative pixel probabilities (last = 1).
        pmf: (H*W,) float64 pixel probabilities.
        solid_angle: (H,) float64 solid angle of a pixel in each row (sr).
    """

    height: int
    width: int
    cdf: np.ndarray
    pmf: np.ndarray
    solid_angle: np.ndarray

    @staticmethod
    def build(envmap: np.ndarray, uniform_mix: float = 0.05) -> "EnvSampler":
        """From an (H, W, 3) map; ``uniform_mix`` of the probability is spread by solid angle (no zero pdf)."""
        check_shape(envmap, ("H", "W", 3), "envmap")
        H, W = envmap.shape[:2]
        omega = equirect_solid_angles(H, W)
        w = np.maximum(luminance(np.asarray(envmap, dtype=np.float64)), 0.0) * omega
        total = w.sum()
        pmf = omega / omega.sum() if total <= 0 else (1 - uniform_mix) * w / total + uniform_mix * omega / omega.sum()
        pmf = pmf.ravel()
        cdf = np.cumsum(pmf)
        cdf /= cdf[-1]
        return EnvSampler(H, W, cdf, pmf, omega[:, 0].copy())

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame directions (N, 3) and pdfs (N,) from uniforms ``u`` (N, 3)."""
        idx = np.minimum(np.searchsorted(self.cdf, u[:, 0], side="right"), self.cdf.size - 1)
        row, col = np.divmod(idx, self.width)
        # Uniform in solid angle inside the pixel: uniform in longitude and in sin(latitude).
        lon = ((col + u[:, 1]) / self.width - 0.5) * 2.0 * np.pi
        s_top = np.sin((0.5 - row / self.height) * np.pi)
        s_bot = np.sin((0.5 - (row + 1) / self.height) * np.pi)
        lat = np.arcsin(np.clip(s_top + (s_bot - s_top) * u[:, 2], -1.0, 1.0))
        return lonlat_to_camera_dir(lon, lat), self.pmf[idx] / self.solid_angle[row]

    def pdf(self, dirs: np.ndarray) -> np.ndarray:
        """Solid-angle pdf (N,) of camera-frame directions (N, 3) under :meth:`sample`."""
        lon, lat = camera_dir_to_lonlat(dirs)
        col = np.clip(((lon / (2 * np.pi) + 0.5) * self.width).astype(np.int64), 0, self.width - 1)
        row = np.clip(((0.5 - lat / np.pi) * self.height).astype(np.int64), 0, self.height - 1)
        return self.pmf[row * self.width + col] / self.solid_angle[row]


def hemisphere_irradiance(envmap: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Irradiance (3,) on a surface with unit ``normal`` (3,) from an unoccluded camera-frame envmap."""
    H, W = envmap.shape[:2]
    cos = np.clip(np.einsum("hwk,k->hw", camera_envmap_directions(H, W), np.asarray(normal, dtype=np.float64)), 0.0, None)
    w = cos * equirect_solid_angles(H, W)
    return np.einsum("hw,hwc->c", w, np.asarray(envmap, dtype=np.float64))


def equirect_texel_moments(height: int, width: int) -> np.ndarray:
    """Integrated direction ``int_texel d dw`` (H, W, 3) of every texel of a camera-frame equirect map.

    Its length is below the texel's solid angle (the directions inside it spread); for any unit n with
    n . d > 0 over the whole texel, ``int_texel n . d dw = n . m`` exactly.
    """
    lon = (np.arange(width + 1) / width - 0.5) * 2.0 * np.pi
    lat = (0.5 - np.arange(height + 1) / height) * np.pi  # top edge first (decreasing)
    a, b = lon[:-1], lon[1:]
    top, bot = lat[:-1], lat[1:]
    i2 = (top / 2 + np.sin(2 * top) / 4) - (bot / 2 + np.sin(2 * bot) / 4)  # int cos^2(lat) dlat
    s2 = (np.sin(top) ** 2 - np.sin(bot) ** 2) / 2.0  # int sin(lat) cos(lat) dlat
    x = i2[:, None] * (np.cos(a) - np.cos(b))[None, :]
    y = -s2[:, None] * (b - a)[None, :]
    z = i2[:, None] * (np.sin(b) - np.sin(a))[None, :]
    return np.stack([x, y, z], axis=-1)


def irradiance_map(envmap: np.ndarray, height: int = 32, width: int = 64) -> np.ndarray:
    """Unoccluded irradiance for every normal direction: (height + 2, width, 3), look up with :func:`lookup_irradiance`.

    Rows 1..height hold ``E(n)`` at the texel centres of a camera-frame equirect (height, width) map,
    row 0 and row height + 1 at the north (up, -y) and south pole, so that normals near the poles are
    interpolated rather than clamped to the first texel row.  ``E(n) = sum_texels L max(0, n . m)`` over
    the map reduced to (height, width) texels (power kept exactly, ``m`` = the texel's integrated
    direction).  Built once per map by :class:`streetaug.augment.render.environment.EnvironmentTables`.
    """
    H, W = envmap.shape[:2]
    # Power per small texel (radiance x solid angle summed exactly), and the texel's mean direction
    # vector m = int d dw: int_texel L max(0, n.d) dw ~ (power / solid angle) max(0, n.m) is exact for
    # texels wholly above the surface's horizon (no error at the poles, unlike centre directions).
    power = np.asarray(envmap, dtype=np.float32) * equirect_solid_angles(H, W)[..., None].astype(np.float32)
    power = cv2.resize(power, (width, height), interpolation=cv2.INTER_AREA).astype(np.float64)
    power *= (H * W) / (height * width)
    radiance = power.reshape(-1, 3) / equirect_solid_angles(height, width).reshape(-1, 1)
    E_dirs = (_irradiance_cosines(height, width) @ radiance.astype(np.float32)).astype(np.float64)
    E = np.concatenate([np.repeat(E_dirs[:1], width, axis=0), E_dirs[1:-1], np.repeat(E_dirs[-1:], width, axis=0)])
    return E.reshape(height + 2, width, 3)


def _irradiance_cosines(height: int, width: int) -> np.ndarray:
    """(height * width + 2, height * width) float32 ``max(0, n . m)`` of :func:`irradiance_map`'s normals (the
    poles, then the texel centres) and texel moments (geometry alone; not cached: 16.8 MB at 32 x 64 would stay
    in every worker for ~6 ms per map)."""
    m = equirect_texel_moments(height, width).reshape(-1, 3)
    d = np.concatenate([[[0.0, -1.0, 0.0]], camera_envmap_directions(height, width).reshape(-1, 3), [[0.0, 1.0, 0.0]]])
    return np.maximum(d.astype(np.float32) @ m.T.astype(np.float32), 0.0)  # (normals, texels): max(0, n . m)


def lookup_irradiance(E: np.ndarray, normals_cam: np.ndarray) -> np.ndarray:
    """Bilinear lookup (N, 3) of an :func:`irradiance_map` at unit camera-frame normals (N, 3)."""
    h, W = E.shape[0] - 2, E.shape[1]
    n = np.asarray(normals_cam, dtype=np.float64)
    lon = np.arctan2(n[:, 0], n[:, 2])
    lat = np.arcsin(np.clip(-n[:, 1], -1.0, 1.0))
    y = (0.5 - lat / np.pi) * h - 0.5  # texel-centre row coordinate, -0.5 (north pole) .. h - 0.5 (south)
    # Row nodes: pole at y = -0.5, texel rows at 0 .. h-1, pole at h - 0.5 -> stored rows 0, 1..h, h+1.
    lo = np.clip(np.floor(y), -1, h - 1).astype(np.int64)
    step = np.where((lo == -1) | (lo == h - 1), 0.5, 1.0)
    base = np.where(lo == -1, -0.5, lo.astype(np.float64))
    fy = np.clip((y - base) / step, 0.0, 1.0)[:, None]
    r0, r1 = lo + 1, lo + 2
    x = (lon * (0.5 / np.pi) + 0.5) * W - 0.5
    x0 = np.floor(x)
    fx = (x - x0)[:, None]
    xa = np.mod(x0.astype(np.int64), W)
    xb = np.mod(xa + 1, W)
    flat = E.reshape(-1, E.shape[2])  # one gather per corner (the same values as E[r, x])
    gx = 1 - fx
    top = flat.take(r0 * W + xa, axis=0) * gx + flat.take(r0 * W + xb, axis=0) * fx
    bot = flat.take(r1 * W + xa, axis=0) * gx + flat.take(r1 * W + xb, axis=0) * fx
    return top * (1 - fy) + bot * fy


def env_pyramid(envmap: np.ndarray, min_width: int = 8) -> list[np.ndarray]:
    """Box-filtered copies (float32) of an equirect map, widths W, W/2, ... down to ``min_width``."""
    levels = [np.asarray(envmap, dtype=np.float32)]
    while levels[-1].shape[1] // 2 >= min_width and levels[-1].shape[0] >= 2:
        h, w = levels[-1].shape[:2]
        levels.append(cv2.resize(levels[-1], (w // 2, max(h // 2, 1)), interpolation=cv2.INTER_AREA))
    return levels
