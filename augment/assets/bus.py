"""Procedural buses: rigid (``vehicle.bus.rigid``) and articulated (``vehicle.bus.bendy``).

A bus section is a lofted box body with rounded edges whose underside rises into the wheel arches;
its faces take a livery (body colour, a skirt of a second colour), a window band along both sides
with black pillars, a big windscreen with a destination sign above it, glazed doors on the kerb side
(either side: nuScenes drives on the right in Boston and on the left in Singapore), a rear window and
lamps.  A roof equipment pod (air conditioning) sits on top.  A rigid bus has 2 axles (3 above 13.5 m:
a tag axle), dual rear tyres; a bendy bus has two sections joined by a bellows and 3 axles.  Object
frame x front, y left, z up, metres, origin at the bottom centre, tyres touching z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .asset import Asset
from .class_sizes import read_class_sizes
from .mesh_parts import target_wlh
from .vehicle_parts import (ACCENT, GLASS, HEADLIGHT, INDICATOR, PAINT, TAILLIGHT, TRIM, Region, arch_bottom,
                            arch_stations, axle_wheels, box, choose_variant, finish_vehicle, light_pair,
                            loft_x, mirror_pair, pick_colour, vehicle_materials, wheel_well)

_SEED_SALT = 0xB05
_CATEGORY = {"rigid": "vehicle.bus.rigid", "bendy": "vehicle.bus.bendy"}

# (name, sRGB hex, weight): body colours and skirt / stripe colours of city bus liveries
_BODY_PALETTE = (
    ("white", "F0F0EC", 4.0), ("red", "C8102E", 2.0), ("green", "4A9A3C", 2.0), ("purple", "5B2C83", 0.8),
    ("yellow", "F2C230", 1.2), ("blue", "2A5CAA", 1.5), ("silver", "B8BBBE", 1.0), ("orange", "E07020", 0.5),
)
_SKIRT_PALETTE = (
    ("dark grey", "3A3C40", 3.0), ("black", "141518", 2.0), ("red", "A81C1C", 1.5), ("green", "2E6B34", 1.5),
    ("blue", "1F3F7A", 1.5), ("purple", "4A2470", 0.6), ("yellow", "E8B820", 0.6), ("silver", "A9ACAE", 1.0),
)


def procedural_bus_variants() -> tuple[str, ...]:
    """Names of the bus variants :func:`procedural_bus` builds (``rigid``, ``bendy``)."""
    return ("rigid", "bendy")


def procedural_bus(seed: int, wlh: ArrayLike | None = None, variant: str | None = None) -> Asset:
    """A bus mesh built to the box ``wlh``, deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (variant when None, proportions, doors, livery).
        wlh: target box [w, l, h] metres (mirrors included), or None for the variant's mean size.
        variant: ``rigid`` (category ``vehicle.bus.rigid``), ``bendy`` (``vehicle.bus.bendy``) or None
            (rigid mostly; bendy for boxes longer than 15 m).

    Returns:
        An :class:`Asset` whose ``wlh`` is the target; about 6-14 k triangles.

    Raises:
        ValueError: an unknown variant, or a wlh that is not 3 finite positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, _SEED_SALT])
    given = target_wlh(wlh, "procedural_bus")
    long_box = given is not None and given[1] > 15.0
    weights = {"rigid": 0.1 if long_box else 0.9, "bendy": 0.9 if long_box else 0.1}
    variant = choose_variant(rng, variant, weights, "procedural_bus")
    category = _CATEGORY[variant]
    W, L, H = given if given is not None else read_class_sizes()[category].mean_wlh
    name_b, body_c = pick_colour(rng, _BODY_PALETTE)
    _, skirt_c = pick_colour(rng, _SKIRT_PALETTE)
    materials = vehicle_materials(rng, body_c, skirt_c, paint_metallic=0.05)

    m_out = float(np.clip(0.5 * (W - rng.uniform(2.5, 2.6)), 0.06, 0.32))
    hw = max(W / 2 - m_out, 0.45 * W)
    r = float(min(np.clip(0.30 + 0.02 * L, 0.4, 0.5), 0.17 * H))
    tw = 0.2 + 0.2 * r
    pod_h = float(min(rng.uniform(0.2, 0.35), 0.12 * H))
    Hb = H - pod_h
    door_side = 1.0 if rng.random() < 0.5 else -1.0
    fo = float(np.clip(0.22 * L, 1.6, 2.8))
    ro = float(np.clip(0.27 * L, 1.5, 3.6))
    look = _Look(hw=hw, Hb=Hb, r=r, door_side=door_side, clear=float(min(0.3, 0.9 * r)),
                 pillar=float(rng.uniform(1.2, 1.6)), z_w0=float(np.clip(0.33 * Hb, 0.7, 1.25)),
                 z_skirt=float(np.clip(rng.uniform(0.55, 0.75), 0.3, 0.25 * Hb)))
    parts = []
    if variant == "rigid":
        xf, xr = L / 2 - fo, -L / 2 + ro
        axles = [(xf, False), (xr, True)] + ([(xr - 1.35, False)] if L > 13.5 else [])
        mid_door = 0.5 * (xf + xr) - 0.3
        parts += _section(look, -L / 2, L / 2, [a for a, _ in axles], front=True, rear=True,
                          doors=[(xf + r + 0.2, min(xf + r + 1.3, L / 2 - 0.35)), (mid_door - 0.6, mid_door + 0.6)])
        pod = (L / 2 - 0.2 * L - 0.4 * L, L / 2 - 0.2 * L)
        parts.append(_pod(look, *pod, H))
    else:
        lb = float(np.clip(0.05 * L, 0.6, 1.0))
        Lf = float(rng.uniform(0.53, 0.58)) * (L - lb)
        xj0, xj1 = L / 2 - Lf, L / 2 - Lf - lb  # joint: front section's rear, rear section's front
        xf, xm, xr = L / 2 - fo, xj0 + float(np.clip(0.12 * Lf, 1.0, 1.8)), -L / 2 + ro
        axles = [(xf, False), (xm, True), (xr, True)]
        door_f = (xf + r + 0.2, min(xf + r + 1.3, L / 2 - 0.35))
        mid_f = 0.5 * (xf + xm) - 0.2
        mid_r = 0.5 * (xj1 + xr) + 0.2
        parts += _section(look, xj0, L / 2, [xf, xm], front=True, rear=False,
                          doors=[door_f, (mid_f - 0.6, mid_f + 0.6)])
        parts += _section(look, -L / 2, xj1, [xr], front=False, rear=True, doors=[(mid_r - 0.6, mid_r + 0.6)])
        parts.append(_bellows(look, xj1 - 0.1, xj0 + 0.1))
        parts.append(_pod(look, L / 2 - 0.15 * L - 0.25 * L, L / 2 - 0.15 * L, H))
    for xa, dual in axles:
        parts += axle_wheels(xa, r, tw, hw - 0.04, dual=dual)
        inner = hw - 0.04 - (2 * tw + 0.04 if dual else tw) - 0.02
        parts.append(wheel_well(xa, r, inner, 2 * r + 0.1))
    parts += mirror_pair(L / 2 - 0.04, hw - 0.05, W / 2, Hb - 0.35, float(np.clip(0.12 * Hb, 0.25, 0.42)), drop=0.1)
    return finish_vehicle(parts, materials, np.array([W, L, H]),
                          f"procedural-bus-{variant}-{seed}-{name_b.replace(' ', '_')}", category)


