"""Procedural traffic cones: a flat base plate under a revolved plastic body with retro-reflective bands.

Variants: ``cone`` (the standard road cone: square base, conical body, 1-2 white bands), ``tall``
(a delineator post: a rubber base, a slim post with a grip ring at the top, 2-4 bands) and ``drum``
(a channelizer drum: a wide barrel with alternating orange / white bands on a rubber base).  The base
plate spans the box's w x l exactly; the body is a surface of revolution up to the box's height.
Object frame: x front, y left, z up, metres, origin at the bottom centre, the base flat on z = 0.
"""

from __future__ import annotations

import numpy as np

from .asset import Asset, Material
from .class_sizes import read_class_sizes
from .mesh_parts import MeshPart, merge_parts, target_wlh
from .procedural import srgb_to_linear
from .revolve import box, revolve, torus, with_material
from .validate import validate_asset

_VARIANTS = ("cone", "tall", "drum")
PLASTIC, BAND, BASE = range(3)
_ORANGE = ("FF5A0A", "F2661A", "FF4A14", "E8501E", "FF6F00", "E33B12")


def procedural_traffic_cone_variants() -> tuple[str, ...]:
    """Variants of :func:`procedural_traffic_cone` (``cone``, ``tall``, ``drum``)."""
    return _VARIANTS


def _banded(part: MeshPart, bands: list[tuple[float, float]]) -> MeshPart:
    """``part`` with the faces whose centroid height lies in one of ``bands`` (z ranges) set to BAND."""
    zc = part.vertices[part.faces].mean(axis=1)[:, 2]
    inside = np.zeros(len(zc), dtype=bool)
    for z0, z1 in bands:
        inside |= (zc > z0) & (zc < z1)
    return with_material(part, np.where(inside, BAND, part.face_material))


