"""Sky-dome geometry of the learned sky model: the upper-hemisphere map, frames, panoramas, peaks.

Frames:

* **heading frame** (z-up): z = gravity up, x = the camera's optical axis projected onto the
  horizontal plane ("ahead"), y = left.  Sky domes and sky vectors live in this frame, so a sky
  vector predicted from an image is relative to where the camera looks (no compass needed).
* **world panorama frame** of an HDRI: z up, world equirect convention of :mod:`streetaug.augment.core.envmap`
  (``lon = atan2(dy, dx)``, ``lat = asin(dz)``).  Poly Haven / ``shared/data/hdri`` files store
  the compass azimuth increasing to the right (``azimuth = 360 u / W - 180``); seen from inside the
  sphere that is clockwise, so :func:`load_hdri` flips the columns and ``lon = -azimuth``.

Sky dome (``H x W``, 1 : 4): the upper hemisphere only, rows from the zenith (top) to the horizon,
columns in the world equirect longitude convention: pixel (i, j) has its centre at
``lon = ((i + 0.5) / W - 0.5) 2 pi`` and ``lat = (1 - (j + 0.5) / H) pi / 2``.  A 32 x 128 dome has
2.8 deg pixels; the paper's 64 x 256 has 1.4 deg pixels.

Radiance is linear RGB; domes handed to the network are scaled so that the LDR the network sees is
``hdr_to_ldr(dome)`` (the contract's camera response at EV 0).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from ...core import InputError, check_shape, lonlat_to_world_dir, luminance, sample_equirect, world_dir_to_lonlat

PEAK_PERCENTILE = 98.0  # the peak region: luminance >= this percentile (as shared/data/hdri/index.json)


# ----------------------------------------------------------------------------- dome grid


def dome_lonlat(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (rad) of every dome pixel centre, each (H, W)."""
    lon = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * np.pi
    lat = (1.0 - (np.arange(height) + 0.5) / height) * np.pi / 2.0
    return np.meshgrid(lon, lat)


@lru_cache(maxsize=8)
def dome_directions(height: int, width: int) -> np.ndarray:
    """Unit heading-frame direction (H, W, 3) float64 of every dome pixel centre (read-only)."""
    d = lonlat_to_world_dir(*dome_lonlat(height, width))
    d.setflags(write=False)
    return d


@lru_cache(maxsize=8)
def dome_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle (sr) of each dome pixel, (H, W); sums to 2 pi."""
    lat_edges = (1.0 - np.arange(height + 1) / height) * np.pi / 2.0
    band = np.sin(lat_edges[:-1]) - np.sin(lat_edges[1:])
    out = np.repeat((band * 2.0 * np.pi / width)[:, None], width, axis=1)
    out.setflags(write=False)
    return out


def dome_pixel_size_rad(height: int) -> float:
    """Angular size (rad) of one dome pixel along a meridian (= along the equator)."""
    return float(np.pi / 2.0 / height)


def sample_dome(dome: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Bilinear lookup (N, C) of a dome (H, W, C) in heading-frame unit directions (N, 3); below the
    horizon returns the horizon row; wraps in longitude."""
    H, W = dome.shape[:2]
    lon, lat = world_dir_to_lonlat(dirs)
    x = np.mod(lon / (2.0 * np.pi) + 0.5, 1.0) * W - 0.5
    y = np.clip((1.0 - np.maximum(lat, 0.0) / (np.pi / 2.0)) * H - 0.5, 0.0, H - 1.0)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    y1 = np.minimum(y0 + 1, H - 1)
    xa, xb = np.mod(x0, W), np.mod(x0 + 1, W)
    top = dome[y0, xa] * (1 - fx) + dome[y0, xb] * fx
    bottom = dome[y1, xa] * (1 - fx) + dome[y1, xb] * fx
    return top * (1 - fy) + bottom * fy


# ----------------------------------------------------------------------------- frames


