"""Procedural cars: a lofted, curved body with a glass greenhouse, wheels in arches, lights and trim.

The body is a loft along x of rounded cross-sections (superellipses in y-z whose width narrows
above the belt line: the "tumblehome"), between a side-profile roof curve ``z_top(x)`` and an
underbody curve ``z_bot(x)`` that rises into wheel arches; its plan-view width rounds off at both
ends, closing the surface.  Materials are assigned per face from its position and normal
(windscreen / side windows / rear window with pillars in between, bumpers, grille, head and tail
lights).  Wheels are revolved tyre profiles with a spoked rim cap.  Output is an :class:`Asset` in
the object frame (x front, y left, z up, metres, origin at the bottom centre, tyres touching z = 0).
"""

from __future__ import annotations

import numpy as np

from .asset import Asset, Material
from .car_body import BODY_SPECS, BODY_WEIGHTS, body_part, jitter_spec
from .car_wheels import wheel_parts, wheel_well_parts
from .mesh_parts import merge_parts
from .validate import validate_asset


def procedural_car_variants() -> tuple[str, ...]:
    """Names of the body types :func:`procedural_car` builds."""
    return tuple(BODY_SPECS)


# ----------------------------------------------------------------------------- paint palette

# (name, sRGB hex, metallic, weight) -- weights roughly follow world car-colour popularity
# (white ~ 35 %, black ~ 20 %, grey ~ 18 %, silver ~ 10 %, blue ~ 7 %, red ~ 6 %, others).
_PALETTE: tuple[tuple[str, str, float, float], ...] = (
    ("pure white", "F2F2EE", 0.0, 12.0),
    ("pearl white", "E8E6DF", 0.3, 10.0),
    ("arctic white", "EDEFF0", 0.0, 7.0),
    ("cream white", "E6E1D3", 0.1, 3.0),
    ("jet black", "0C0C0D", 0.0, 8.0),
    ("black metallic", "141518", 0.5, 8.0),
    ("midnight black", "1A1B20", 0.4, 4.0),
    ("graphite grey", "3C3F44", 0.6, 5.0),
    ("gunmetal grey", "53565C", 0.6, 4.0),
    ("dark grey", "2E3034", 0.5, 3.0),
    ("mid grey", "6E7074", 0.4, 3.0),
    ("nardo grey", "8A8C8C", 0.0, 2.0),
    ("silver", "B5B8BB", 0.7, 5.0),
    ("bright silver", "C8CACC", 0.7, 3.0),
    ("champagne silver", "BDB5A6", 0.6, 2.0),
    ("navy blue", "1B2A4A", 0.5, 2.0),
    ("dark blue", "1F3560", 0.5, 2.0),
    ("royal blue", "2A4F9C", 0.4, 1.5),
    ("sky blue", "6F9CC8", 0.3, 0.8),
    ("steel blue", "4A6580", 0.5, 1.0),
    ("bright red", "B01C1C", 0.0, 2.0),
    ("dark red", "6E1418", 0.4, 1.5),
    ("candy red", "9A1420", 0.5, 1.5),
    ("maroon", "4E1A22", 0.4, 0.8),
    ("orange", "D9621C", 0.2, 0.5),
    ("yellow", "E3B521", 0.1, 0.4),
    ("racing green", "1E3B2C", 0.4, 0.6),
    ("olive green", "55603E", 0.3, 0.4),
    ("teal", "1F5D63", 0.4, 0.4),
    ("beige", "C2B28F", 0.2, 0.8),
    ("bronze", "7A5B3C", 0.6, 0.6),
    ("brown", "4A3528", 0.4, 0.8),
    ("taxi yellow", "F0B21A", 0.0, 0.3),
    ("purple", "3E2A52", 0.5, 0.3),
)


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB in [0, 1] -> linear RGB (same shape)."""
    c = np.asarray(srgb, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def paint_palette() -> list[tuple[str, np.ndarray, float, float]]:
    """The paint palette as (name, linear RGB (3,), metallic, weight) entries (>= 30 colours)."""
    out = []
    for name, hexcode, metallic, weight in _PALETTE:
        srgb = np.array([int(hexcode[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0
        out.append((name, srgb_to_linear(srgb), metallic, weight))
    return out


# ----------------------------------------------------------------------------- public entry point


def procedural_car(seed: int, body: str | None = None, paint: tuple | None = None) -> Asset:
    """A plausible car mesh, deterministic for ``seed``.

    Args:
        seed: random seed (body choice when ``body`` is None, dimension jitter, paint, glass tint).
        body: one of :func:`procedural_car_variants` (``sedan``, ``hatchback``, ``suv``, ``van``) or None.
        paint: optional linear RGB (3,) paint colour in [0, 1], or (r, g, b, metallic).

    Returns:
        An :class:`Asset` (category ``vehicle.car``), object frame (x front, y left, z up, metres),
        origin at the bottom centre; the tyres touch z = 0.  About 8-10 k triangles.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x5CA4])
    names = list(BODY_SPECS)
    if body is None:
        w = np.array([BODY_WEIGHTS[n] for n in names])
        body = names[int(rng.choice(len(names), p=w / w.sum()))]
    else:
        rng.random()  # keep the stream aligned with the body=None case
    if body not in BODY_SPECS:
        raise ValueError(f"procedural_car: unknown body {body!r}; expected one of {', '.join(names)}")
    spec = jitter_spec(BODY_SPECS[body](), rng)
    materials, paint_name = _materials(rng, paint)

    parts = [body_part(spec)]
    parts += wheel_parts(spec)
    parts += wheel_well_parts(spec)
    vertices, faces, face_material = merge_parts(parts)

    # Origin at the bottom centre of the box, tyres on z = 0.
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = vertices - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    normals = np.concatenate([p.normals for p in parts])
    asset = Asset(
        name=f"procedural-{body}-{seed}-{paint_name.replace(' ', '_')}",
        vertices=vertices, faces=faces, face_material=face_material, materials=materials,
        vertex_normals=normals, uv=None, category="vehicle.car",
    )
    return validate_asset(asset)


