"""Procedural trailers (nuScenes ``vehicle.trailer``, annotated without the tractor that pulls them).

Above 6 m a trailer is a semi-trailer: a deck on two main beams, landing legs (raised, feet off the
ground) behind the kingpin end and a rear axle group of 1-3 axles (twin or wide single tyres), a rear
underrun bar with the lamps.  Below 6 m it is a drawbar trailer: an A-frame drawbar with a coupler in
front and one or two axles under the middle.  On top: ``box`` (a van body with rear doors), ``container``
(a ribbed shipping container with corner posts on a skeletal chassis) or ``flatbed`` (a flat deck with
low sides and a load).  Object frame x front (the coupling end), y left, z up, metres, origin at the
bottom centre, tyres touching z = 0.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .asset import Asset
from .class_sizes import read_class_sizes
from .mesh_parts import target_wlh
from .vehicle_parts import (ACCENT, CARGO, CHROME, METAL, PAINT, TAILLIGHT, TRIM, Region, axle_wheels, box,
                            choose_variant, finish_vehicle, light_pair, loft_x, pick_colour, rear_doors,
                            tube, vehicle_materials, wheel_well)

CATEGORY = "vehicle.trailer"
_SEED_SALT = 0x7EA1

# (name, sRGB hex, weight)
_BOX_PALETTE = (
    ("white", "F0F0EC", 10.0), ("light grey", "C4C6C6", 3.0), ("silver", "A9ACAE", 2.0), ("red", "B01C1C", 1.0),
    ("blue", "2A4F9C", 1.0), ("yellow", "E8B820", 0.5), ("green", "2F7A3A", 0.5),
)
_CONTAINER_PALETTE = (
    ("sea blue", "4A7FA8", 2.0), ("red brown", "8B3A2B", 2.5), ("grey", "8A8C8C", 2.0), ("green", "2E6B34", 1.0),
    ("orange", "D9621C", 1.0), ("white", "E8E8E2", 1.0), ("yellow", "E3B521", 0.5), ("dark blue", "1F3560", 1.0),
    ("maroon", "5A1E22", 0.8),
)
_STRIPE_PALETTE = (
    ("red", "B01C1C", 1.0), ("blue", "1F4A8C", 1.0), ("green", "2E6B34", 1.0), ("orange", "D9621C", 0.6),
    ("black", "141518", 0.6),
)


def procedural_trailer_variants() -> tuple[str, ...]:
    """Names of the trailer variants :func:`procedural_trailer` builds."""
    return ("box", "container", "flatbed")


def procedural_trailer(seed: int, wlh: ArrayLike | None = None, variant: str | None = None) -> Asset:
    """A trailer mesh built to the box ``wlh``, deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (variant when None, proportions, axles, colours, load).
        wlh: target box [w, l, h] metres, or None for the category's mean size.
        variant: ``box``, ``container``, ``flatbed`` or None (flatbeds mostly for short or low boxes).

    Returns:
        An :class:`Asset` of category ``vehicle.trailer`` whose ``wlh`` is the target; about 4-10 k triangles.

    Raises:
        ValueError: an unknown variant, or a wlh that is not 3 finite positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, _SEED_SALT])
    given = target_wlh(wlh, "procedural_trailer")
    small = given is not None and (given[1] < 6.0 or given[2] < 2.6)
    weights = {"box": 0.2 if small else 0.5, "container": 0.1 if small else 0.3, "flatbed": 0.7 if small else 0.2}
    variant = choose_variant(rng, variant, weights, "procedural_trailer")
    W, L, H = given if given is not None else read_class_sizes()[CATEGORY].mean_wlh
    palette = {"box": _BOX_PALETTE, "container": _CONTAINER_PALETTE, "flatbed": _CONTAINER_PALETTE[:3]}[variant]
    name_c, body_c = pick_colour(rng, palette)
    _, stripe_c = pick_colour(rng, _STRIPE_PALETTE)
    materials = vehicle_materials(rng, stripe_c, body_c, accent_clearcoat=0.6 if variant == "box" else 0.1)
    hw = W / 2
    drawbar = L < 6.0
    parts, z_d, x_front = _chassis(rng, hw, L, H, drawbar, low=(variant == "flatbed"))
    if variant == "box":
        parts += _box_body(rng, hw, L, H, z_d, x_front)
    elif variant == "container":
        parts += _container(hw, L, H, z_d, x_front)
    else:
        parts += _flat_load(rng, hw, L, H, z_d, x_front)
    return finish_vehicle(parts, materials, np.array([W, L, H]),
                          f"procedural-trailer-{variant}-{seed}-{name_c.replace(' ', '_')}", CATEGORY)


