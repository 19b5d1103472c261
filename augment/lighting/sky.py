"""Parametric daylight: an analytic clear sky (Preetham et al. 1999), an overcast CIE sky, a ground, and the sun.

Units: radiance is linear Rec. 709 RGB in "broadband W m^-2 sr^-1": a white extraterrestrial sun
delivers ``SOLAR_CONSTANT_W_M2`` = 1361 W m^-2 per channel (luminance 1361). Photometric values
follow with a luminous efficacy of ~93 lm/W (cd m^-2 = value x 93). These are absolute,
physical-ish magnitudes; images live on their own radiometric scale, which ``make_sky_light``'s
``scale`` maps to (e.g. ~3e-3 for a typical daylight exposure).

Model:

* Sun (``sun_irradiance``): direct normal irradiance through ``m`` air masses (Kasten & Young
  1989), per channel with Rayleigh (0.008735 lambda^-4.08) and Angstrom aerosol optical depth
  (beta = 0.04608 T - 0.04586, alpha = 1.3, Preetham's turbidity T), times the cloud visibility
  ``(1 - cloud_cover) ** SUN_VISIBILITY_EXPONENT``.
* Clear sky: the Preetham/Perez angular distribution and chromaticity (x, y) with turbidity T; its
  absolute level is set so that its horizontal irradiance equals a fraction ``DOWN_SCATTER`` of the
  light the atmosphere removed from the direct beam (Preetham's absolute zenith luminance diverges
  for a high sun). Clear noon, T = 3: direct horizontal ~ 1000 W m^-2, sky ~ 170 W m^-2 (ratio ~ 6).
* Overcast sky: CIE overcast ``L(theta) = L_z (1 + 2 cos theta) / 3``, slightly bluish grey, with a
  horizontal irradiance ``OVERCAST_FRACTION`` x the top-of-atmosphere horizontal irradiance.
  ``cloud_cover`` blends clear -> overcast linearly.
* Below the horizon (and for twilight): the sun's elevation is replaced by a smooth effective
  value so the sky dims exponentially (``TWILIGHT_DEG`` per e-fold) down to a night floor; the
  sky's shape then uses the sun at the horizon. Never NaN.
* Ground (directions below the horizon): Lambertian, ``albedo * E_horizontal / pi`` with
  ``E_horizontal`` = sun (with visibility) + sky.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..core import ConventionError, camera_envmap_directions, check_shape, luminance
from .light import DistantLight, SunLight

SOLAR_CONSTANT_W_M2 = 1361.0
SUN_TOA_RGB = np.array([1.06, 0.99, 0.92])  # white-ish sun above the atmosphere (before norm)
SUN_TOA_RGB = SUN_TOA_RGB / luminance(SUN_TOA_RGB)
CHANNEL_WAVELENGTH_UM = np.array([0.61, 0.55, 0.465])  # effective wavelengths of R, G, B
ANGSTROM_ALPHA = 1.3
DOWN_SCATTER = 0.45  # fraction of the light scattered out of the beam that reaches the ground as sky light
OVERCAST_FRACTION = 0.3  # overcast horizontal irradiance / top-of-atmosphere horizontal irradiance
OVERCAST_RGB = np.array([0.95, 1.0, 1.08]) / luminance(np.array([0.95, 1.0, 1.08]))
SUN_VISIBILITY_EXPONENT = 1.5
TWILIGHT_DEG = 1.5  # e-folding of the twilight sky brightness per degree of sun depression
TWILIGHT_SIN_AT_HORIZON = 0.02  # effective sin(elevation) when the sun sits on the horizon
NIGHT_RADIANCE = 2e-4  # W m^-2 sr^-1 floor (urban night sky glow, ~0.02 cd m^-2)
MIN_SHAPE_ELEVATION_DEG = 1.0  # the Preetham shape is evaluated with the sun at least this high

_XYZ_TO_SRGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)
# Preetham et al. 1999, appendix: zenith chromaticity polynomials [T^2, T, 1] x M x [th^3, th^2, th, 1].
_ZENITH_X = np.array(
    [[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394], [0.11693, -0.21196, 0.06052, 0.25886]]
)
_ZENITH_Y = np.array(
    [[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516], [0.15346, -0.26756, 0.06670, 0.26688]]
)
# Perez coefficients (A..E) as (slope, intercept) in T, for Y, x and y.
_PEREZ_Y = np.array([[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251], [0.1206, -2.5771], [-0.0670, 0.3703]])
_PEREZ_X = np.array([[-0.0193, -0.2592], [-0.0665, 0.0008], [-0.0004, 0.2125], [-0.0641, -0.8989], [-0.0033, 0.0452]])
_PEREZ_YC = np.array([[-0.0167, -0.2608], [-0.0950, 0.0092], [-0.0079, 0.2102], [-0.0441, -1.6537], [-0.0109, 0.0529]])


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if not np.all(np.isfinite(v)) or np.any(n < 1e-12):
        raise ConventionError(f"{name}: expected finite non-zero direction vectors")
    return v / n


def _check_params(turbidity: float, cloud_cover: float, ground_albedo: float = 0.2) -> None:
    if not 1.7 <= turbidity <= 12.0:
        raise ValueError(f"turbidity must be in [1.7, 12] (Preetham's valid range), got {turbidity}")
    if not 0.0 <= cloud_cover <= 1.0:
        raise ValueError(f"cloud_cover must be in [0, 1], got {cloud_cover}")
    if not 0.0 <= ground_albedo <= 1.0:
        raise ValueError(f"ground_albedo must be in [0, 1], got {ground_albedo}")


def air_mass(elevation_rad: float) -> float:
    """Relative optical air mass (Kasten & Young 1989); the elevation is clamped to >= 0."""
    el_deg = float(np.degrees(max(elevation_rad, 0.0)))
    zenith_deg = 90.0 - el_deg
    return float(1.0 / (np.cos(np.radians(zenith_deg)) + 0.50572 * (96.07995 - zenith_deg) ** -1.6364))


def _beam_transmittance(elevation_rad: float, turbidity: float) -> np.ndarray:
    """(3,) per-channel direct-beam transmittance (Rayleigh + Angstrom aerosol)."""
    m = air_mass(elevation_rad)
    lam = CHANNEL_WAVELENGTH_UM
    tau_rayleigh = 0.008735 * lam**-4.08
    beta = 0.04608 * turbidity - 0.04586
    tau_aerosol = beta * lam**-ANGSTROM_ALPHA
    return np.exp(-m * (tau_rayleigh + tau_aerosol))


def _effective_sin_elevation(elevation_rad: float) -> float:
    """sin(elevation) above ~3 degrees, a smooth twilight ramp below (never 0, never negative)."""
    s = float(np.sin(elevation_rad))
    el_deg = float(np.degrees(elevation_rad))
    twilight = TWILIGHT_SIN_AT_HORIZON * np.exp(min(el_deg, 0.0) / TWILIGHT_DEG)
    if el_deg >= 0.0:
        # blend so that the value at the horizon equals the twilight value and joins sin() smoothly
        return float(np.sqrt(s * s + twilight * twilight))
    return float(twilight)


def sun_irradiance(sun_dir_up: np.ndarray, turbidity: float = 3.0, cloud_cover: float = 0.0) -> np.ndarray:
    """Irradiance (3,) RGB, W m^-2, on a surface facing the sun; zero when the sun is below the horizon.

    Args:
        sun_dir_up: (3,) direction towards the sun in a z-up frame (normalised here).
        turbidity: Preetham turbidity, 1.7 (very clear) .. 12 (hazy).
        cloud_cover: 0..1; the sun's visibility is ``(1 - cloud_cover) ** 1.5``.
    """
    _check_params(turbidity, cloud_cover)
    d = _unit(sun_dir_up, "sun_dir_up")
    check_shape(d, (3,), "sun_dir_up")
    if d[2] <= 0.0:
        return np.zeros(3)
    elevation = float(np.arcsin(np.clip(d[2], -1.0, 1.0)))
    visibility = sun_visibility(cloud_cover)
    return SOLAR_CONSTANT_W_M2 * SUN_TOA_RGB * _beam_transmittance(elevation, turbidity) * visibility


def sun_visibility(cloud_cover: float) -> float:
    """Fraction of the direct sun that gets through the clouds, ``(1 - cloud_cover) ** 1.5``."""
    return float((1.0 - float(np.clip(cloud_cover, 0.0, 1.0))) ** SUN_VISIBILITY_EXPONENT)


def _perez(cos_theta: np.ndarray, gamma: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    A, B, C, D, E = coeffs
    cos_theta = np.maximum(cos_theta, 1e-3)
    return (1.0 + A * np.exp(B / cos_theta)) * (1.0 + C * np.exp(D * gamma) + E * np.cos(gamma) ** 2)


def _clear_sky_shape(dirs_up: np.ndarray, sun_shape_dir: np.ndarray, turbidity: float) -> np.ndarray:
    """Relative clear-sky RGB (N, 3) for upper-hemisphere directions; luminance 1 at the zenith... times F ratio."""
    T = turbidity
    theta_s = float(np.arccos(np.clip(sun_shape_dir[2], -1.0, 1.0)))
    cos_theta = np.clip(dirs_up[:, 2], 0.0, 1.0)
    gamma = np.arccos(np.clip(dirs_up @ sun_shape_dir, -1.0, 1.0))
    tvec = np.array([T * T, T, 1.0])
    svec = np.array([theta_s**3, theta_s**2, theta_s, 1.0])
    x_z = tvec @ _ZENITH_X @ svec
    y_z = tvec @ _ZENITH_Y @ svec
    out = []
    for zenith_value, table in ((1.0, _PEREZ_Y), (x_z, _PEREZ_X), (y_z, _PEREZ_YC)):
        coeffs = table[:, 0] * T + table[:, 1]
        f0 = _perez(np.array([1.0]), np.array([theta_s]), coeffs)[0]
        out.append(zenith_value * _perez(cos_theta, gamma, coeffs) / f0)
    Y, x, y = out
    y = np.maximum(y, 1e-6)
    X = x / y * Y
    Z = (1.0 - x - y) / y * Y
    rgb = np.stack([X, Y, Z], axis=1) @ _XYZ_TO_SRGB.T
    return np.maximum(rgb, 0.0)


def _hemisphere_quadrature(n_theta: int = 48, n_phi: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """Upper-hemisphere directions (M, 3) and their cosine-weighted solid angles (M,)."""
    th_edges = np.linspace(0.0, np.pi / 2, n_theta + 1)
    th = 0.5 * (th_edges[:-1] + th_edges[1:])
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    band = np.cos(th_edges[:-1]) - np.cos(th_edges[1:])
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    dirs = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], axis=-1).reshape(-1, 3)
    w = (np.repeat(band[:, None], n_phi, axis=1) * 2 * np.pi / n_phi * np.cos(TH)).reshape(-1)
    return dirs, w


_QUAD_DIRS, _QUAD_W = _hemisphere_quadrature()


@lru_cache(maxsize=64)
def _clear_shape_irradiance(shape_dir: tuple[float, float, float], turbidity: float) -> tuple[float, np.ndarray]:
    """The clear-sky shape's horizontal irradiance (luminance, and (3,) RGB) for a shape sun direction (cached: one
    L1 estimate asks for the same sun several times)."""
    shape_q = _clear_sky_shape(_QUAD_DIRS, np.asarray(shape_dir), turbidity)
    rgb = (shape_q * _QUAD_W[:, None]).sum(axis=0)
    rgb.flags.writeable = False
    return float(luminance(shape_q) @ _QUAD_W), rgb


def _sky_components(sun_dir: np.ndarray, turbidity: float, cloud_cover: float):
    """Per-call constants: shape sun direction, clear-sky gain, overcast zenith radiance, sky horizontal irradiance."""
    elevation = float(np.arcsin(np.clip(sun_dir[2], -1.0, 1.0)))
    # Sun direction used for the sky's shape: at least MIN_SHAPE_ELEVATION_DEG above the horizon.
    min_el = np.radians(MIN_SHAPE_ELEVATION_DEG)
    horiz = sun_dir[:2]
    horiz = horiz / np.linalg.norm(horiz) if np.linalg.norm(horiz) > 1e-9 else np.array([1.0, 0.0])
    shape_el = max(elevation, min_el)
    shape_dir = np.array([horiz[0] * np.cos(shape_el), horiz[1] * np.cos(shape_el), np.sin(shape_el)])
    if elevation > min_el:
        shape_dir = sun_dir
    toa_horizontal = SOLAR_CONSTANT_W_M2 * _effective_sin_elevation(elevation)
    t_lum = float(luminance(SUN_TOA_RGB * _beam_transmittance(max(elevation, 0.0), turbidity)))
    clear_target = DOWN_SCATTER * (1.0 - t_lum) * toa_horizontal  # W m^-2 horizontal (luminance)
    shape_lum_e, shape_e = _clear_shape_irradiance(tuple(float(v) for v in shape_dir), float(turbidity))
    clear_gain = clear_target / max(shape_lum_e, 1e-12)
    overcast_target = OVERCAST_FRACTION * toa_horizontal
    overcast_zenith = overcast_target * 9.0 / (7.0 * np.pi)
    # Horizontal sky irradiance per channel (for the ground), blended like the radiance.
    clear_e = clear_gain * shape_e
    overcast_e = overcast_target * OVERCAST_RGB
    sky_e = (1.0 - cloud_cover) * clear_e + cloud_cover * overcast_e
    return shape_dir, clear_gain, overcast_zenith, sky_e


def sky_radiance(
    dirs_up: np.ndarray,
    sun_dir_up: np.ndarray,
    turbidity: float = 3.0,
    cloud_cover: float = 0.0,
    ground_albedo: float = 0.2,
) -> np.ndarray:
    """Radiance (N, 3) float64, linear RGB W m^-2 sr^-1 (see module doc), arriving from ``dirs_up``; sun disc excluded.

    Args:
        dirs_up: (N, 3) directions in a z-up frame (normalised here).
        sun_dir_up: (3,) direction towards the sun, same frame; may be below the horizon.
        turbidity: Preetham turbidity in [1.7, 12].
        cloud_cover: 0 (clear, Preetham) .. 1 (CIE overcast).
        ground_albedo: Lambertian albedo of the ground seen below the horizon.
    """
    _check_params(turbidity, cloud_cover, ground_albedo)
    dirs = _unit(dirs_up, "dirs_up")
    check_shape(dirs, ("N", 3), "dirs_up")
    sun = _unit(sun_dir_up, "sun_dir_up")
    check_shape(sun, (3,), "sun_dir_up")
    shape_dir, clear_gain, overcast_zenith, sky_e = _sky_components(sun, turbidity, cloud_cover)
    cos_theta = dirs[:, 2]
    up = cos_theta >= 0.0
    sky = 0.0  # the clear / overcast blend; a weight of 0 skips its component's work
    if cloud_cover < 1.0:
        sky = (1.0 - cloud_cover) * (clear_gain * _clear_sky_shape(dirs, shape_dir, turbidity))
    if cloud_cover > 0.0:
        overcast = overcast_zenith * ((1.0 + 2.0 * np.clip(cos_theta, 0.0, 1.0)) / 3.0)[:, None] * OVERCAST_RGB[None]
        sky = sky + cloud_cover * overcast
    sun_e = sun_irradiance(sun, turbidity, cloud_cover) * max(float(sun[2]), 0.0)
    ground = ground_albedo * (sun_e + sky_e) / np.pi
    out = np.where(up[:, None], sky, ground[None, :])
    return np.maximum(out, NIGHT_RADIANCE)


def rotation_up_from_frame(up: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """R (3, 3) taking vectors of a frame to a z-up frame whose +z is ``up`` (x axis from ``hint``)."""
    z = _unit(up, "up")
    x = hint - (hint @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
        if np.linalg.norm(x) < 1e-6:
            x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=0)


def make_sky_light(
    sun_dir: np.ndarray,
    up: np.ndarray,
    turbidity: float = 3.0,
    cloud_cover: float = 0.0,
    ground_albedo: float = 0.2,
    height: int = 128,
    width: int = 256,
    scale: float = 1.0,
) -> DistantLight:
    """A :class:`DistantLight` in the frame of ``sun_dir`` and ``up`` (e.g. the camera frame).

    The envmap (height, width, 3) float32 uses the camera-frame equirect convention of that frame;
    the sun is a :class:`SunLight` with ``sun_irradiance`` (visibility applied), or None when the sun
    is below the horizon. Every radiance is multiplied by ``scale`` (physical units -> image units).
    """
    if height < 2 or width < 4:
        raise ValueError(f"envmap size must be at least 2 x 4, got {height} x {width}")
    if not np.isfinite(scale) or scale < 0:
        raise ValueError(f"scale must be finite and >= 0, got {scale}")
    sun_f = _unit(sun_dir, "sun_dir")
    check_shape(sun_f, (3,), "sun_dir")
    R_up_from_f = rotation_up_from_frame(np.asarray(up, dtype=np.float64), np.array([0.0, 0.0, 1.0]))
    dirs_f = camera_envmap_directions(height, width).reshape(-1, 3)
    sun_up = R_up_from_f @ sun_f
    rad = sky_radiance(dirs_f @ R_up_from_f.T, sun_up, turbidity, cloud_cover, ground_albedo)
    env = (rad * scale).reshape(height, width, 3).astype(np.float32)
    e_sun = sun_irradiance(sun_up, turbidity, cloud_cover)
    sun = None
    if np.any(e_sun > 0):
        sun = SunLight(direction=sun_f, irradiance_rgb=e_sun * scale, visibility=sun_visibility(cloud_cover))
    return DistantLight(env, sun)


def sky_horizontal_irradiance(sun_dir_up: np.ndarray, turbidity: float = 3.0, cloud_cover: float = 0.0) -> np.ndarray:
    """Irradiance (3,) RGB, W m^-2, that the sky alone (sun excluded) delivers to a horizontal surface."""
    _check_params(turbidity, cloud_cover)
    sun = _unit(sun_dir_up, "sun_dir_up")
    check_shape(sun, (3,), "sun_dir_up")
    return _sky_components(sun, turbidity, cloud_cover)[3]


def sun_horizontal_irradiance(sun_dir_up: np.ndarray, turbidity: float = 3.0, cloud_cover: float = 0.0) -> np.ndarray:
    """Irradiance (3,) RGB, W m^-2, that the sun alone delivers to a horizontal surface (0 below the horizon)."""
    sun = _unit(sun_dir_up, "sun_dir_up")
    return sun_irradiance(sun, turbidity, cloud_cover) * max(float(sun[2]), 0.0)