# ----------------------------------------------------------------------------- materials


def _materials(rng: np.random.Generator, paint: tuple | None) -> tuple[tuple[Material, ...], str]:
    palette = paint_palette()
    weights = np.array([p[3] for p in palette])
    idx = int(rng.choice(len(palette), p=weights / weights.sum()))
    name, color, metallic, _ = palette[idx]
    color = np.clip(color * rng.uniform(0.93, 1.07), 0.0, 1.0)  # small per-car variation
    if paint is not None:
        p = np.asarray(paint, dtype=np.float64).ravel()
        if p.size not in (3, 4) or not np.all(np.isfinite(p)) or p.min() < 0 or p[:3].max() > 1:
            raise ValueError(f"procedural_car: paint must be linear (r, g, b[, metallic]) in [0, 1], got {paint!r}")
        color, name = p[:3].copy(), "custom"
        metallic = float(p[3]) if p.size == 4 else 0.3
    paint_rough = float(rng.uniform(0.30, 0.45))
    glass_opacity = float(rng.uniform(0.30, 0.50))
    tint = np.array([0.015, 0.020, 0.022]) * rng.uniform(0.8, 1.2)
    rim_dark = rng.random() < 0.25
    mats = (
        Material("paint", base_color=color, metallic=metallic, roughness=paint_rough, clearcoat=1.0),
        Material("glass", base_color=tint, metallic=0.0, roughness=0.05, specular=0.5, opacity=glass_opacity),
        Material("trim", base_color=np.array([0.025, 0.025, 0.027]), metallic=0.0, roughness=0.75),
        Material("tyre", base_color=np.array([0.02, 0.02, 0.02]), metallic=0.0, roughness=0.9, specular=0.3),
        Material("rim", base_color=np.array([0.12, 0.12, 0.13]) if rim_dark else np.array([0.62, 0.62, 0.64]),
                 metallic=1.0, roughness=0.3),
        Material("headlight", base_color=np.array([0.85, 0.85, 0.85]), metallic=0.0, roughness=0.06,
                 emission=np.array([0.05, 0.05, 0.05])),
        Material("taillight", base_color=np.array([0.45, 0.015, 0.02]), metallic=0.0, roughness=0.12),
    )
    return mats, name


__all__ = ["paint_palette", "procedural_car", "procedural_car_variants", "srgb_to_linear"]
