"""Procedural trucks (nuScenes ``vehicle.truck``): box lorries, flatbed lorries and pick-ups.

A lorry is a cab-over-engine cab (:func:`~.vehicle_parts.cab_over`) on a ladder frame with 2 axles
(3 above 8.3 m: a tandem rear), dual rear tyres from 5.2 m, side guards, a fuel tank, a rear underrun
bar with the tail lamps, and either a cargo box (``box``) or a flat deck with low drop sides, a
headboard and a load (``flatbed``).  A pick-up (nuScenes labels pick-ups as trucks) is a lofted lower
body with wheel arches and a bed, a tapered glasshouse, and optionally a bed canopy or a roof rack.
Everything is built to the target box (object frame x front, y left, z up, metres, origin at the
bottom centre, tyres touching z = 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .asset import Asset
from .class_sizes import read_class_sizes
from .mesh_parts import target_wlh
from .vehicle_parts import (ACCENT, CARGO, CHROME, GLASS, HEADLIGHT, INDICATOR, METAL, PAINT, TAILLIGHT, TRIM, CabSpec,
                            Region, arch_bottom, arch_stations, axle_wheels, box, cab_over, choose_variant,
                            finish_vehicle, light_pair, loft_x, mirror_pair, pick_colour, prism, rear_doors, taper,
                            tube, vehicle_materials, wheel_well)

CATEGORY = "vehicle.truck"
_SEED_SALT = 0x7A0C

# (name, sRGB hex, weight): lorry cabs (white dominant), cargo boxes (white / grey / brand colours), pick-ups
_CAB_PALETTE = (
    ("white", "F2F2EE", 10.0), ("off white", "E6E4DC", 3.0), ("silver", "B5B8BB", 2.0), ("grey", "6E7074", 1.5),
    ("red", "A81C1C", 2.0), ("blue", "1F4A8C", 2.0), ("navy", "1B2A4A", 1.0), ("green", "2E6B34", 1.0),
    ("yellow", "E3B521", 0.7), ("orange", "D9621C", 0.6), ("black", "141518", 1.0),
)
_BOX_PALETTE = (
    ("white", "F0F0EC", 10.0), ("light grey", "C4C6C6", 3.0), ("silver", "A9ACAE", 2.0), ("red", "B01C1C", 1.0),
    ("blue", "2A4F9C", 1.0), ("yellow", "E8B820", 0.6), ("green", "2F7A3A", 0.6), ("orange", "DD6A1E", 0.4),
)
_PICKUP_PALETTE = (
    ("white", "F2F2EE", 6.0), ("silver", "B5B8BB", 3.0), ("grey", "53565C", 3.0), ("black", "141518", 3.0),
    ("red", "9A1420", 1.5), ("blue", "1F3560", 1.5), ("dark green", "1E3B2C", 0.5), ("beige", "C2B28F", 0.5),
)
_DEFAULT_WLH = {"box": (2.35, 7.2, 3.3), "flatbed": (2.35, 7.5, 2.9), "pickup": (1.95, 5.3, 1.85)}


def procedural_truck_variants() -> tuple[str, ...]:
    """Names of the truck variants :func:`procedural_truck` builds."""
    return ("box", "flatbed", "pickup")


def procedural_truck(seed: int, wlh: ArrayLike | None = None, variant: str | None = None) -> Asset:
    """A truck mesh built to the box ``wlh``, deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (variant when None, proportions, axles, paint, load).
        wlh: target box [w, l, h] metres (mirrors included), or None for the variant's typical size.
        variant: ``box`` (cab + cargo box), ``flatbed`` (cab + flat deck with drop sides and a load),
            ``pickup``, or None to draw one (pick-ups only for short, low boxes).

    Returns:
        An :class:`Asset` of category ``vehicle.truck`` whose ``wlh`` is the target; about 5-12 k triangles.

    Raises:
        ValueError: an unknown variant, or a wlh that is not 3 finite positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, _SEED_SALT])
    given = target_wlh(wlh, "procedural_truck")
    if given is None:
        weights = {"box": 0.5, "flatbed": 0.2, "pickup": 0.3}
    else:
        small = given[1] < 6.2 and given[2] < 2.3
        weights = {"box": 0.5, "flatbed": 0.25, "pickup": 0.6 if small else 0.02}
    variant = choose_variant(rng, variant, weights, "procedural_truck")
    target = given if given is not None else np.array(_DEFAULT_WLH[variant])
    if variant == "pickup":
        parts, paint = _pickup(rng, *target), _PICKUP_PALETTE
        name_c, colour = pick_colour(rng, paint)
        accent = colour
        metallic = 0.4
    else:
        parts = _lorry(rng, *target, flatbed=(variant == "flatbed"))
        name_c, colour = pick_colour(rng, _CAB_PALETTE)
        accent = pick_colour(rng, _BOX_PALETTE)[1] if variant == "box" else \
            np.array([0.45, 0.46, 0.47]) * rng.uniform(0.8, 1.1)
        metallic = 0.1
    materials = vehicle_materials(rng, colour, accent, paint_metallic=metallic,
                                  accent_clearcoat=1.0 if variant != "flatbed" else 0.3)
    read_class_sizes()  # the table the targets come from must be readable (raises InputError otherwise)
    return finish_vehicle(parts, materials, target, f"procedural-truck-{variant}-{seed}-{name_c.replace(' ', '_')}",
                          CATEGORY)