def heading_from_camera(up_cam: np.ndarray) -> np.ndarray:
    """Rotation ``R_heading_from_cam`` (3, 3) for a camera whose gravity-up direction is ``up_cam`` (3,).

    Convention: heading x = the optical axis (+z camera) projected onto the horizontal plane,
    z = up, y = z x x (left).  Raises ValueError if the camera looks straight up or down.
    """
    up = np.asarray(up_cam, dtype=np.float64)
    check_shape(up, (3,), "up_cam")
    n = np.linalg.norm(up)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError("up_cam must be a finite non-zero direction")
    z = up / n
    fwd = np.array([0.0, 0.0, 1.0]) - z[2] * z
    if np.linalg.norm(fwd) < 1e-6:
        raise ValueError("camera looks straight up or down: the heading frame is undefined")
    x = fwd / np.linalg.norm(fwd)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=0)


def camera_from_angles(yaw_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0) -> np.ndarray:
    """``R_world_from_cam`` (3, 3): OpenCV camera looking at azimuth ``yaw`` (world lon), tilted up by
    ``pitch``, rolled clockwise (as seen by the camera) by ``roll``; world z up."""
    # level camera looking along world +x: cam z -> +x, cam x (right) -> -y, cam y (down) -> -z
    R0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    R_roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])  # about the camera z axis
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    R_pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])  # about camera x: +pitch looks up
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    R_yaw = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return R_yaw @ R0 @ R_pitch @ R_roll


# ----------------------------------------------------------------------------- panoramas


