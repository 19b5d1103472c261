"""Light objects the renderer consumes: a distant environment (sky dome) plus an explicit sun.

Convention: everything here lives in ONE frame, the frame of the rays the renderer casts (the camera
frame in practice); radiance is linear HDR on the image's radiometric scale (so that rendering then
applying the camera response of :mod:`streetaug.augment.core.response` matches the image's exposure).

The sun is kept out of the environment map and described analytically (direction, irradiance,
angular radius), so renderers can sample it explicitly, trace its visibility and get penumbrae
from its disc; :meth:`DistantLight.to_envmap` paints it back in for files and previews.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from scipy import ndimage

from ..core import (
    camera_dir_to_lonlat,
    camera_envmap_directions,
    check_shape,
    equirect_pixel_lonlat,
    equirect_solid_angles,
    lonlat_to_camera_dir,
    luminance,
    sample_equirect,
)

SUN_HALF_ANGLE_RAD = np.radians(0.2665)  # the real sun's angular radius


class Light(Protocol):
    """Anything that answers the radiance arriving at points from directions (Eq. 1 of the paper)."""

    def radiance(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) arriving at points (N, 3) from unit directions (N, 3) (pointing away)."""
        ...


@dataclass(frozen=True)
class SunLight:
    """The sun as a small disc.

    Attributes:
        direction: (3,) unit vector towards the sun, in the light's frame.
        irradiance_rgb: (3,) irradiance on a surface facing the sun (= disc radiance x disc solid
            angle), already multiplied by ``visibility``.
        half_angle_rad: angular radius of the disc (wider than the real sun gives softer shadows).
        visibility: 0..1, how unoccluded the sun is by clouds (informational; already applied).
    """

    direction: np.ndarray
    irradiance_rgb: np.ndarray
    half_angle_rad: float = SUN_HALF_ANGLE_RAD
    visibility: float = 1.0

    @property
    def solid_angle_sr(self) -> float:
        return float(2 * np.pi * (1 - np.cos(self.half_angle_rad)))

    @property
    def radiance_rgb(self) -> np.ndarray:
        return np.asarray(self.irradiance_rgb) / self.solid_angle_sr

    def rotated(self, R_new_from_old: np.ndarray) -> "SunLight":
        return replace(self, direction=np.asarray(R_new_from_old) @ self.direction)


@dataclass(frozen=True)
class DistantLight:
    """Distant lighting: an equirect environment map (camera-frame convention) without the sun, plus the sun.

    Attributes:
        envmap: (H, W, 3) float32 radiance of sky and surroundings, sun disc excluded.
        sun: the sun in the same frame, or None (night, overcast, unknown).
    """

    envmap: np.ndarray
    sun: SunLight | None = None

    def radiance(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) from unit directions (N, 3); distant, so ``points`` are ignored."""
        check_shape(directions, ("N", 3), "directions")
        lon, lat = camera_dir_to_lonlat(directions)
        rgb = sample_equirect(self.envmap, lon, lat).astype(np.float64)
        if self.sun is not None:
            in_disc = directions @ self.sun.direction >= np.cos(self.sun.half_angle_rad)
            rgb = rgb + in_disc[:, None] * self.sun.radiance_rgb[None]
        return rgb

    def to_envmap(self, height: int | None = None, width: int | None = None) -> np.ndarray:
        """The full environment (sun included, its energy spread over the pixels it covers), (H, W, 3)."""
        env = self.envmap
        if height is not None and (height, width) != env.shape[:2]:
            import cv2

            env = cv2.resize(env, (width, height), interpolation=cv2.INTER_AREA)
        env = env.astype(np.float32).copy()
        if self.sun is not None:
            H, W = env.shape[:2]
            d = camera_envmap_directions(H, W)
            omega = equirect_solid_angles(H, W)
            cosang = d @ self.sun.direction
            # Spread over at least the pixel that contains the sun, energy-preserving.
            cone = np.cos(max(self.sun.half_angle_rad, 0.75 * np.pi / H))
            mask = cosang >= cone
            if not mask.any():
                mask = cosang >= cosang.max()
            env[mask] += (self.sun.irradiance_rgb / omega[mask].sum()).astype(np.float32)
        return env

    @staticmethod
    def from_envmap(envmap: np.ndarray, sun_threshold: float = 20.0, min_sun_fraction: float = 0.05) -> "DistantLight":
        """Split an HDR environment map (camera-frame convention) into sun + residual sky.

        The sun is the connected bright region around the brightest pixel whose luminance is at least
        ``sun_threshold`` x the map's median; it is kept as a sun only if it delivers at least
        ``min_sun_fraction`` of the map's total luminance x solid angle (otherwise it is an ordinary
        bright patch and stays in the map).
        """
        env = np.asarray(envmap, dtype=np.float32)
        check_shape(env, ("H", "W", 3), "envmap")
        if not np.all(np.isfinite(env)):
            raise ValueError("environment map contains NaN or Inf values")
        env = np.maximum(env, 0.0)
        H, W = env.shape[:2]
        lum = luminance(env)
        omega = equirect_solid_angles(H, W)
        median = float(np.median(lum))
        peak = np.unravel_index(np.argmax(lum), lum.shape)
        threshold = max(sun_threshold * median, 1e-6)
        if lum[peak] < threshold:
            return DistantLight(env, None)
        labels, _ = ndimage.label(lum >= threshold)
        region = labels == labels[peak]
        # The region may wrap around the seam: merge labels touching across it.
        seam = labels[:, 0][region[:, -1]]
        for lab in np.unique(seam[seam > 0]):
            region |= labels == lab
        # Background to leave in place of the sun: median of a ring around the region.
        ring = ndimage.binary_dilation(region, iterations=3) & ~region
        background = np.median(env[ring], axis=0) if ring.any() else np.zeros(3, np.float32)
        excess = np.maximum(env[region] - background, 0.0)
        irradiance = (excess * omega[region][:, None]).sum(axis=0)
        total = float((lum * omega).sum())
        if luminance(irradiance) < min_sun_fraction * total:
            return DistantLight(env, None)
        weights = luminance(excess) * omega[region]
        lon, lat = equirect_pixel_lonlat(H, W)
        dirs = lonlat_to_camera_dir(lon[region], lat[region])
        direction = (dirs * weights[:, None]).sum(axis=0)
        direction = direction / np.linalg.norm(direction)
        residual = env.copy()
        residual[region] = np.minimum(env[region], background)
        sun = SunLight(direction=direction, irradiance_rgb=irradiance.astype(np.float64), visibility=1.0)
        return DistantLight(residual, sun)

    def rotated(self, R_new_from_old: np.ndarray, height: int | None = None, width: int | None = None) -> "DistantLight":
        """The same light with directions expressed in another frame (rotation only)."""
        H, W = (height, width) if height else self.envmap.shape[:2]
        d_new = camera_envmap_directions(H, W).reshape(-1, 3)
        d_old = d_new @ np.asarray(R_new_from_old)  # R^T d
        lon, lat = camera_dir_to_lonlat(d_old)
        env = sample_equirect(self.envmap, lon, lat).reshape(H, W, 3).astype(np.float32)
        sun = self.sun.rotated(R_new_from_old) if self.sun is not None else None
        return DistantLight(env, sun)
