"""Synthetic HDR skies for training: the analytic sky of :mod:`..sky` plus procedural clouds and the sun.

Model (z-up frame, physical units of :mod:`..sky`; sun disc excluded from :meth:`SynthSky.radiance`):

* background: ``sky_radiance`` (Preetham clear sky blended towards CIE overcast by ``haze``, with the
  sky model's turbidity and ground albedo below the horizon);
* clouds: a layer seen in perspective (a direction d hits it at ``d_xy / (d_z + 0.06)``), density
  from a random-Fourier fBm field thresholded to the requested ``coverage``, optical depth up to
  ``thickness`` (longer slant paths near the horizon); transmittance ``T = exp(-tau)``;
* cloud radiance (single-bounce-style, per channel): a white body lit by the sun and the sky,
  ``albedo (E_sun,h + E_sky,h) / pi`` darkened for thick clouds, plus a forward-scattering glow
  around the sun (Henyey-Greenstein, g = 0.75) for thin clouds;  ``L = L_sky T + L_cloud (1 - T)``;
* the sun: ``sun_irradiance`` (haze visibility included) times the cloud transmittance at the sun;
  :meth:`SynthSky.dome` splats it bilinearly (energy- and centroid-preserving) into the dome pixels.

Random draws (:func:`random_sky`) cover clear, partly cloudy (sun free or behind a cloud), overcast
and twilight skies.  Everything is deterministic for a seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from ..core import equirect_pixel_lonlat, lonlat_to_world_dir, luminance
from ..lighting.sky import sky_horizontal_irradiance, sky_radiance, sun_irradiance
from ..lighting.skynet.dome import dome_directions, dome_solid_angles

SUN_HALF_ANGLE_RAD = float(np.radians(0.2665))
N_WAVES = 48


@dataclass(frozen=True)
class SynthSky:
    """One procedural sky.

    Attributes:
        sun_dir: (3,) unit vector towards the sun in the sky's z-up frame (may be below the horizon).
        turbidity: Preetham turbidity in [1.7, 12].
        haze: uniform overcast blend of :func:`..sky.sky_radiance` (its ``cloud_cover``), 0..1.
        coverage: fraction of the sky covered by the procedural cloud layer, 0..1.
        thickness: optical depth of the densest cloud.
        cloud_albedo: brightness of a sunlit cloud body relative to a white Lambertian surface.
        ground_albedo: of the sky model's ground below the horizon.
        waves: (K, 4) random-Fourier components of the cloud field: (kx, ky, phase, amplitude).
        sun_half_angle_rad: angular radius of the sun disc (for renderers' soft shadows).
    """

    sun_dir: np.ndarray
    turbidity: float = 3.0
    haze: float = 0.0
    coverage: float = 0.0
    thickness: float = 8.0
    cloud_albedo: float = 0.7
    ground_albedo: float = 0.15
    waves: np.ndarray | None = None
    sun_half_angle_rad: float = SUN_HALF_ANGLE_RAD

    # ---- the duck-typed interface of scenegen.render.SkyParams (so StreetRenderer can use it)
    @property
    def sun_dir_global(self) -> np.ndarray:
        return np.asarray(self.sun_dir, dtype=np.float64)

    def _cloud_tau(self, dirs: np.ndarray) -> np.ndarray:
        """Optical depth (N,) of the cloud layer along unit directions (N, 3); 0 below the horizon."""
        if self.coverage <= 0.0 or self.waves is None:
            return np.zeros(len(dirs))
        up = dirs[:, 2] > 0.0
        p = dirs[:, :2] / (np.maximum(dirs[:, 2], 0.0) + 0.06)[:, None]
        k, phase, amp = self.waves[:, :2], self.waves[:, 2], self.waves[:, 3]
        field = np.sin(p @ k.T + phase[None]) @ amp / np.sqrt(0.5 * (amp**2).sum())  # ~ unit variance
        threshold = float(ndtri(np.clip(1.0 - self.coverage, 1e-4, 1 - 1e-4)))
        density = np.clip((field - threshold) / 0.6, 0.0, 1.0)
        # far clouds (near the horizon) are smaller than a pixel: fade to their mean (a haze band)
        w = np.exp(-np.clip(dirs[:, 2], 0.0, 1.0) / 0.12)
        density = density * (1.0 - w) + w * 0.5 * self.coverage
        slant = 1.0 + 1.5 * (1.0 - np.clip(dirs[:, 2], 0.0, 1.0))
        return np.where(up, self.thickness * density**0.8 * slant, 0.0)

    def _irradiances(self) -> tuple[np.ndarray, np.ndarray]:
        """(sun irradiance after haze, 3), (sky horizontal irradiance, 3); W m^-2."""
        s = np.asarray(self.sun_dir, dtype=np.float64)
        return sun_irradiance(s, self.turbidity, self.haze), sky_horizontal_irradiance(s, self.turbidity, self.haze)

    def radiance(self, dirs: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) float64 from unit z-up directions (N, 3), sun disc excluded."""
        dirs = np.asarray(dirs, dtype=np.float64)
        base = sky_radiance(dirs, self.sun_dir, self.turbidity, self.haze, self.ground_albedo)
        tau = self._cloud_tau(dirs)
        if not np.any(tau > 0):
            return base
        e_sun, e_sky = self._irradiances()
        sun = np.asarray(self.sun_dir, dtype=np.float64)
        e_sun_h = e_sun * max(float(sun[2]), 0.0)
        T = np.exp(-tau)[:, None]
        body = self.cloud_albedo * (e_sun_h + e_sky) / np.pi
        dark = 0.3 + 0.7 * np.exp(-0.12 * tau)[:, None]
        mu = np.clip(dirs @ sun, -1.0, 1.0)
        g = 0.75
        hg = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * mu) ** 1.5)
        glow = e_sun[None] * (0.5 * hg * np.exp(-0.5 * tau))[:, None]
        cloud = body[None] * dark + glow
        return np.where(tau[:, None] > 0, base * T + cloud * (1 - T), base)

    @property
    def sun_transmittance(self) -> float:
        """Fraction of the direct sun passing the cloud layer (haze not included)."""
        s = np.asarray(self.sun_dir, dtype=np.float64)
        return float(np.exp(-self._cloud_tau(s[None]))[0])

    @property
    def sun_irradiance_rgb(self) -> np.ndarray:
        """(3,) irradiance of the sun (haze and clouds applied) on a surface facing it; 0 below the horizon."""
        return self._irradiances()[0] * self.sun_transmittance

    @property
    def sun_visibility(self) -> float:
        """Fraction of the clear-sky sun that reaches the ground (0 below the horizon), 0..1."""
        s = np.asarray(self.sun_dir, dtype=np.float64)
        if s[2] <= 0:
            return 0.0
        clear = luminance(sun_irradiance(s, self.turbidity, 0.0))
        return float(luminance(self.sun_irradiance_rgb) / max(clear, 1e-12))

    @property
    def cloud_cover(self) -> float:  # scenegen.render.SkyParams compatibility
        return float(self.haze)

    def envmap_world(self, height: int, width: int) -> np.ndarray:
        """Radiance (height, width, 3) float32 in the world equirect convention, sun excluded."""
        d = lonlat_to_world_dir(*equirect_pixel_lonlat(height, width)).reshape(-1, 3)
        return self.radiance(d).reshape(height, width, 3).astype(np.float32)

    def dome(self, height: int, width: int, R_sky_from_heading: np.ndarray | None = None,
             supersample: int = 2) -> np.ndarray:
        """HDR sky dome (height, width, 3) float32 in a heading frame, sun included (bilinear splat).

        ``R_sky_from_heading`` (3, 3) rotates heading-frame directions into the sky's frame
        (identity by default).  Each pixel averages ``supersample``^2 directions.
        """
        R = np.eye(3) if R_sky_from_heading is None else np.asarray(R_sky_from_heading, dtype=np.float64)
        s = max(int(supersample), 1)
        fine = dome_directions(height * s, width * s).reshape(-1, 3)
        rad = self.radiance(fine @ R.T).reshape(height, s, width, s, 3).mean(axis=(1, 3))
        e_sun = self.sun_irradiance_rgb
        sun_h = R.T @ np.asarray(self.sun_dir, dtype=np.float64)
        if np.any(e_sun > 0) and sun_h[2] > 0:
            rad = rad + splat_direction(sun_h / np.linalg.norm(sun_h), e_sun, height, width)
        return rad.astype(np.float32)


