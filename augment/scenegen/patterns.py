"""Procedural surface patterns of the street materials, evaluated at ray hit points.

All functions are pure, vectorised and deterministic (integer hashing, no global RNG state).
Coordinates are street-frame metres (x along the road, y left, z up).
"""

from __future__ import annotations

import numpy as np

from .street import SurfaceMaterial

PATTERNS = ("plain", "asphalt", "paving", "grass", "facade", "paint", "foliage")


def hash01(ix: np.ndarray, iy: np.ndarray, salt: int = 0) -> np.ndarray:
    """Deterministic pseudo-random values in [0, 1) for integer lattice points (any equal shapes)."""
    h = (np.asarray(ix, dtype=np.int64) * 73856093) ^ (np.asarray(iy, dtype=np.int64) * 19349663) ^ (salt * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(0x1000000)


def value_noise(x: np.ndarray, y: np.ndarray, salt: int = 0) -> np.ndarray:
    """Smooth value noise in [0, 1) on a unit lattice (bilinear with smoothstep)."""
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    ix, iy = x0.astype(np.int64), y0.astype(np.int64)
    a = hash01(ix, iy, salt)
    b = hash01(ix + 1, iy, salt)
    c = hash01(ix, iy + 1, salt)
    d = hash01(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def fbm(x: np.ndarray, y: np.ndarray, octaves: int = 3, salt: int = 0) -> np.ndarray:
    """Fractal sum of value noise, normalised to [0, 1)."""
    total, amp, norm = np.zeros_like(np.asarray(x, dtype=np.float64)), 1.0, 0.0
    for o in range(octaves):
        total = total + amp * value_noise(x * 2**o, y * 2**o, salt + 17 * o)
        norm += amp
        amp *= 0.5
    return total / norm


def _asphalt(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Albedo factor (N,) of asphalt: fine and coarse grain, darker smoother wheel tracks mid-lane."""
    fine = fbm(x / 0.15, y / 0.15, 2, salt=1)
    coarse = fbm(x / 7.0, y / 7.0, 3, salt=2)
    lane_pos = np.mod(y, 2.8) / 2.8
    tracks = 1.0 - 0.12 * (np.exp(-(((lane_pos - 0.27) / 0.07) ** 2)) + np.exp(-(((lane_pos - 0.73) / 0.07) ** 2)))
    return (0.8 + 0.4 * fine) * (0.85 + 0.3 * coarse) * tracks


def _paving(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Albedo factor (N,) of 0.6 m paving tiles with darker joints."""
    tile = 0.6
    fx, fy = np.mod(x, tile) / tile, np.mod(y, tile) / tile
    joint = (fx < 0.04) | (fy < 0.04)
    var = 0.88 + 0.24 * hash01(np.floor(x / tile), np.floor(y / tile), salt=3)
    return np.where(joint, 0.6, var) * (0.9 + 0.2 * fbm(x / 3, y / 3, 2, salt=4))


def _grass(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return 0.6 + 0.8 * fbm(x / 4.0, y / 4.0, 4, salt=5)


def _paint(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return 0.75 + 0.3 * fbm(x / 0.3, y / 0.3, 2, salt=6)


def _foliage(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return 0.6 + 0.8 * hash01(np.floor(x / 0.25), np.floor((y + z) / 0.25), salt=7)


# pattern -> albedo factor at street-frame points (x, y, z) of that pattern
_ALBEDO_FACTORS = {"asphalt": _asphalt, "paving": _paving, "grass": _grass, "paint": _paint, "foliage": _foliage}


def _facade(materials: tuple[SurfaceMaterial, ...], material_id: np.ndarray, points_street: np.ndarray,
            normals_street: np.ndarray, albedo: np.ndarray, gloss: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Albedo (N, 3) and gloss (N,) of facade points: window rows (some lit), shop windows, stains, roofs.

    ``albedo`` / ``gloss``: the materials' base values at these points.
    """
    floor_h = np.array([m.floor_height_m for m in materials])[material_id]
    pitch = np.array([m.window_pitch_m for m in materials])[material_id]
    window = np.array([m.window_albedo for m in materials])[material_id]
    x, y, zz = points_street[:, 0], points_street[:, 1], points_street[:, 2]
    n = normals_street
    u = np.where(np.abs(n[:, 0]) > np.abs(n[:, 1]), y, x)
    wall = np.abs(n[:, 2]) < 0.5
    fu, fz = np.mod(u, pitch) / pitch, np.mod(zz, floor_h) / floor_h
    upper = (zz > floor_h) & (fu > 0.22) & (fu < 0.78) & (fz > 0.3) & (fz < 0.8)
    fu2 = np.mod(u, 2 * pitch) / (2 * pitch)
    shop = (zz < floor_h) & (zz > 0.5) & (zz < floor_h - 0.6) & (fu2 > 0.08) & (fu2 < 0.92)
    is_window = wall & (upper | shop)
    # some windows lit from inside / with blinds: vary their albedo
    lit = hash01(np.floor(u / pitch), np.floor(zz / floor_h), salt=8)
    win_rgb = window * (0.7 + 1.2 * lit[:, None] ** 3)
    stain = 0.85 + 0.3 * fbm(u / 5.0, zz / 5.0, 2, salt=9)
    band = np.where(wall & (fz < 0.06) & (zz > floor_h), 0.8, 1.0)
    wall_rgb = albedo * (stain * band)[:, None]
    roof = ~wall
    wall_rgb[roof] = albedo[roof] * 0.6
    return np.where(is_window[:, None], win_rgb, wall_rgb), np.where(is_window, gloss, 0.0)


def surface_albedo(
    materials: tuple[SurfaceMaterial, ...],
    material_id: np.ndarray,
    points_street: np.ndarray,
    normals_street: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Albedo and gloss at surface points.

    Args:
        materials: the scene's material table.
        material_id: (N,) int64 material index per point.
        points_street: (N, 3) float64 hit points, street frame, metres.
        normals_street: (N, 3) float64 unit geometric normals, street frame.

    Returns:
        albedo: (N, 3) float64 linear RGB.
        gloss: (N,) float64 strength of the mirror sky reflection.
    """
    base = np.array([m.albedo for m in materials], dtype=np.float64)
    albedo = base[material_id].copy()
    gloss = np.array([m.gloss for m in materials])[material_id]
    pattern = np.array([PATTERNS.index(m.pattern) for m in materials])[material_id]
    x, y, z = points_street[:, 0], points_street[:, 1], points_street[:, 2]
    for name, factor in _ALBEDO_FACTORS.items():
        sel = pattern == PATTERNS.index(name)
        if sel.any():
            albedo[sel] *= factor(x[sel], y[sel], z[sel])[:, None]
    idx = np.nonzero(pattern == PATTERNS.index("facade"))[0]
    if len(idx):
        albedo[idx], gloss[idx] = _facade(materials, material_id[idx], points_street[idx], normals_street[idx],
                                          albedo[idx], gloss[idx])
    return np.clip(albedo, 0.0, 1.0), gloss