def _chassis(rng: np.random.Generator, hw: float, L: float, H: float, drawbar: bool, low: bool):
    """Deck frame, wheels, legs or drawbar, underrun bar and lamps; returns (parts, deck height, body front x)."""
    parts = []
    if drawbar:
        ld = float(np.clip(0.25 * L, 0.7, 1.4))
        x_front = L / 2 - ld
        r = float(min(np.clip(0.26 + 0.02 * L, 0.26, 0.38), 0.2 * H))
        z_d = float(min(2 * r + 0.12, 0.42 * H))
        r = min(r, 0.5 * (z_d - 0.08))
        body = x_front + L / 2
        xc = -L / 2 + 0.45 * body
        axles = [xc] if body < 3.8 else [xc - 0.45, xc + 0.45]
        dual, tw = False, float(np.clip(0.5 * r, 0.15, 0.2))
        # A-frame drawbar to the coupler at the very front
        zc = float(min(0.5, z_d - 0.05))
        tip = (L / 2 - 0.12, 0.0, zc)
        for s in (1.0, -1.0):
            parts.append(tube((x_front + 0.05, s * 0.7 * hw, z_d - 0.08), tip, 0.04, METAL, 8))
        parts.append(box((L / 2 - 0.2, -0.06, zc - 0.06), (L / 2, 0.06, zc + 0.06), METAL))
    else:
        x_front = L / 2
        z_d = float(min(rng.uniform(1.1, 1.3) if not low else rng.uniform(1.2, 1.45), 0.4 * H))
        r = float(min(0.5, 0.5 * (z_d - 0.15)))
        n_ax = 1 if L < 7.5 else (2 if L < 10.5 else 3)
        ro = float(np.clip(0.09 * L, 0.9, 1.6))
        axles = [-L / 2 + ro + r + 1.31 * k for k in range(n_ax)]
        dual = rng.random() < 0.6
        tw = 0.16 + 0.26 * r if dual else 0.2 + 0.35 * r
        # landing legs, raised: feet 0.1-0.3 m off the ground
        xl = L / 2 - float(np.clip(0.2 * L, 1.2, 2.6))
        foot = float(rng.uniform(0.1, 0.3)) * min(1.0, z_d / 1.1)
        for s in (1.0, -1.0):
            y = s * (hw - 0.45)
            parts.append(box((xl - 0.07, y - 0.07, foot + 0.05), (xl + 0.07, y + 0.07, z_d - 0.3), METAL))
            parts.append(box((xl - 0.15, y - 0.15, foot), (xl + 0.15, y + 0.15, foot + 0.05), METAL))
        parts.append(tube((xl, -(hw - 0.45), 0.6 * z_d), (xl, hw - 0.45, 0.6 * z_d), 0.03, METAL, 8))
    # main beams and the deck frame
    zb = max(z_d - 0.35, 0.5 * z_d)
    for s in (1.0, -1.0):
        parts.append(box((-L / 2 + 0.1, s * 0.5 - 0.05, zb), (x_front - 0.05, s * 0.5 + 0.05, z_d), METAL))
    for xa in axles:
        y_out = hw - 0.04
        parts += axle_wheels(xa, r, tw, y_out, dual=dual)
        inner = y_out - (2 * tw + 0.04 if dual else tw) - 0.03
        parts.append(wheel_well(xa, r, max(inner, 0.1), z_d - 0.02))
        parts.append(tube((xa, -inner, r), (xa, inner, r), 0.06, METAL, 10))
    # rear underrun bar with the lamps
    zr = float(min(max(0.4, 0.45 * z_d), z_d - 0.12))
    parts.append(box((-L / 2 + 0.05, -hw + 0.1, zr), (-L / 2 + 0.15, hw - 0.1, zr + 0.1), METAL))
    parts += light_pair(-L / 2 + 0.05, -1.0, hw - 0.28, zr + 0.01, zr + 0.09, 0.3, TAILLIGHT, depth=0.03)
    return parts, z_d, x_front