# ----------------------------------------------------------------------------- lorries


def _lorry(rng: np.random.Generator, W: float, L: float, H: float, flatbed: bool) -> list:
    """A cab-over lorry (box body or flatbed) filling W x L x H."""
    m_out = float(np.clip(rng.uniform(0.14, 0.24), 0.05, max(0.05, (W - 1.4) / 2)))
    hw = W / 2 - m_out
    r = float(min(np.clip(0.28 + 0.024 * L, 0.36, 0.53), 0.19 * H + 0.02))
    tw = 0.18 + 0.22 * r
    dual = L > 5.2
    fo = float(np.clip(0.16 * L, 0.95, 1.45))
    ro = float(np.clip(0.2 * L, 0.8, 2.6))
    xf = L / 2 - fo
    rear_axles = [-L / 2 + ro] if L <= 8.3 else [-L / 2 + ro, -L / 2 + ro + 1.35]
    floor = min(2 * r + 0.12, 0.45 * H)
    Lc = float(np.clip(rng.uniform(1.65, 2.25), 1.3, 0.42 * L))
    Hc = min(H, floor + float(rng.uniform(1.45, 1.9)))
    if H - Hc < 0.12:
        Hc = H
    hw_cab = hw - float(rng.uniform(0.0, 0.06))
    cab = CabSpec(x_front=L / 2, length=Lc, half_w=hw_cab, y_mirror=W / 2, top=Hc, floor=floor, x_axle=xf,
                  wheel_r=r, rake=float(rng.uniform(0.03, 0.15)), sleeper=Lc > 2.0 and rng.random() < 0.6)
    parts = cab_over(cab, grille_mat=CHROME if rng.random() < 0.3 else TRIM)
    x_cab_rear = L / 2 - Lc
    x_body_front = x_cab_rear - 0.12
    z_frame = min(2 * r * 0.95 + 0.04, floor - 0.02)

    # ladder frame, axles, wheels
    for s in (1.0, -1.0):
        parts.append(box((-L / 2 + 0.15, s * 0.43 - 0.045, z_frame - 0.26), (x_cab_rear + 0.5, s * 0.43 + 0.045,
                                                                              z_frame), METAL))
    parts += axle_wheels(xf, r, tw, hw_cab - 0.02, dual=False)
    for xa in rear_axles:
        parts += axle_wheels(xa, r, tw, hw - 0.03, dual=dual)
        parts.append(wheel_well(xa, r, hw - 0.03 - (2 * tw + 0.05 if dual else tw) - 0.02, z_frame + 0.02))
        parts.append(tube((xa, -hw + 0.3, r), (xa, hw - 0.3, r), 0.07, METAL, 10))
    parts.append(tube((xf, -hw + 0.3, r), (xf, hw - 0.3, r), 0.07, METAL, 10))

    # fuel tank and side guards between the front wheel and the first rear wheel
    g0, g1 = rear_axles[-1] + r + 0.15, xf - r - 0.2
    if g1 - g0 > 0.6:
        side = 1.0 if rng.random() < 0.5 else -1.0
        rt = min(0.26, 0.4 * r)
        t1 = g1 - 0.05
        t0 = max(g0 + 0.1, t1 - float(rng.uniform(0.8, 1.3)))
        parts.append(tube((t0, side * (hw - 0.12 - rt), z_frame - 0.26 - rt + 0.05),
                          (t1, side * (hw - 0.12 - rt), z_frame - 0.26 - rt + 0.05), rt, CHROME, 16))
        for s in (1.0, -1.0):
            for zg in (0.45 * r + 0.3, 0.45 * r + 0.62):
                if zg + 0.08 < z_frame:
                    parts.append(box((g0, s * (hw - 0.06) - 0.03, zg), (g1, s * (hw - 0.06) + 0.03, zg + 0.08),
                                     TRIM))

    # rear underrun bar with the tail lamps
    zb = max(0.42, 0.5 * z_frame)
    parts.append(box((-L / 2 + 0.06, -hw + 0.08, zb), (-L / 2 + 0.18, hw - 0.08, zb + 0.14), METAL))
    parts += light_pair(-L / 2 + 0.06, -1.0, hw - 0.3, zb + 0.01, zb + 0.13, 0.32, TAILLIGHT, depth=0.03)

    if flatbed:
        parts += _flatbed_body(rng, L, H, hw, Hc, z_frame, x_body_front)
    else:
        parts += _box_body(rng, L, H, hw, Hc, z_frame, x_body_front, x_cab_rear)
    return parts