def _profile_with_edges(z: np.ndarray, r: np.ndarray, edges: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The (z, r) profile with a point inserted where it crosses each band edge (rising segments only),
    so material boundaries follow rings."""
    zz, rr = list(z), list(r)
    for e in sorted(edges):
        for i in range(len(zz) - 1):
            if zz[i] < e < zz[i + 1]:
                t = (e - zz[i]) / (zz[i + 1] - zz[i])
                zz.insert(i + 1, e)
                rr.insert(i + 1, rr[i] + t * (rr[i + 1] - rr[i]))
                break
    return np.array(zz), np.array(rr)


def procedural_traffic_cone(seed: int, wlh=None, variant: str | None = None) -> Asset:
    """A traffic cone, delineator post or drum, deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (shade of orange, band layout, proportions).
        wlh: target box [w, l, h] metres, or None (the category's typical size for the variant).
        variant: one of :func:`procedural_traffic_cone_variants` or None (drawn; a drum only when
            the target is wide enough, a tall post when it is tall and narrow).

    Returns:
        An :class:`Asset` (category ``movable_object.trafficcone``) with ``wlh`` equal to the target;
        a flat base on z = 0.  A few hundred to ~1.5 k triangles.

    Raises:
        ValueError: unknown variant, or a wlh that is not 3 positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xC0E5])
    u = rng.random(10)
    target = target_wlh(wlh, "procedural_traffic_cone")
    if variant is None:
        if target is None:
            variant = "cone" if u[0] < 0.75 else ("tall" if u[0] < 0.92 else "drum")
        else:
            side, h = float(min(target[:2])), float(target[2])
            p_drum = 0.5 if side > 0.5 and 0.75 < h < 1.15 else 0.0
            p_tall = 0.6 if h > 0.95 and side < 0.45 else (0.15 if h > 0.8 else 0.0)
            variant = "drum" if u[0] < p_drum else ("tall" if u[0] < p_drum + p_tall else "cone")
    if variant not in _VARIANTS:
        raise ValueError(f"procedural_traffic_cone: unknown variant {variant!r}; "
                         f"expected one of {', '.join(_VARIANTS)}")
    if target is None:
        size = read_class_sizes()["movable_object.trafficcone"]
        typical = {"cone": (0.40, 0.40, 0.72), "tall": (0.32, 0.32, 1.05), "drum": (0.58, 0.58, 1.0)}[variant]
        side = typical[0] * (0.92 + 0.16 * u[1])
        target = np.clip(np.array([side, side, typical[2] * (0.9 + 0.2 * u[2])]), size.min_wlh, size.max_wlh)
    w, l, h = (float(x) for x in target)
    half = 0.5 * min(w, l)
    orange = srgb_to_linear(np.array([int(_ORANGE[int(u[3] * 6) % 6][i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)
    materials = (
        Material("cone_plastic", base_color=orange * (0.92 + 0.08 * u[4]), roughness=0.45 + 0.1 * u[5]),
        Material("reflective_band", base_color=np.array([0.82, 0.82, 0.8]), roughness=0.3,
                 retroreflective=0.8 + 0.2 * u[6]),
        Material("base_rubber", base_color=np.array([0.03, 0.03, 0.03]) if variant != "cone" or u[7] < 0.5
                 else orange * 0.8, roughness=0.85),
    )
    plate_t = min(0.035 if variant == "cone" else 0.06, 0.1 * h)
    parts = [box(np.array([-l / 2, -w / 2, 0.0]), np.array([l / 2, w / 2, plate_t]),
                 BASE if variant != "cone" or u[7] < 0.5 else PLASTIC)]
    z_axis = np.array([0.0, 0.0, 1.0])
    body_h = h - plate_t
    if variant == "cone":
        rb = half * (0.72 + 0.1 * u[8])
        rt = min(0.03, 0.25 * rb)
        z = plate_t + np.array([0.0, 0.0, 0.02, 0.35, 0.7, 0.97, 1.0]) * body_h
        z[2] = plate_t + 0.02 * body_h
        r = np.array([0.0, rb, rb * 0.97, 0.0, 0.0, rt, 0.0])
        r[3] = rb + (rt - rb) * 0.35
        r[4] = rb + (rt - rb) * 0.7
        z[-1] = h
        n_bands = 1 if h < 0.6 or u[9] < 0.4 else 2
        bands = [(plate_t + 0.55 * body_h, plate_t + 0.72 * body_h)]
        if n_bands == 2:
            bands = [(plate_t + f0 * body_h, plate_t + f1 * body_h) for f0, f1 in ((0.63, 0.78), (0.38, 0.5))]
    elif variant == "tall":
        rb = min(half * 0.55, 0.06)
        rt = rb * 0.75
        ring_major, ring_minor = 0.04 + 0.01 * u[8], 0.014
        ring_z = h - ring_major - ring_minor  # the grip ring's top reaches h
        top = ring_z - ring_major + 0.012
        z = np.array([plate_t, plate_t, plate_t + 0.05, top - 0.03, top, top])
        r = np.array([0.0, min(half * 0.8, rb * 2.0), rb, rt, rt, 0.0])
        n_bands = 2 + int(u[9] * 3)
        span = top - 0.05 - (plate_t + 0.25 * body_h)
        step = span / n_bands
        bands = [(top - 0.05 - (i + 0.5) * step - 0.3 * step, top - 0.05 - (i + 0.5) * step + 0.3 * step)
                 for i in range(n_bands)]
        parts.append(torus(np.array([0.0, 0.0, ring_z]), np.array([0.0, 1.0, 0.0]), ring_major, ring_minor, PLASTIC,
                           n_major=20, n_minor=6))
    else:  # drum
        rb = half * 0.96
        z = plate_t + np.array([0.0, 0.0, 0.04, 0.9, 0.97, 0.985, 1.0]) * body_h
        z[-1] = h
        r = np.array([0.0, rb * 0.9, rb, rb * 0.93, rb * 0.85, rb * 0.5, 0.0])
        n_bands = 2 + int(u[9] * 2)
        pitch = 0.86 * body_h / (2 * n_bands)
        bands = [(plate_t + 0.06 * body_h + (2 * i + 1) * pitch, plate_t + 0.06 * body_h + (2 * i + 2) * pitch)
                 for i in range(n_bands)]
    edges = [e for b in bands for e in b]
    zz, rr = _profile_with_edges(z, r, edges)
    body = revolve(zz, rr, np.zeros(3), z_axis, PLASTIC, n_around=28)
    parts.insert(1, _banded(body, bands))
    V, F, M = merge_parts(parts)
    N = np.concatenate([p.normals for p in parts])
    asset = Asset(name=f"procedural-trafficcone-{variant}-{seed}", vertices=V, faces=F, face_material=M,
                  materials=materials, vertex_normals=N, category="movable_object.trafficcone")
    return validate_asset(asset)


__all__ = ["procedural_traffic_cone", "procedural_traffic_cone_variants"]
