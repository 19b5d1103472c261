"""Procedural construction vehicles (nuScenes ``vehicle.construction``): excavators, wheel loaders, crane trucks.

* ``excavator``: two rubber-black track loops on a track frame, a slewing ring, a house (engine hood,
  rounded counterweight) with the glazed cab on its left front, and the boom + arm + bucket folded
  forward and down to the ground in front of the tracks (hydraulic cylinders along them).
* ``loader``: a wheel loader: four big tyres, an articulated body (front frame with lift arms and a
  full-width bucket carried low, rear frame with the engine hood, counterweight and cab).
* ``crane_truck``: a cab-over truck chassis (2-4 axles) with outriggers, a turntable with the crane's
  superstructure at the rear and the telescopic boom folded forward over the cab.

The box encloses everything, booms included; the parts are built to it (object frame x front, y left,
z up, metres, origin at the bottom centre, tyres / tracks touching z = 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .asset import Asset
from .class_sizes import read_class_sizes
from .mesh_parts import target_wlh
from .vehicle_parts import (CHROME, HEADLIGHT, METAL, PAINT, TAILLIGHT, TRIM, TYRE, CabSpec, axle_wheels, beam, box,
                            cab_over, choose_variant, circle, finish_vehicle, glass_cabin, light_pair,
                            loft_x, pick_colour, prism, stadium, tube, vehicle_materials, wheel_well)

CATEGORY = "vehicle.construction"
_SEED_SALT = 0xC0B5

# (name, sRGB hex, weight): machine paints (yellow / orange dominant)
_MACHINE_PALETTE = (
    ("cat yellow", "F2B705", 5.0), ("komatsu yellow", "EFC30A", 2.0), ("orange", "E86A10", 2.5),
    ("deep orange", "D9541C", 1.0), ("white", "EDEDE8", 0.6), ("blue", "2F5D9E", 0.3), ("red", "B01C1C", 0.3),
    ("green", "367C2B", 0.3),
)
_CRANE_PALETTE = (("yellow", "F2C230", 3.0), ("white", "EDEDE8", 2.0), ("red", "B01C1C", 1.0),
                  ("orange", "E86A10", 1.0))
_DEFAULT_WLH = {"excavator": (2.9, 6.5, 3.0), "loader": (2.8, 7.2, 3.3), "crane_truck": (2.55, 10.0, 3.8)}


def procedural_construction_vehicle_variants() -> tuple[str, ...]:
    """Names of the variants :func:`procedural_construction_vehicle` builds."""
    return ("excavator", "loader", "crane_truck")


def procedural_construction_vehicle(seed: int, wlh: ArrayLike | None = None, variant: str | None = None) -> Asset:
    """A construction vehicle built to the box ``wlh`` (boom / arm / bucket inside), deterministic.

    Args:
        seed: random seed (variant when None, proportions, paint).
        wlh: target box [w, l, h] metres, or None for the variant's typical size.
        variant: ``excavator``, ``loader``, ``crane_truck`` or None (crane trucks only for long boxes).

    Returns:
        An :class:`Asset` of category ``vehicle.construction`` whose ``wlh`` is the target; 3-12 k triangles.

    Raises:
        ValueError: an unknown variant, or a wlh that is not 3 finite positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, _SEED_SALT])
    given = target_wlh(wlh, "procedural_construction_vehicle")
    long_box = given is None or given[1] > 7.5
    loader_fits = given is None or (given[1] < 8.5 and given[2] < 4.0)
    weights = {"excavator": 0.5, "loader": 0.35 if loader_fits else 0.05, "crane_truck": 0.3 if long_box else 0.02}
    variant = choose_variant(rng, variant, weights, "procedural_construction_vehicle")
    W, L, H = given if given is not None else np.array(_DEFAULT_WLH[variant])
    name_c, colour = pick_colour(rng, _CRANE_PALETTE if variant == "crane_truck" else _MACHINE_PALETTE)
    accent = np.array([0.03, 0.03, 0.032]) if variant != "crane_truck" else pick_colour(rng, _CRANE_PALETTE)[1]
    materials = vehicle_materials(rng, colour, accent, paint_metallic=0.05, accent_clearcoat=0.3)
    build = {"excavator": _excavator, "loader": _loader, "crane_truck": _crane_truck}[variant]
    parts = build(rng, W, L, H)
    read_class_sizes()  # the table the targets come from must be readable
    return finish_vehicle(parts, materials, np.array([W, L, H]),
                          f"procedural-construction-{variant}-{seed}-{name_c.replace(' ', '_')}", CATEGORY)