@dataclass(frozen=True)
class _Look:
    """Shared dimensions of a bus's sections (metres): half width, body height (below the pod), wheel radius,
    door side (+1 left, -1 right), ground clearance, window pillar spacing, window base, skirt top."""

    hw: float
    Hb: float
    r: float
    door_side: float
    clear: float
    pillar: float
    z_w0: float
    z_skirt: float


def _section(k: _Look, x0: float, x1: float, axles: list[float], front: bool, rear: bool,
             doors: list[tuple[float, float]]) -> list:
    """One body section from x0 to x1 with windows, doors (on ``k.door_side``), and lamps at its open ends."""
    e_f = 0.16 if front else 0.04
    e_r = 0.12 if rear else 0.04
    xa0, xa1 = x0 + e_r, x1 - e_f
    arches = [(xa, k.r + 0.08) for xa in axles]
    z_w1 = k.Hb - float(np.clip(0.08 * k.Hb, 0.18, 0.3))
    z_ws0 = float(np.clip(0.25 * k.Hb, 0.65, 0.95))
    sign0, sign1 = k.Hb - 0.36, k.Hb - 0.1
    # window band from the front to the rear, black pillars every ~k.pillar metres
    w0, w1 = xa0 + (0.5 if rear else 0.15), xa1 - (0.3 if front else 0.15)
    n_win = max(int(round((w1 - w0) / k.pillar)), 1)
    pillars = np.linspace(w0, w1, n_win + 1)
    doors = [(a, b) for a, b in doors if b - a > 0.5 and a > xa0 + 0.2 and b < xa1 - 0.1
             and all(abs(a - xa) > k.r + 0.1 and abs(b - xa) > k.r + 0.1 and not (a < xa < b) for xa in axles)]
    regions = [
        Region(ACCENT, (-np.inf, -np.inf, -np.inf), (np.inf, np.inf, k.z_skirt), None),
        Region(GLASS, (w0, -np.inf, k.z_w0), (w1, np.inf, z_w1), (0.0, 1.0, 0.0), 0.6, both_sides=True),
    ]
    regions += [Region(TRIM, (p - 0.05, -np.inf, k.z_w0), (p + 0.05, np.inf, z_w1), (0.0, 1.0, 0.0), 0.6,
                       both_sides=True) for p in pillars]
    for a, b in doors:
        side_n = (0.0, k.door_side, 0.0)
        regions.append(Region(GLASS, (a, -np.inf, k.clear + 0.1), (b, np.inf, z_w1), side_n, 0.6))
        regions.append(Region(TRIM, (0.5 * (a + b) - 0.03, -np.inf, k.clear + 0.1), (0.5 * (a + b) + 0.03, np.inf,
                                                                                      z_w1), side_n, 0.6))
    if front:
        regions.append(Region(GLASS, (xa1 - 0.2, -k.hw + 0.1, z_ws0), (np.inf, k.hw - 0.1, sign0), (1.0, 0, 0), 0.5))
        regions.append(Region(TRIM, (xa1 - 0.2, -k.hw + 0.1, sign0), (np.inf, k.hw - 0.1, sign1), (1.0, 0, 0), 0.5))
        regions.append(Region(INDICATOR, (xa1 - 0.2, -0.6 * k.hw, sign0 + 0.04), (np.inf, 0.6 * k.hw, sign1 - 0.04),
                              (1.0, 0, 0), 0.5))  # the destination sign
    if rear:
        rw0 = max(0.6 * k.Hb, k.z_w0)
        regions.append(Region(GLASS, (-np.inf, -0.8 * k.hw, rw0), (xa0 + 0.2, 0.8 * k.hw, z_w1), (-1.0, 0, 0), 0.5))
    xcuts = [w0, w1, *pillars - 0.05, *pillars + 0.05]
    for a, b in doors:
        xcuts += [a, b, 0.5 * (a + b) - 0.03, 0.5 * (a + b) + 0.03]
    xs = arch_stations(xa0, xa1, arches, cuts=xcuts, step=1.0, n_arch=8)
    zlo = arch_bottom(xs, k.clear, arches, k.r)
    zcuts = sorted({k.clear + 0.1, k.z_skirt, k.z_w0, z_w1, z_ws0, sign0, sign0 + 0.04, sign1 - 0.04, sign1,
                    max(0.6 * k.Hb, k.z_w0)})
    parts = [loft_x(xs, zlo, k.Hb, k.hw, radius=float(min(0.18, k.Hb - sign1 - 0.01)), mat=PAINT,
                    regions=regions, z_cuts=zcuts, end_round=(e_r, e_f), n_corner=2)]
    if front:
        zb = k.clear + 0.02
        parts.append(box((x1 - 0.2, -k.hw + 0.05, zb), (x1 - 0.02, k.hw - 0.05, zb + 0.3), TRIM))
        parts += light_pair(x1 - 0.06, 1.0, k.hw - 0.25, zb + 0.36, zb + 0.52, 0.34, HEADLIGHT, depth=0.06)
    if rear:
        zb = k.clear + 0.02
        parts.append(box((x0 + 0.02, -k.hw + 0.05, zb), (x0 + 0.2, k.hw - 0.05, zb + 0.28), TRIM))
        parts += light_pair(x0 + 0.07, -1.0, k.hw - 0.12, zb + 0.35, zb + 0.95, 0.14, TAILLIGHT, depth=0.05)
    return parts


def _pod(k: _Look, x0: float, x1: float, top: float):
    """The roof equipment pod (air conditioning) from x0 to x1, reaching ``top``."""
    return loft_x([x0 + 0.1, x1 - 0.1], k.Hb - 0.03, top, 0.78 * k.hw, radius=0.08, mat=PAINT,
                  end_round=(0.1, 0.1), n_corner=2)


def _bellows(k: _Look, x0: float, x1: float):
    """The accordion bellows of an articulated bus between x0 and x1."""
    n = max(int((x1 - x0) / 0.06), 4)
    xs = np.linspace(x0, x1, 2 * n + 1)
    hw = np.where(np.arange(len(xs)) % 2 == 0, k.hw - 0.14, k.hw - 0.06)
    top = np.where(np.arange(len(xs)) % 2 == 0, k.Hb - 0.12, k.Hb - 0.05)
    return loft_x(xs, k.clear + 0.15, top, hw, radius=0.15, mat=TRIM, n_corner=2)


__all__ = ["procedural_bus", "procedural_bus_variants"]