def splat_direction(direction: np.ndarray, irradiance_rgb: np.ndarray, height: int, width: int) -> np.ndarray:
    """Dome (H, W, 3) holding irradiance (3,) from one upper-hemisphere direction (3,), spread bilinearly
    over the 4 nearest pixel centres (the irradiance-weighted centroid stays at ``direction``)."""
    lon = np.arctan2(direction[1], direction[0])
    lat = np.arcsin(np.clip(direction[2], 0.0, 1.0))
    x = (lon / (2 * np.pi) + 0.5) * width - 0.5
    y = float(np.clip((1.0 - lat / (np.pi / 2)) * height - 0.5, 0.0, height - 1.0))
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0
    out = np.zeros((height, width, 3))
    omega = dome_solid_angles(height, width)
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            j, i = min(y0 + dy, height - 1), (x0 + dx) % width
            out[j, i] += wy * wx * np.asarray(irradiance_rgb) / omega[j, i]
    return out


def random_waves(rng: np.random.Generator, scale: float) -> np.ndarray:
    """(N_WAVES, 4) random-Fourier components of an fBm-like field (power ~ k^-2.6), base wavelength ~ 1/scale."""
    k_mag = scale * np.exp(rng.uniform(0.0, np.log(12.0), N_WAVES))
    theta = rng.uniform(0, 2 * np.pi, N_WAVES)
    k = np.stack([k_mag * np.cos(theta), k_mag * np.sin(theta)], axis=1)
    amp = (k_mag / scale) ** -1.3
    return np.concatenate([k, rng.uniform(0, 2 * np.pi, (N_WAVES, 1)), amp[:, None]], axis=1)