def _cylinder(p0, p1, r: float) -> list:
    """A hydraulic cylinder from p0 to p1 (3,): a painted barrel over the first 60 %, a chrome rod after."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    pm = p0 + 0.6 * (p1 - p0)
    return [tube(p0, pm, r, PAINT, 10), tube(pm - 0.05 * (p1 - p0), p1, 0.55 * r, CHROME, 8)]


# ----------------------------------------------------------------------------- excavator


def _excavator(rng: np.random.Generator, W: float, L: float, H: float) -> list:
    ht = float(np.clip(0.26 * H, 0.45, 0.95))
    tt = float(np.clip(0.2 * W, 0.3, 0.6))
    Lt = float(np.clip(rng.uniform(0.5, 0.6) * L, 1.4, 5.0))
    tail = float(np.clip(0.12 * Lt, 0.1, 0.6))
    xt = -L / 2 + tail + Lt / 2
    parts = []
    for s in (1.0, -1.0):
        y0, y1 = sorted((s * W / 2, s * (W / 2 - tt)))
        parts.append(prism(stadium(xt - Lt / 2, xt + Lt / 2, 0.0, ht, n_end=12), "y", y0, y1, TYRE, smooth=True))
        # idler / sprocket hubs on the inner side of each loop
        for xe in (xt - Lt / 2 + ht / 2, xt + Lt / 2 - ht / 2):
            yi = s * (W / 2 - tt)
            parts.append(prism(circle((xe, ht / 2), 0.32 * ht, 12), "y", *sorted((yi, yi - s * 0.05)), METAL))
        # grousers: shoe ribs across the top run of the loop
        for xg in np.arange(xt - Lt / 2 + ht / 2, xt + Lt / 2 - ht / 2, 0.22):
            parts.append(box((xg - 0.03, y0 + 0.01, ht - 0.01), (xg + 0.03, y1 - 0.01, ht + 0.03), TYRE))
    parts.append(box((xt - 0.42 * Lt, -(W / 2 - tt), 0.18 * ht), (xt + 0.42 * Lt, W / 2 - tt, 0.85 * ht), METAL))
    z_h0 = ht + 0.08 + 0.03
    parts.append(prism(circle((xt, 0.0), float(min(0.3 * W, 0.45 * Lt)), 16), "z", ht - 0.02, z_h0 + 0.01, METAL))
    # the house: from the rear of the box, rounded counterweight at the back
    Lh = float(np.clip(rng.uniform(0.85, 1.0) * Lt, 1.2, 0.55 * L))
    hwh = W / 2 - float(rng.uniform(0.0, 0.08))
    cab_top = float(min(H - 0.02, z_h0 + rng.uniform(1.65, 2.0)))
    z_h1 = z_h0 + float(min(np.clip(0.28 * H, 0.55, 1.2), 0.6 * (cab_top - z_h0)))
    x_hr, x_hf = -L / 2, -L / 2 + Lh
    e_r = float(min(0.3, 0.25 * (z_h1 - z_h0)))
    parts.append(loft_x([x_hr + e_r, x_hf - 0.09], z_h0, z_h1, hwh, radius=0.1, mat=PAINT,
                        end_round=(e_r, 0.05), n_corner=3))
    # cab on the left front of the house
    cab_w = float(np.clip(0.36 * W, 0.75, 1.0))
    Lcab = float(np.clip(0.5 * Lh, 0.9, 1.6))
    yc = hwh - cab_w / 2 - 0.02
    parts.append(glass_cabin(x_hf - Lcab, x_hf, yc, cab_w / 2, z_h0, cab_top, z_h0 + 0.3 * (cab_top - z_h0)))
    parts.append(tube((x_hr + 0.5, -0.5 * hwh, z_h1 - 0.02), (x_hr + 0.5, -0.5 * hwh,
                                                              min(z_h1 + 0.35, H - 0.05)), 0.05, METAL, 8))
    # boom, arm and bucket folded forward in the plane y = yb (right of the cab)
    yb = float(0.5 * (-hwh + (yc - cab_w / 2)))
    bw = float(np.clip(0.14 * W, 0.25, 0.5))
    tb = float(np.clip(0.12 * H, 0.3, 0.6))
    bl = float(np.clip(0.15 * L, 0.45, 1.3))
    bh = float(np.clip(0.3 * H, 0.5, 1.1))
    xb0 = L / 2 - bl
    bucket = [(xb0, 0.3 * bh), (xb0 + 0.3 * bl, 0.03), (L / 2 - 0.1 * bl, 0.03), (L / 2, 0.35 * bh),
              (L / 2 - 0.25 * bl, bh), (xb0 + 0.1 * bl, bh)]
    kw = float(np.clip(0.34 * W, 0.5, 1.4))
    yk = float(np.clip(yb, -W / 2 + kw / 2, W / 2 - kw / 2))
    parts.append(prism(bucket, "y", yk - kw / 2, yk + kw / 2, METAL))
    for yt in np.linspace(yk - 0.4 * kw, yk + 0.4 * kw, 5):  # teeth on the cutting edge
        parts.append(box((L / 2 - 0.12 * bl, yt - 0.04, 0.03), (L / 2 - 0.01, yt + 0.04, 0.1), METAL))
    p_pivot = np.array([x_hf - 0.15, z_h0 + 0.35])
    p_bucket = np.array([L / 2 - 0.55 * bl, 0.8 * bh])
    z_e = H - tb / 2
    x_e = float(p_pivot[0] + rng.uniform(0.5, 0.65) * max(p_bucket[0] - p_pivot[0], 0.2))
    knee = np.array([p_pivot[0] + 0.45 * (x_e - p_pivot[0]), p_pivot[1] + 0.8 * (z_e - p_pivot[1])])
    p_elbow = np.array([x_e, z_e])
    parts.append(beam(p_pivot, knee, yb - bw / 2, yb + bw / 2, tb, tb, PAINT))
    parts.append(beam(knee, p_elbow, yb - bw / 2, yb + bw / 2, tb, 0.8 * tb, PAINT))
    parts.append(beam(p_elbow, p_bucket, yb - 0.4 * bw, yb + 0.4 * bw, 0.75 * tb, 0.5 * tb, PAINT))
    for p, rp in ((p_pivot, 0.5 * tb), (knee, 0.5 * tb), (p_elbow, 0.5 * tb), (p_bucket, 0.25 * tb)):
        parts.append(tube((p[0], yb - 0.5 * bw - 0.02, p[1]), (p[0], yb + 0.5 * bw + 0.02, p[1]), rp, METAL, 12))
    # hydraulic cylinders: boom lift (from the house front), arm (over the boom), bucket (along the arm)
    rc = 0.18 * tb
    base = np.array([x_hf - 0.05, z_h0 + 0.1])
    mid = p_pivot + 0.55 * (knee - p_pivot) + np.array([0.0, -0.3 * tb])
    parts += _cylinder((base[0], yb, base[1]), (mid[0], yb, mid[1]), rc)
    top = knee + np.array([0.0, 0.45 * tb])
    up = p_elbow + np.array([-0.1, 0.0])
    parts += _cylinder((top[0], yb, min(top[1], H - rc)), (up[0], yb, min(up[1], H - rc)), 0.8 * rc)
    a0 = p_elbow + 0.2 * (p_bucket - p_elbow)
    a1 = p_bucket + np.array([-0.15 * bl, 0.35 * bh])
    parts += _cylinder((a0[0], yb, a0[1]), (a1[0], yb, a1[1]), 0.7 * rc)
    parts += light_pair(x_hf - 0.02, 1.0, 0.0, z_h1 - 0.2, z_h1 - 0.1, 0.15, HEADLIGHT, depth=0.03)[:1]
    return parts


# ----------------------------------------------------------------------------- wheel loader


def _loader(rng: np.random.Generator, W: float, L: float, H: float) -> list:
    r = float(min(np.clip(0.25 * H, 0.45, 0.95), 0.13 * L + 0.1))
    tw = float(np.clip(0.6 * r, 0.3, 0.6))
    bl = float(np.clip(0.15 * L, 0.5, 1.5))
    bh = float(np.clip(0.3 * H, 0.5, 1.3))
    xf = L / 2 - bl - 0.1 - 0.95 * r
    wb = float(np.clip(0.4 * L, 1.5, 4.2))
    xr = max(xf - wb, -L / 2 + 1.1 * r + 0.25)
    y_out = W / 2 - float(np.clip(0.05 * W, 0.05, 0.15))
    parts = []
    for xa in (xf, xr):
        parts += axle_wheels(xa, r, tw, y_out, dual=False, rim_frac=0.55, n_around=28)
        parts.append(box((xa - 1.0 * r, y_out - tw - 0.02, 2 * r + 0.02), (xa + 0.9 * r, y_out + 0.0, 2 * r + 0.08),
                         PAINT))
        parts.append(box((xa - 1.0 * r, -y_out, 2 * r + 0.02), (xa + 0.9 * r, -(y_out - tw - 0.02), 2 * r + 0.08),
                         PAINT))
    inner = y_out - tw - 0.05
    # front frame, articulation, rear frame with the engine hood and counterweight
    parts.append(box((xf - 0.8 * r, -inner, 0.55 * r), (xf + 0.6 * r, inner, 2 * r + 0.1), PAINT))
    xm = 0.5 * (xf + xr)
    parts.append(box((xm - 0.25, -0.35, 0.6 * r), (xm + 0.25, 0.35, 1.5 * r), METAL))
    z_hood = float(min(2 * r + rng.uniform(0.2, 0.45), 0.62 * H))
    hood_hw = float(min(inner + 0.1, y_out - 0.05))
    x_hood1 = xm - 0.1
    parts.append(loft_x([-L / 2 + 0.25, x_hood1 - 0.05], 0.6 * r, z_hood, hood_hw, radius=0.12, mat=PAINT,
                        end_round=(0.25, 0.05), n_corner=2))
    parts.append(box((-L / 2 + 0.05, -hood_hw + 0.1, 0.5 * r), (-L / 2 + 0.35, hood_hw - 0.1, 0.5 * r + 0.45), TRIM))
    parts += light_pair(-L / 2 + 0.2, -1.0, hood_hw - 0.2, z_hood - 0.25, z_hood - 0.12, 0.15, TAILLIGHT, depth=0.05)
    parts.append(tube((-L / 2 + 0.6, -0.3 * hood_hw, z_hood - 0.02), (-L / 2 + 0.6, -0.3 * hood_hw,
                                                                      min(z_hood + 0.4, H - 0.05)), 0.06, METAL, 8))
    # cab over the articulation (top = H)
    cab_l = float(np.clip(0.22 * L, 1.0, 1.9))
    cab_hw = float(min(0.8, hood_hw))
    zc0 = float(min(max(1.7 * r, H - 2.1), H - 1.2))
    if zc0 > z_hood - 0.1:  # a pedestal lifts the cab of a big machine
        parts.append(box((x_hood1 - cab_l + 0.1, -cab_hw + 0.1, z_hood - 0.2), (x_hood1, cab_hw - 0.1, zc0 + 0.05),
                         PAINT))
    else:
        zc0 = z_hood - 0.1
    parts.append(glass_cabin(x_hood1 - cab_l, x_hood1 + 0.05, 0.0, cab_hw, zc0, H, zc0 + 0.35 * (H - zc0)))
    # lift arms and the full-width bucket carried low
    z_b0 = float(min(0.25, 0.3 * r))
    xb0 = L / 2 - bl
    bucket = [(xb0, z_b0 + 0.15 * bh), (xb0 + 0.25 * bl, z_b0), (L / 2, z_b0), (L / 2 - 0.05 * bl, z_b0 + 0.3 * bh),
              (xb0 + 0.5 * bl, z_b0 + bh), (xb0 + 0.05 * bl, z_b0 + bh)]
    parts.append(prism(bucket, "y", -W / 2, W / 2, PAINT))
    p0 = np.array([xf - 0.75 * r, float(min(2 * r + 0.3, 0.7 * H))])
    p1 = np.array([xb0 + 0.1, z_b0 + 0.55 * bh])
    for s in (1.0, -1.0):
        ya = s * (inner - 0.15)
        parts.append(beam(p0, p1, ya - 0.12, ya + 0.12, 0.35 * r + 0.12, 0.25 * r + 0.08, PAINT))
        parts += _cylinder((xf - 0.1 * r, ya - s * 0.25, 1.3 * r), (p0[0] + 0.6 * (p1[0] - p0[0]), ya - s * 0.25,
                                                                 p0[1] + 0.6 * (p1[1] - p0[1]) - 0.1), 0.08)
    parts += _cylinder((xf + 0.3 * r, 0.0, 2 * r + 0.1), (xb0 + 0.1, 0.0, z_b0 + 0.9 * bh), 0.09)
    parts += light_pair(xf + 0.6 * r, 1.0, 0.5 * inner, 1.5 * r, 1.5 * r + 0.12, 0.18, HEADLIGHT, depth=0.04)
    return parts


# ----------------------------------------------------------------------------- crane truck


def _crane_truck(rng: np.random.Generator, W: float, L: float, H: float) -> list:
    m_out = float(np.clip(rng.uniform(0.12, 0.2), 0.05, max(0.05, (W - 1.6) / 2)))
    hw = W / 2 - m_out
    r = float(min(np.clip(0.3 + 0.02 * L, 0.42, 0.58), 0.14 * H))
    tw = 0.2 + 0.3 * r
    n_ax = 2 if L < 7.5 else (3 if L < 9.5 else 4)
    xf = L / 2 - float(np.clip(0.13 * L, 1.0, 1.5))
    x_last = -L / 2 + float(np.clip(0.15 * L, 0.9, 2.2))
    axles = [xf] + list(np.linspace(x_last + 1.45 * (n_ax - 2), x_last, n_ax - 1))
    if n_ax == 4:
        axles = [xf, xf - 1.6] + [x_last + 1.45, x_last]
    boom_t = float(np.clip(0.15 * H, 0.4, 0.7))
    floor = min(2 * r + 0.1, 0.4 * H)
    Lc = float(np.clip(0.2 * L, 1.5, 2.1))
    Hc = float(min(H - boom_t - 0.08, floor + 1.6))
    cab = CabSpec(x_front=L / 2, length=Lc, half_w=hw, y_mirror=W / 2, top=Hc, floor=floor, x_axle=xf, wheel_r=r,
                  rake=0.05)
    parts = cab_over(cab)
    z_frame = min(2 * r + 0.08, floor)
    x_cab_r = L / 2 - Lc
    parts.append(box((-L / 2 + 0.1, -hw + 0.1, z_frame - 0.3), (x_cab_r - 0.05, hw - 0.1, z_frame), PAINT))
    for xa in axles:
        parts += axle_wheels(xa, r, tw, hw - 0.03, dual=False)
        if xa != xf:
            parts.append(wheel_well(xa, r, hw - tw - 0.08, z_frame - 0.02))
    # outrigger boxes behind the cab and at the rear
    for xo in (x_cab_r - 0.35, -L / 2 + 0.4):
        parts.append(box((xo - 0.25, -hw, z_frame - 0.55), (xo + 0.25, hw, z_frame - 0.2), METAL))
    parts.append(box((-L / 2 + 0.02, -hw + 0.1, 0.45), (-L / 2 + 0.12, hw - 0.1, 0.6), METAL))
    parts += light_pair(-L / 2 + 0.02, -1.0, hw - 0.3, 0.47, 0.58, 0.3, TAILLIGHT, depth=0.02)
    # turntable and superstructure at the rear, the operator's cabin on its left
    x_tt = -L / 2 + float(np.clip(0.17 * L, 1.1, 2.4))
    rt = float(min(0.75, 0.8 * hw))
    z_tt = z_frame + 0.25
    parts.append(prism(circle((x_tt, 0.0), rt, 20), "z", z_frame - 0.01, z_tt, METAL))
    z_s1 = float(min(z_tt + 0.9, H - boom_t - 0.05))
    parts.append(box((x_tt - 1.1 * rt - 0.3, -0.8 * hw, z_tt), (x_tt + rt, 0.3 * hw, z_s1), PAINT))
    parts.append(box((-L / 2 + 0.05, -0.8 * hw, z_tt), (x_tt - 1.1 * rt - 0.3, 0.5 * hw, z_tt + 0.6), METAL))
    parts.append(glass_cabin(x_tt - 0.2, x_tt + rt + 0.35, 0.6 * hw, 0.35 * hw, z_tt,
                             float(min(z_tt + 1.5, H - 0.05)), z_tt + 0.4))
    # telescopic boom over the cab: base section and a slimmer fly section ending at the front
    yb = -0.25 * hw
    x_p = x_tt - 0.1
    x_head = L / 2 - 0.12
    x_mid = x_p + 0.55 * (x_head - x_p)
    drop = 0.12
    z_top = lambda x: H - drop * (x - x_p) / (x_head - x_p)  # noqa: E731 (the boom's top line)
    bw = float(np.clip(0.28 * W, 0.45, 0.8))
    parts.append(prism([(x_p, z_top(x_p)), (x_mid, z_top(x_mid)), (x_mid, z_top(x_mid) - boom_t),
                        (x_p, z_top(x_p) - boom_t)], "y", yb - bw / 2, yb + bw / 2, PAINT))
    t2 = 0.75 * boom_t
    parts.append(prism([(x_mid - 0.3, z_top(x_mid) - 0.05), (x_head, z_top(x_head) - 0.05),
                        (x_head, z_top(x_head) - 0.05 - t2), (x_mid - 0.3, z_top(x_mid) - 0.05 - t2)], "y",
                       yb - 0.38 * bw, yb + 0.38 * bw, PAINT))
    # the boom foot: a pedestal on the superstructure carrying the boom's pivot
    parts.append(box((x_p - 0.05, yb - 0.45 * bw, z_tt), (x_p + 0.5, yb + 0.45 * bw, z_top(x_p) - boom_t + 0.02),
                     PAINT))
    parts.append(tube((x_p + 0.2, yb - 0.5 * bw - 0.03, z_top(x_p) - 0.5 * boom_t),
                      (x_p + 0.2, yb + 0.5 * bw + 0.03, z_top(x_p) - 0.5 * boom_t), 0.1, METAL, 10))
    zh = z_top(x_head) - 0.05 - t2 / 2
    parts.append(tube((x_head - 0.12, yb - 0.3 * bw, zh), (x_head - 0.12, yb + 0.3 * bw, zh), 0.12, METAL, 12))
    parts.append(box((x_head - 0.35, yb - 0.15, Hc + 0.02), (x_head - 0.1, yb + 0.15, zh - 0.2), TRIM))
    parts += _cylinder((x_tt + 0.5 * rt, yb, z_s1 - 0.2), (x_p + 0.35 * (x_head - x_p), yb,
                                                           z_top(x_p) - boom_t - 0.02), 0.12)
    # boom rest on the cab roof
    parts.append(box((x_cab_r + 0.3, yb - 0.25, Hc - 0.02), (x_cab_r + 0.5, yb + 0.25, z_top(x_cab_r) - boom_t + 0.01),
                     METAL))
    return parts


__all__ = ["procedural_construction_vehicle", "procedural_construction_vehicle_variants"]