def _box_body(rng, L, H, hw, Hc, z_frame, x_front, x_cab_rear) -> list:
    """Cargo box from the rear of the vehicle to just behind the cab, roof at H, rear doors, roof deflector."""
    z0 = z_frame + 0.12
    parts = [box((-L / 2 + 0.1, -hw + 0.12, z_frame), (x_front - 0.05, hw - 0.12, z0), METAL)]
    e = 0.04
    x0, x1 = -L / 2 + 0.03, x_front - e
    regions = []
    if rng.random() < 0.5:  # a brand stripe in the cab colour
        zs = z0 + float(rng.uniform(0.1, 0.3)) * (H - z0)
        regions.append(Region(PAINT, (x0 + 0.3, -np.inf, zs), (x1 - 0.3, np.inf, zs + 0.12 * (H - z0)),
                              (0.0, 1.0, 0.0), 0.7, both_sides=True))
        cuts = (zs, zs + 0.12 * (H - z0))
    else:
        cuts = ()
    parts.append(loft_x([x0, x1], z0, H, hw, radius=0.05, mat=ACCENT, regions=regions, z_cuts=cuts,
                        end_round=(0.0, e), n_corner=2))
    # rear door frame, seam and locking rods
    parts += rear_doors(-L / 2, x0, hw, z0, H)
    # roof deflector on the cab when the box is much taller than the cab
    if H - Hc > 0.45 and rng.random() < 0.6:
        xd1 = x_cab_rear + float(min(1.2, 0.7 * (L / 2 - x_cab_rear)))
        xd0 = x_cab_rear + 0.15
        zt = H - float(rng.uniform(0.02, 0.12))
        parts.append(prism([(xd0, Hc - 0.02), (xd1, Hc - 0.02), (xd0 + 0.15, zt), (xd0, zt)], "y",
                           -hw + 0.15, hw - 0.15, PAINT))
    return parts


def _flatbed_body(rng, L, H, hw, Hc, z_frame, x_front) -> list:
    """Deck with drop sides and a headboard; a load reaching H when the cab is lower than the box."""
    zd0 = z_frame + 0.02
    zd = zd0 + 0.16
    x0, x1 = -L / 2, x_front
    parts = [box((x0, -hw, zd0), (x1, hw, zd), METAL)]
    rail = float(min(rng.uniform(0.3, 0.5), max(0.1, 0.4 * (Hc - zd))))
    for y0, y1 in ((hw - 0.045, hw), (-hw, -hw + 0.045)):
        parts.append(box((x0 + 0.02, y0, zd), (x1 - 0.08, y1, zd + rail), ACCENT))
    parts.append(box((x0, -hw, zd), (x0 + 0.05, hw, zd + rail), ACCENT))
    head = float(min(zd + rng.uniform(0.8, 1.2), Hc - 0.08))
    parts.append(box((x1 - 0.08, -hw + 0.05, zd), (x1, hw - 0.05, head), ACCENT))
    # the load: 1-3 blocks; the first reaches H when H is above the cab
    deck_len = x1 - x0 - 0.3
    n = int(rng.integers(1, 4))
    need_top = H > Hc + 0.01
    if need_top or rng.random() < 0.7:
        seg = deck_len / n
        for k in range(n):
            bl = seg * float(rng.uniform(0.65, 0.9))
            xc = x1 - 0.2 - seg * (k + 0.5)
            bw = hw * float(rng.uniform(0.75, 0.95))
            if k == 0 and need_top:
                top = H
            else:
                top = zd + float(rng.uniform(0.35, 1.0)) * max(min(Hc, H) - 0.05 - zd, 0.2)
            parts.append(box((xc - bl / 2, -bw, zd), (xc + bl / 2, bw, top), CARGO))
    return parts