def load_hdri(path: str | Path) -> np.ndarray:
    """Read a Radiance ``.hdr`` / EXR equirect panorama as float32 (H, W, 3) linear RGB in the world
    equirect convention (columns flipped from the file's clockwise azimuth, see module doc)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: panorama file not found")
    image = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
    if image is None or image.ndim != 3:
        raise InputError(f"{path}: cannot decode as an HDR panorama (.hdr or .exr, 3 channels)")
    H, W = image.shape[:2]
    if W != 2 * H:
        raise InputError(f"{path}: expected an equirectangular 2:1 panorama, got {W} x {H}")
    rgb = np.ascontiguousarray(image[:, ::-1, ::-1]).astype(np.float32)
    if not np.all(np.isfinite(rgb)):
        raise InputError(f"{path}: panorama contains NaN or Inf")
    return np.maximum(rgb, 0.0)


def hdri_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """World direction (3,) of a (clockwise azimuth, elevation) pair as written in ``hdri/index.json``."""
    return lonlat_to_world_dir(np.radians(-azimuth_deg), np.radians(elevation_deg))


def panorama_to_dome(pano_world: np.ndarray, height: int, width: int, yaw_rad: float = 0.0) -> np.ndarray:
    """Energy-preserving sky dome (height, width, 3) float32 of a world panorama (Hp, Wp, 3), in a
    heading frame rotated by ``yaw_rad`` about z (heading x = world lon ``yaw_rad``).

    The rotation is a whole-column roll of the panorama (exact to its pixel size), then an area
    average of the upper half down to the dome.
    """
    check_shape(pano_world, ("H", "W", 3), "panorama")
    Hp, Wp = pano_world.shape[:2]
    shift = int(round(yaw_rad / (2.0 * np.pi) * Wp))
    upper = np.roll(pano_world[: Hp // 2], -shift, axis=1)
    return cv2.resize(np.ascontiguousarray(upper), (width, height), interpolation=cv2.INTER_AREA).astype(np.float32)


def render_perspective(pano_world: np.ndarray, K: np.ndarray, R_world_from_cam: np.ndarray, width: int, height: int,
                       supersample: int = 2) -> np.ndarray:
    """Pinhole view (height, width, 3) float32 of a world panorama, with ``supersample``^2 rays per pixel.

    K (3, 3): pixel centres at integers; R_world_from_cam (3, 3): OpenCV camera to world.
    """
    s = max(int(supersample), 1)
    off = (np.arange(s) + 0.5) / s - 0.5
    u, v = np.meshgrid((np.arange(width)[:, None] + off[None]).ravel(), (np.arange(height)[:, None] + off[None]).ravel())
    rays = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3) @ np.linalg.inv(K).T
    d_world = rays @ np.asarray(R_world_from_cam).T
    lon, lat = world_dir_to_lonlat(d_world)
    rgb = sample_equirect(pano_world, lon, lat).reshape(height, s, width, s, 3)
    return rgb.mean(axis=(1, 3)).astype(np.float32)


# ----------------------------------------------------------------------------- peaks


def find_peak(dome: np.ndarray, percentile: float = PEAK_PERCENTILE) -> np.ndarray:
    """Peak (sun) direction (3,) of a dome (H, W, 3) in its own frame.

    The method of ``shared/data/hdri/index.json`` on the dome: pixels with luminance >= the
    ``percentile`` of the dome's luminance, 8-connected with longitude wrap-around; among the
    components the one with the largest luminance x solid angle (the sun, not a large bright cloud);
    its luminance x solid-angle weighted centroid on the unit sphere.
    """
    check_shape(dome, ("H", "W", 3), "dome")
    H, W = dome.shape[:2]
    lum = luminance(np.asarray(dome, dtype=np.float64))
    omega = dome_solid_angles(H, W)
    threshold = np.percentile(lum, percentile)
    mask = lum >= threshold
    if mask.mean() > 2.0 * (1.0 - percentile / 100.0):  # ties (a flat map): only what stands out
        mask = lum > threshold
        if not mask.any():
            mask = lum >= threshold
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    if n > 1:  # join components touching across the longitude seam
        left, right = labels[:, 0], labels[:, -1]
        parent = np.arange(n + 1)

        def root(a: int) -> int:
            while parent[a] != a:
                a = parent[a]
            return a

        for j in range(H):
            for jj in (j - 1, j, j + 1):
                if 0 <= jj < H and left[j] > 0 and right[jj] > 0:
                    ra, rb = root(int(left[j])), root(int(right[jj]))
                    if ra != rb:
                        parent[max(ra, rb)] = min(ra, rb)
        roots = np.array([root(i) for i in range(n + 1)])
        labels = roots[labels]
    w = lum * omega
    energy = ndimage.sum(w, labels, index=np.arange(labels.max() + 1))
    energy[0] = -1.0
    region = labels == int(np.argmax(energy))
    dirs = dome_directions(H, W)[region]
    d = (dirs * w[region][:, None]).sum(axis=0)
    return d / np.linalg.norm(d)


def peak_centroid(dome: np.ndarray, fraction: float = 0.05) -> np.ndarray:
    """Direction (3,) of the brightest blob of a dome (H, W, 3): centroid, weighted by (luminance - median)
    x solid angle, of the pixels 8-connected to the brightest one that exceed the median by at least
    ``fraction`` x (max - median).  (``find_peak`` is the index.json definition; this one measures where
    a decoder put its peak, unbiased by a broad glow.)"""
    check_shape(dome, ("H", "W", 3), "dome")
    H, W = dome.shape[:2]
    lum = luminance(np.asarray(dome, dtype=np.float64))
    background = float(np.median(lum))
    j, i = np.unravel_index(np.argmax(lum), lum.shape)
    shift = W // 2 - i  # centre the maximum so its blob never crosses the seam
    excess = np.roll(lum - background, shift, axis=1)
    labels, _ = ndimage.label(excess >= fraction * excess.max(), structure=np.ones((3, 3), dtype=bool))
    region = np.roll(labels == labels[j, W // 2], -shift, axis=1)
    w = ((lum - background) * dome_solid_angles(H, W))[region]
    d = (dome_directions(H, W)[region] * w[:, None]).sum(axis=0)
    return d / np.linalg.norm(d)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (deg) between direction vectors (..., 3) (normalised here)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