def _box_body(rng: np.random.Generator, hw: float, L: float, H: float, z_d: float, x_front: float) -> list:
    """A van body from the rear to ``x_front``, floor at z_d, roof at H, maybe a stripe, and rear doors."""
    x0, e = -L / 2 + 0.03, 0.04
    x1 = x_front - e
    regions, cuts = [], ()
    if rng.random() < 0.4:
        zs = z_d + float(rng.uniform(0.1, 0.25)) * (H - z_d)
        zt = zs + 0.1 * (H - z_d)
        regions.append(Region(PAINT, (x0 + 0.2, -np.inf, zs), (x1 - 0.2, np.inf, zt), (0.0, 1.0, 0.0), 0.7, True))
        cuts = (zs, zt)
    parts = [loft_x([x0, x1], z_d, H, hw, radius=0.05, mat=ACCENT, regions=regions, z_cuts=cuts,
                    end_round=(0.0, e), n_corner=2)]
    parts += rear_doors(-L / 2, x0, hw, z_d, H)
    # side skirt between the legs and the wheels of long trailers
    if L > 9.0 and rng.random() < 0.4:
        for y0, y1 in ((hw - 0.12, hw - 0.08), (-hw + 0.08, -hw + 0.12)):
            parts.append(box((-L / 2 + 0.35 * L, y0, 0.45), (L / 2 - 0.3 * L, y1, z_d), TRIM))
    return parts


def _container(hw: float, L: float, H: float, z_d: float, x_front: float) -> list:
    """A shipping container on the chassis: panels, corrugation ribs, rails, corner posts and rear door bars."""
    x0, x1 = -L / 2, x_front
    t = 0.03
    parts = [box((x0 + t, -hw + t, z_d + 0.05), (x1 - t, hw - t, H - 0.05), ACCENT)]
    n = max(int((x1 - x0 - 0.4) / 0.3), 1)
    for xr in np.linspace(x0 + 0.25, x1 - 0.25, n):
        for y0, y1 in ((hw - t, hw - 0.005), (-hw + 0.005, -hw + t)):
            parts.append(box((xr - 0.06, y0, z_d + 0.12), (xr + 0.06, y1, H - 0.12), ACCENT))
    for z0, z1 in ((z_d, z_d + 0.12), (H - 0.12, H)):
        parts.append(box((x0 + 0.1, -hw, z0), (x1 - 0.1, hw, z1), ACCENT))
    for xa, xb in ((x0, x0 + 0.12), (x1 - 0.12, x1)):
        for ya, yb in ((-hw, -hw + 0.12), (hw - 0.12, hw)):
            parts.append(box((xa, ya, z_d), (xb, yb, H), ACCENT))
    for yr in np.linspace(-0.6, 0.6, 4) * hw:
        parts.append(tube((x0 + t, yr, z_d + 0.2), (x0 + t, yr, H - 0.2), 0.02, CHROME, 6))
    parts.append(box((x0 + 0.01, -0.01, z_d + 0.12), (x0 + t + 0.005, 0.01, H - 0.12), TRIM))
    return parts


def _flat_load(rng: np.random.Generator, hw: float, L: float, H: float, z_d: float, x_front: float) -> list:
    """A flat deck with low sides and a load (tarp-covered blocks, crates); the first block reaches H when
    the sides do not."""
    x0, x1 = -L / 2, x_front
    deck_top = z_d + 0.12
    parts = [box((x0, -hw, z_d), (x1, hw, deck_top), CARGO if rng.random() < 0.3 else METAL)]
    side = float(min(rng.uniform(0.25, 0.45), max(H - deck_top, 0.05)))
    for ya, yb in ((hw - 0.04, hw), (-hw, -hw + 0.04)):
        parts.append(box((x0 + 0.02, ya, deck_top), (x1 - 0.02, yb, deck_top + side), METAL))
    for xa, xb in ((x0, x0 + 0.04), (x1 - 0.04, x1)):
        parts.append(box((xa, -hw + 0.04, deck_top), (xb, hw - 0.04, deck_top + side), METAL))
    if H > deck_top + side + 0.01 or rng.random() < 0.6:
        n = int(rng.integers(1, 4))
        seg = (x1 - x0 - 0.2) / n
        for k in range(n):
            bl = seg * float(rng.uniform(0.6, 0.9))
            xc = x1 - 0.1 - seg * (k + 0.5)
            bw = (hw - 0.06) * float(rng.uniform(0.75, 0.98))
            top = H if k == 0 else deck_top + float(rng.uniform(0.3, 1.0)) * max(H - deck_top, 0.1)
            parts.append(loft_x([xc - bl / 2 + 0.05, xc + bl / 2 - 0.05], deck_top, top, bw, radius=0.06, mat=CARGO,
                                end_round=(0.05, 0.05), n_corner=2))
    return parts


__all__ = ["procedural_trailer", "procedural_trailer_variants"]