# ----------------------------------------------------------------------------- pick-ups


def _pickup(rng: np.random.Generator, W: float, L: float, H: float) -> list:
    """A pick-up: lower body with arches and a bed, glasshouse, bumpers, lamps, mirrors; maybe canopy/rack."""
    m_out = float(np.clip(rng.uniform(0.09, 0.14), 0.04, max(0.04, (W - 1.4) / 2)))
    hw = W / 2 - m_out
    r = float(min(np.clip(0.31 + 0.018 * L, 0.36, 0.45), 0.21 * H + 0.02))
    tw = float(np.clip(0.12 + 0.3 * r, 0.22, 0.3))
    fo = float(np.clip(0.17 * L, 0.8, 1.25))
    ro = float(np.clip(0.2 * L, 0.9, 1.6))
    xf, xr = L / 2 - fo, -L / 2 + ro
    H_cab = float(min(H, 2.05))
    z_belt = float(np.clip(0.58 * H_cab, 0.85, 1.2))
    clear = float(min(0.28 + 0.1 * r, 0.6 * r))
    arches = [(xf, r + 0.06), (xr, r + 0.06)]
    x_ws = xf - float(rng.uniform(0.35, 0.6))  # windscreen base
    L_cab = float(np.clip(rng.uniform(0.33, 0.42) * L, 1.4, 2.9))
    x_cr = x_ws - L_cab
    e_r, e_f = 0.06, 0.16
    x0, x1 = -L / 2 + 0.04 + e_r, L / 2 - 0.05 - e_f
    bed0, bed1 = -L / 2 + 0.1, x_cr - 0.06
    xs = arch_stations(x0, x1, arches, cuts=(bed0, bed1, x_ws), step=0.35)
    zlo = arch_bottom(xs, clear, arches, r)
    zhi = np.where(xs > x_ws, z_belt - 0.1 * (xs - x_ws) / max(x1 - x_ws, 0.1), z_belt)
    grille_top = z_belt - 0.16
    regions = [
        Region(TRIM, (bed0, -hw + 0.07, z_belt - 0.01), (bed1, hw - 0.07, np.inf), (0.0, 0.0, 1.0), 0.8),
        Region(TRIM, (x1 - 0.05, -0.55 * hw, clear + 0.2), (np.inf, 0.55 * hw, grille_top), (1.0, 0.0, 0.0), 0.5),
    ]
    parts = [loft_x(xs, zlo, zhi, hw, radius=0.12, mat=PAINT, regions=regions,
                    z_cuts=(clear + 0.2, grille_top, z_belt - 0.25), end_round=(e_r, e_f))]
    # bed walls (a rim above the liner)
    for s in (1.0, -1.0):
        parts.append(box((bed0, s * (hw - 0.02) - 0.04, z_belt - 0.05), (bed1, s * (hw - 0.02) + 0.04, z_belt + 0.03),
                         PAINT))
    parts.append(box((bed0 - 0.04, -hw + 0.03, z_belt - 0.05), (bed0 + 0.04, hw - 0.03, z_belt + 0.03), PAINT))
    # glasshouse
    gh0, gh1 = x_cr + 0.05, x_ws - 0.05
    zg0 = z_belt - 0.03
    hg = H_cab - zg0
    pillar = 0.5 * (gh0 + gh1) + 0.1 * (gh1 - gh0)
    regions = [
        Region(GLASS, (-np.inf, -np.inf, zg0 + 0.06), (np.inf, np.inf, H_cab - 0.07), (0.0, 1.0, 0.0), 0.6,
               both_sides=True),
        Region(PAINT, (pillar - 0.06, -np.inf, -np.inf), (pillar + 0.06, np.inf, np.inf), (0.0, 1.0, 0.0), 0.6,
               both_sides=True),
        Region(GLASS, (-np.inf, -hw, zg0 + 0.05), (np.inf, hw, H_cab - 0.06), (1.0, 0.0, 0.0), 0.5),
        Region(GLASS, (-np.inf, -0.75 * hw, zg0 + 0.12), (np.inf, 0.75 * hw, H_cab - 0.1), (-1.0, 0.0, 0.0), 0.5),
    ]
    xs_g = np.unique(np.round(np.concatenate([np.linspace(gh0, gh1, 6), [pillar - 0.06, pillar + 0.06]]), 6))
    gh = loft_x(xs_g, zg0, H_cab, hw * 0.97, radius=min(0.05, 0.2 * hg), mat=PAINT, regions=regions,
                z_cuts=(zg0 + 0.06, zg0 + 0.12, H_cab - 0.1, H_cab - 0.07), end_round=(0.04, 0.04), n_corner=2)
    parts.append(taper(gh, gh0 - 0.04, gh1 + 0.04, zg0 + 0.05, H_cab, front_setback=0.65 * hg, rear_setback=0.06,
                       tumble=0.1))
    # bumpers, lamps, mirrors
    bump = CHROME if rng.random() < 0.4 else TRIM
    parts.append(box((L / 2 - 0.2, -hw + 0.06, clear + 0.02), (L / 2 - 0.02, hw - 0.06, clear + 0.24), bump))
    parts.append(box((-L / 2 + 0.02, -hw + 0.06, clear + 0.05), (-L / 2 + 0.2, hw - 0.06, clear + 0.22), bump))
    parts += light_pair(L / 2 - 0.08, 1.0, hw - 0.22, grille_top - 0.12, grille_top + 0.02, 0.28, HEADLIGHT,
                        depth=0.08)
    parts += light_pair(L / 2 - 0.12, 1.0, hw - 0.05, clear + 0.3, clear + 0.36, 0.08, INDICATOR, depth=0.06)
    parts += light_pair(-L / 2 + 0.04, -1.0, hw - 0.07, z_belt - 0.35, z_belt - 0.05, 0.12, TAILLIGHT, depth=0.04)
    parts += mirror_pair(x_ws - 0.12, hw - 0.04, W / 2, z_belt + 0.22, 0.17)
    # wheels
    for xa in (xf, xr):
        parts += axle_wheels(xa, r, tw, hw - 0.04, dual=False, rim_frac=0.62)
        parts.append(wheel_well(xa, r, hw - tw - 0.08, min(2 * r + 0.08, z_belt - 0.05)))
    # bed canopy or a roof rack reaching H
    if H > H_cab + 0.01:
        parts += _rack(bed0, bed1 + 0.02, hw, z_belt, H)
    elif rng.random() < 0.25:
        zt = H_cab - float(rng.uniform(0.03, 0.12))
        regions = [Region(GLASS, (-np.inf, -np.inf, z_belt + 0.1), (np.inf, np.inf, zt - 0.08), (0.0, 1.0, 0.0), 0.6,
                          both_sides=True)]
        parts.append(loft_x([bed0 + 0.04, bed1 - 0.04], z_belt, zt, hw - 0.03, radius=0.06, mat=PAINT,
                            regions=regions, z_cuts=(z_belt + 0.1, zt - 0.08), end_round=(0.03, 0.03), n_corner=2))
    return parts


def _rack(x0: float, x1: float, hw: float, z0: float, top: float) -> list:
    """A tubular ladder rack over the bed whose top rails reach ``top``."""
    parts = []
    rt = 0.025
    y = hw - 0.08
    for xp in (x0 + 0.08, x1 - 0.08):
        for s in (1.0, -1.0):
            parts.append(tube((xp, s * y, z0), (xp, s * y, top - rt), rt, METAL, 8))
        parts.append(tube((xp, -y, top - rt), (xp, y, top - rt), rt, METAL, 8))
    for s in (1.0, -1.0):
        parts.append(tube((x0 + 0.08, s * y, top - rt), (x1 - 0.08, s * y, top - rt), rt, METAL, 8))
    return parts


__all__ = ["procedural_truck", "procedural_truck_variants"]
