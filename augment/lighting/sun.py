"""Sun position from the ephemeris (pysolar) for nuScenes locations, in the global and camera frames.

Convention: the global frame is the nuScenes map of ``log.location`` with x = east, y = north,
z = up (the maps are small enough that grid north = true north at their origin). pysolar (>= 0.8)
returns the azimuth in degrees clockwise from north (90 = east, 180 = south) and the altitude in
degrees above the horizon (with atmospheric refraction).
"""

from __future__ import annotations

import datetime as dt
import warnings
from dataclasses import dataclass

import numpy as np

from ...datasets.sample import CameraView
from ..core import check_shape, rotate_vectors

# Map origins (lat, lon in degrees) of the nuScenes map expansion (public devkit constants).
LOCATION_LATLON: dict[str, tuple[float, float]] = {
    "boston-seaport": (42.336849169438615, -71.05785369873047),
    "singapore-onenorth": (1.2882100868743724, 103.78475189208984),
    "singapore-hollandvillage": (1.2993652317780957, 103.78217697143555),
    "singapore-queenstown": (1.2782562240223188, 103.76741409301758),
}


@dataclass(frozen=True)
class SunPosition:
    """Where the sun is.

    Attributes:
        direction_global: (3,) float64 unit vector towards the sun, global frame (x east, y north, z up).
        elevation_deg: altitude above the horizon (negative below it), degrees.
        azimuth_deg: degrees clockwise from north (0 = north, 90 = east, 180 = south).
    """

    direction_global: np.ndarray
    elevation_deg: float
    azimuth_deg: float

    @property
    def above_horizon(self) -> bool:
        return self.elevation_deg > 0.0


def azimuth_elevation_to_enu(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit (3,) east-north-up direction from a compass azimuth (clockwise from north) and an elevation."""
    az = np.radians(azimuth_deg)
    el = np.radians(elevation_deg)
    return np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])


def location_latlon(location: str) -> tuple[float, float]:
    """(lat, lon) in degrees of a known location; raises ValueError listing the known ones."""
    if location not in LOCATION_LATLON:
        known = ", ".join(sorted(LOCATION_LATLON))
        raise ValueError(f"unknown location {location!r}: the sun position needs one of {known}")
    return LOCATION_LATLON[location]


def sun_direction_global(location: str, timestamp_us: int) -> SunPosition:
    """Sun position at a nuScenes location and a UTC time (microseconds since the Unix epoch)."""
    from pysolar import solar

    lat, lon = location_latlon(location)
    if timestamp_us is None or not np.isfinite(float(timestamp_us)):
        raise ValueError(f"timestamp_us must be a finite number of microseconds, got {timestamp_us!r}")
    when = dt.datetime.fromtimestamp(int(timestamp_us) / 1e6, tz=dt.timezone.utc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pysolar warns about leap-second tables for recent dates
        elevation = float(solar.get_altitude(lat, lon, when))
        azimuth = float(solar.get_azimuth(lat, lon, when)) % 360.0
    return SunPosition(azimuth_elevation_to_enu(azimuth, elevation), elevation, azimuth)


def sun_direction_camera(view: CameraView, location: str) -> np.ndarray:
    """Unit (3,) direction towards the sun in the camera frame of ``view``."""
    sun = sun_direction_global(location, view.timestamp_us)
    T = np.asarray(view.T_cam_from_global)
    check_shape(T, (4, 4), "T_cam_from_global")
    d = rotate_vectors(T, sun.direction_global[None])[0]
    return d / np.linalg.norm(d)


def up_direction_camera(view: CameraView) -> np.ndarray:
    """Unit (3,) global up (+z) expressed in the camera frame of ``view``."""
    d = rotate_vectors(np.asarray(view.T_cam_from_global), np.array([[0.0, 0.0, 1.0]]))[0]
    return d / np.linalg.norm(d)
