"""Equirectangular maps: the camera-frame map of the contract and the world (z-up) map of sky domes.

* Camera-frame map (``envmap_camera.exr``): direction ``d`` has ``lon = atan2(dx, dz)`` (0 = ahead,
  +90 deg = right) and ``lat = asin(-dy)`` (+90 deg = image up).
* World (z-up) map: ``lon = atan2(dy, dx)`` (0 = +x, +90 deg = +y), ``lat = asin(dz)``.
* Both: continuous map coordinates (u, v), 0 at the left/top edge, give ``lon = (u/W - 0.5) 2 pi`` and
  ``lat = (0.5 - v/H) pi``; pixel (i, j) has its centre at u = i + 0.5, v = j + 0.5.
  :func:`sample_equirect` is the one bilinear lookup (wraps in longitude, clamps in latitude).
"""

from __future__ import annotations

import numpy as np



def equirect_pixel_lonlat(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (rad) of every pixel centre of an H x W map, each (H, W)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    lon = (u - 0.5) * 2.0 * np.pi
    lat = (0.5 - v) * np.pi
    return np.meshgrid(lon, lat)


def lonlat_to_uv(lon: np.ndarray, lat: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous map coordinates (u in [0, W), v in [0, H]) of longitudes/latitudes (rad)."""
    u = np.mod(np.asarray(lon) / (2.0 * np.pi) + 0.5, 1.0) * width
    v = (0.5 - np.asarray(lat) / np.pi) * height
    return u, v


def camera_dir_to_lonlat(d_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame directions (..., 3) -> (lon, lat) in rad (camera equirect convention)."""
    d = np.asarray(d_cam, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.arctan2(d[..., 0], d[..., 2]), np.arcsin(np.clip(-d[..., 1], -1.0, 1.0))


def lonlat_to_camera_dir(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(lon, lat) in rad -> unit camera-frame directions (..., 3) (camera equirect convention)."""
    c = np.cos(lat)
    return np.stack([c * np.sin(lon), -np.sin(lat), c * np.cos(lon)], axis=-1)


def world_dir_to_lonlat(d_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """z-up directions (..., 3) -> (lon, lat) in rad (world equirect convention)."""
    d = np.asarray(d_world, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.arctan2(d[..., 1], d[..., 0]), np.arcsin(np.clip(d[..., 2], -1.0, 1.0))


def lonlat_to_world_dir(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(lon, lat) in rad -> unit z-up directions (..., 3) (world equirect convention)."""
    c = np.cos(lat)
    return np.stack([c * np.cos(lon), c * np.sin(lon), np.sin(lat)], axis=-1)


def camera_envmap_directions(height: int, width: int) -> np.ndarray:
    """Unit camera-frame direction of every pixel centre of a camera-frame equirect map, (H, W, 3)."""
    lon, lat = equirect_pixel_lonlat(height, width)
    return lonlat_to_camera_dir(lon, lat)


def equirect_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle (sr) of each pixel of an H x W equirect map, (H, W); sums to 4 pi."""
    lat_edges = (0.5 - np.arange(height + 1) / height) * np.pi
    band = np.sin(lat_edges[:-1]) - np.sin(lat_edges[1:])  # (H,)
    return np.repeat((band * 2.0 * np.pi / width)[:, None], width, axis=1)


def sample_equirect(envmap: np.ndarray, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W, C) equirect map at (lon, lat) (rad); wraps in longitude.

    Returns an array of shape ``lon.shape + (C,)``.
    """
    H, W = envmap.shape[:2]
    u, v = lonlat_to_uv(lon, lat, H, W)
    x = u - 0.5
    y = np.clip(v - 0.5, 0.0, H - 1.0)
    x0f, y0f = np.floor(x), np.floor(y)
    fx = (x - x0f)[..., None]
    fy = (y - y0f)[..., None]
    x0, y0 = x0f.astype(np.int64), y0f.astype(np.int64)
    y1 = np.minimum(y0 + 1, H - 1)
    x0w = np.mod(x0, W)
    x1w = np.mod(x0 + 1, W)
    # rows of the flattened map (one gather each: a third faster than four 2-D fancy indexings, the same values)
    flat = np.asarray(envmap).reshape(H * W, *envmap.shape[2:])
    r0, r1 = y0 * W, y1 * W
    gx = 1 - fx
    top = flat.take(r0 + x0w, axis=0) * gx + flat.take(r0 + x1w, axis=0) * fx
    bottom = flat.take(r1 + x0w, axis=0) * gx + flat.take(r1 + x1w, axis=0) * fx
    return top * (1 - fy) + bottom * fy