def random_sky(rng: np.random.Generator, sun_dir: np.ndarray | None = None) -> SynthSky:
    """A random sky: ~25 % clear, ~45 % partly cloudy, ~20 % overcast, ~10 % twilight (sun below the horizon).

    ``sun_dir`` (3,) fixes the sun (z-up) instead of drawing it.
    """
    kind = rng.choice(["clear", "cloudy", "overcast", "twilight"], p=[0.25, 0.45, 0.2, 0.1])
    if sun_dir is None:
        if kind == "twilight":
            el = np.radians(rng.uniform(-6.0, 0.5))
        else:
            el = np.arcsin(rng.uniform(np.sin(np.radians(1.0)), np.sin(np.radians(85.0))))
        az = rng.uniform(-np.pi, np.pi)
        sun_dir = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    turbidity = float(np.exp(rng.uniform(np.log(1.8), np.log(9.0))))
    albedo = float(rng.uniform(0.08, 0.3))
    waves = random_waves(rng, float(np.exp(rng.uniform(np.log(1.5), np.log(8.0)))))
    if kind == "clear":
        return SynthSky(sun_dir, turbidity, float(rng.uniform(0.0, 0.15)), 0.0, ground_albedo=albedo)
    if kind == "overcast":
        return SynthSky(sun_dir, turbidity, float(rng.uniform(0.75, 1.0)), float(rng.uniform(0.0, 1.0)),
                        float(rng.uniform(3.0, 25.0)), float(rng.uniform(0.4, 0.8)), albedo, waves)
    coverage = float(rng.uniform(0.1, 0.85))
    return SynthSky(sun_dir, turbidity, float(rng.uniform(0.0, 0.5)), coverage, float(rng.uniform(1.0, 20.0)),
                    float(rng.uniform(0.5, 0.95)), albedo, waves)
