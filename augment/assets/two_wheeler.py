"""Procedural bicycles and motorcycles, with or without a rider.

A two-wheeler is built parametrically to its box: the wheel radius follows the length and height,
the wheelbase fills the length (the tyres are the front and rear of the box), the handlebar (and the
motorcycle's mirrors) or the rider's helmet/head set the height, and the bar / mirror width sets the
width.  A rider (:func:`~.pedestrian.rider_parts`) sits on the saddle with the hands on the grips and
the feet on the pedals / pegs; its standing height is solved so the combined object has the target
height.  Object frame: x front, y left, z up, metres, origin at the bottom centre of the box, tyres on
z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Asset, Material
from .class_sizes import read_class_sizes
from .mesh_parts import MeshPart, merge_parts, target_wlh
from .pedestrian import rider_parts
from .procedural import srgb_to_linear
from .revolve import (
    box, capsule, ellipse_rings, ellipsoid, loft, revolve, rot_y, straight_tubes, torus, tube, with_material,
)
from .validate import validate_asset

_RIDER_VARIANTS = ("with_rider", "without_rider")
_ATTRIBUTE = {"with_rider": "cycle.with_rider", "without_rider": "cycle.without_rider"}

# Material slots shared by both vehicles (indices into their material tables).
PAINT, TYRE, RIM, STEEL, BLACK, LIGHT, TAIL, ENGINE = range(8)

_BIKE_PAINT = ("151515", "EDEDEA", "8C1B1B", "1E3A6E", "2F5A3A", "C8C8C4", "D0A020", "3A3F48", "6A8FB0", "A04A7A",
               "D9621C", "4A3A2C")
_MOTO_PAINT = ("0E0E10", "E8E8E4", "A8141A", "12306E", "9A9CA0", "2A2C30", "D46A10", "1F5A30", "C9A227", "5A1E60")


def procedural_bicycle_variants() -> tuple[str, ...]:
    """Variants of :func:`procedural_bicycle` (``with_rider``, ``without_rider``)."""
    return _RIDER_VARIANTS


def procedural_motorcycle_variants() -> tuple[str, ...]:
    """Variants of :func:`procedural_motorcycle` (``with_rider``, ``without_rider``)."""
    return _RIDER_VARIANTS


def _hex(h: str) -> np.ndarray:
    return srgb_to_linear(np.array([int(h[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)


def _choose_variant(rng: np.random.Generator, variant: str | None, target: np.ndarray | None, name: str,
                    h_split: float) -> str:
    """The rider variant: given, or drawn (from the height when a target is given)."""
    u = rng.random()
    if variant is None:
        if target is None:
            variant = "with_rider" if u < 0.5 else "without_rider"
        else:
            p_rider = float(np.clip(0.5 + (target[2] - h_split) / 0.2, 0.03, 0.97))
            variant = "with_rider" if u < p_rider else "without_rider"
    if variant not in _RIDER_VARIANTS:
        raise ValueError(f"{name}: unknown variant {variant!r}; expected one of {', '.join(_RIDER_VARIANTS)}")
    return variant


# ----------------------------------------------------------------------------- wheels


def spoked_wheel(centre: np.ndarray, r: float, tyre_r: float, n_spokes: int, hub_half: float) -> list[MeshPart]:
    """A bicycle wheel in the x-z plane: tyre torus, rim, hub and ``n_spokes`` thin spokes (axis along y)."""
    y = np.array([0.0, 1.0, 0.0])
    R_tyre = r - tyre_r
    rim_R = R_tyre - tyre_r - 0.006
    parts = [torus(centre, y, R_tyre, tyre_r, TYRE, n_major=40, n_minor=8),
             torus(centre, y, rim_R, 0.009, RIM, n_major=36, n_minor=6, scale_axial=1.3),
             revolve(np.array([-hub_half, -hub_half, hub_half, hub_half]), np.array([0.0, 0.02, 0.02, 0.0]),
                     centre, y, STEEL, n_around=10)]
    ang = np.arange(n_spokes) * 2 * np.pi / n_spokes
    side = np.where(np.arange(n_spokes) % 2 == 0, 1.0, -1.0)
    hub_pts = centre + np.stack([0.02 * np.cos(ang), side * 0.8 * hub_half, 0.02 * np.sin(ang)], 1)
    rim_a = ang + 0.25  # spokes leave the hub tangentially-ish: offset from their hub angle
    rim_pts = centre + (rim_R - 0.006) * np.stack([np.cos(rim_a), 0.0 * ang, np.sin(rim_a)], 1)
    parts.append(straight_tubes(hub_pts, rim_pts, 0.0022, STEEL, n_around=4))
    return parts


def moto_wheel(centre: np.ndarray, r: float, tyre_r: float, width_scale: float, disc: bool) -> list[MeshPart]:
    """A motorcycle / scooter wheel: fat tyre torus, a closed cast rim (dark centre), optional brake disc."""
    y = np.array([0.0, 1.0, 0.0])
    R_tyre = r - tyre_r
    rim_r = R_tyre - 0.6 * tyre_r
    hw = tyre_r * width_scale * 0.75
    parts = [torus(centre, y, R_tyre, tyre_r, TYRE, n_major=40, n_minor=10, scale_axial=width_scale),
             revolve(np.array([-hw, -hw, -0.4 * hw, 0.4 * hw, hw, hw]), np.array([0.0, rim_r, rim_r * 1.02,
                                                                                    rim_r * 1.02, rim_r, 0.0]),
                     centre, y, RIM, n_around=28),
             revolve(np.array([-hw - 0.03, -hw - 0.03, hw + 0.03, hw + 0.03]), np.array([0.0, 0.05, 0.05, 0.0]),
                     centre, y, ENGINE, n_around=12)]
    if disc:
        dc = centre + np.array([0.0, hw + 0.012, 0.0])
        parts.append(revolve(np.array([-0.003, -0.003, 0.003, 0.003]), np.array([0.0, 0.8 * rim_r, 0.8 * rim_r, 0.0]),
                             dc, y, STEEL, n_around=24))
    return parts


def _grip_bar(centre: np.ndarray, half: float, rise: float, sweep: float, bar_r: float, grip_len: float,
              bar_mat: int, grip_mat: int) -> tuple[list[MeshPart], np.ndarray]:
    """A handlebar across y at ``centre``: a bent tube (rise up, sweep back at the ends) with grips.

    Returns the parts and the (2, 3) grip centres (left, right).
    """
    ys = np.array([-half, -0.75 * half, -0.3 * half, 0.3 * half, 0.75 * half, half])
    zs = np.array([rise, rise, 0.3 * rise, 0.3 * rise, rise, rise]) - rise
    xs = -np.array([sweep, 0.6 * sweep, 0.0, 0.0, 0.6 * sweep, sweep])
    pts = centre + np.stack([xs, ys, zs], 1)
    parts = [tube(pts[1:-1], bar_r, bar_mat, n_around=8)]
    grips = []
    for a, b in ((pts[1], pts[0]), (pts[-2], pts[-1])):
        d = (b - a) / np.linalg.norm(b - a)
        start = b - d * grip_len
        parts.append(capsule(start, b - d * 1.4 * bar_r, 1.4 * bar_r, 1.4 * bar_r, grip_mat, n_around=8, n_cap=2))
        grips.append(0.5 * (start + b))
    return parts, np.array([grips[1], grips[0]])  # left (+y) first


# ----------------------------------------------------------------------------- bicycle


@dataclass(frozen=True)
class _BikeGeometry:
    r: float
    tyre_r: float
    wheelbase: float
    bb: np.ndarray
    seat_top: np.ndarray  # top of the seat tube (seat cluster)
    saddle: np.ndarray  # top centre of the saddle
    head_top: np.ndarray
    head_bottom: np.ndarray
    bar: np.ndarray  # handlebar centre
    bar_half: float
    crank: float
    crank_phase: float
    step_through: bool


def _bike_geometry(r: float, tyre_r: float, wb: float, saddle_z: float, bar_z: float, bar_half: float,
                   u: np.ndarray) -> _BikeGeometry:
    s = wb / 1.05
    rear = np.array([-wb / 2, 0.0, r])
    front = np.array([wb / 2, 0.0, r])
    bb = rear + np.array([0.42 * s, 0.0, -0.07 * s])
    seat_dir = np.array([-np.cos(np.radians(73)), 0.0, np.sin(np.radians(73))])
    st_len = float(np.clip(0.50 * s, 0.2, (saddle_z - 0.08 - bb[2]) / seat_dir[2]))
    seat_top = bb + st_len * seat_dir
    saddle = bb + (saddle_z - bb[2]) / seat_dir[2] * seat_dir
    head_dir = np.array([-np.cos(np.radians(71)), 0.0, np.sin(np.radians(71))])
    fork_len = 0.40 * s * r / 0.34
    head_bottom = front + fork_len * head_dir + np.array([-0.04, 0.0, 0.0])
    head_len = float(np.clip(0.14 * s + 0.1 * u[0] * s, 0.08, max(0.09, (bar_z - 0.03 - head_bottom[2]) / head_dir[2])))
    head_top = head_bottom + head_len * head_dir
    bar = np.array([head_top[0] - 0.06 - 0.05 * u[1], 0.0, bar_z])
    return _BikeGeometry(r, tyre_r, wb, bb, seat_top, saddle, head_top, head_bottom, bar, bar_half,
                         crank=0.17 * min(1.0, s), crank_phase=float(2 * np.pi * u[2]), step_through=bool(u[3] < 0.2))


def _pedals(g: _BikeGeometry) -> np.ndarray:
    """(2, 3) pedal centres (left, right) for the crank phase."""
    ph = g.crank_phase
    out = []
    for s, extra in ((1.0, 0.0), (-1.0, np.pi)):
        a = ph + extra
        out.append(g.bb + np.array([g.crank * np.cos(a), s * 0.12, g.crank * np.sin(a)]))
    return np.array(out)


def _bike_parts(g: _BikeGeometry) -> tuple[list[MeshPart], np.ndarray]:
    """The bicycle's parts and its (2, 3) grip centres."""
    rear = np.array([-g.wheelbase / 2, 0.0, g.r])
    front = np.array([g.wheelbase / 2, 0.0, g.r])
    parts: list[MeshPart] = []
    parts += spoked_wheel(rear, g.r, g.tyre_r, 16, 0.055)
    parts += spoked_wheel(front, g.r, g.tyre_r, 16, 0.05)
    tr = 0.016  # main tube radius (3.2 cm tubes)
    if g.step_through:
        mid = 0.5 * (g.bb + g.head_bottom) + np.array([0.0, 0.0, -0.06])
        parts.append(tube(np.stack([g.bb, mid, g.head_bottom + np.array([0.0, 0.0, 0.03])]), tr, PAINT))
        low = g.seat_top + 0.45 * (g.bb - g.seat_top)
        parts.append(tube(np.stack([low, 0.5 * (low + g.head_bottom) + np.array([0, 0, -0.02]), g.head_bottom
                                    + 0.5 * (g.head_top - g.head_bottom)]), 0.012, PAINT))
    else:
        parts.append(tube(np.stack([g.bb, g.head_bottom]), tr, PAINT))
        seat_dir = (g.seat_top - g.bb) / np.linalg.norm(g.seat_top - g.bb)
        head_dir = (g.head_top - g.head_bottom) / np.linalg.norm(g.head_top - g.head_bottom)
        parts.append(tube(np.stack([g.seat_top - 0.03 * seat_dir, g.head_top - 0.02 * head_dir]), 0.0135, PAINT))
    parts.append(tube(np.stack([g.bb, g.seat_top]), 0.0145, PAINT))
    parts.append(tube(np.stack([g.head_bottom, g.head_top]), 0.019, PAINT))
    for s in (1.0, -1.0):
        off = np.array([0.0, s * 0.05, 0.0])
        parts.append(tube(np.stack([g.bb + 0.4 * off, rear + off]), 0.009, PAINT, n_around=6))
        parts.append(tube(np.stack([g.seat_top - 0.02 * (g.seat_top - g.bb), rear + off]), 0.008, PAINT, n_around=6))
        parts.append(tube(np.stack([g.head_bottom + 0.35 * off, front + off]), 0.011, PAINT, n_around=6))
    # seatpost + saddle
    parts.append(tube(np.stack([g.seat_top, g.saddle - np.array([0.0, 0.0, 0.04])]), 0.0125, STEEL))
    sc = g.saddle + np.array([0.01, 0.0, -0.03])
    parts.append(ellipsoid(sc, np.array([0.135, 0.075, 0.03]), BLACK, n_around=12, n_rings=7))
    # stem + bar
    stem_top = g.bar - np.array([0.0, 0.0, 0.0])
    parts.append(tube(np.stack([g.head_top, stem_top]), 0.014, STEEL))
    bar_parts, grips = _grip_bar(g.bar, g.bar_half, 0.02, 0.06, 0.011, 0.12, STEEL, BLACK)
    parts += bar_parts
    # drivetrain: chainring, cranks, pedals, chain (as two thin tubes)
    y = np.array([0.0, 1.0, 0.0])
    ring_c = g.bb + np.array([0.0, -0.045, 0.0])
    parts.append(revolve(np.array([-0.003, -0.003, 0.003, 0.003]), np.array([0.0, 0.1, 0.1, 0.0]), ring_c, y, STEEL,
                         n_around=20))
    parts.append(revolve(np.array([-0.06, -0.06, 0.06, 0.06]), np.array([0.0, 0.022, 0.022, 0.0]), g.bb, y, BLACK,
                         n_around=10))
    pedals = _pedals(g)
    for p, s in zip(pedals, (1.0, -1.0)):
        arm0 = g.bb + np.array([0.0, s * 0.065, 0.0])
        parts.append(tube(np.stack([arm0, p - np.array([0.0, s * 0.03, 0.0])]), 0.01, STEEL, n_around=6))
        parts.append(box(p - np.array([0.045, 0.045, 0.012]), p + np.array([0.045, 0.045, 0.012]), BLACK))
    cog = rear + np.array([0.0, -0.045, 0.0])
    for dz in (0.1, -0.1):
        parts.append(tube(np.stack([ring_c + np.array([0.0, 0.0, dz]), cog + np.array([0.0, 0.0, dz * 0.35])]), 0.004,
                          ENGINE, n_around=4))
    return parts, grips


def _bike_materials(rng: np.random.Generator) -> tuple[Material, ...]:
    u = rng.random(4)
    paint = _hex(_BIKE_PAINT[int(u[0] * len(_BIKE_PAINT)) % len(_BIKE_PAINT)])
    return (
        Material("frame_paint", base_color=paint, metallic=0.3 * u[1], roughness=0.3 + 0.2 * u[2], clearcoat=0.6),
        Material("tyre", base_color=np.array([0.025, 0.025, 0.025]), roughness=0.85, specular=0.5),
        Material("rim", base_color=np.array([0.55, 0.56, 0.58]) if u[3] < 0.6 else np.array([0.03, 0.03, 0.03]),
                 metallic=1.0, roughness=0.35),
        Material("steel", base_color=np.array([0.6, 0.6, 0.62]), metallic=1.0, roughness=0.3),
        Material("black_plastic", base_color=np.array([0.02, 0.02, 0.02]), roughness=0.7),
        Material("light", base_color=np.array([0.9, 0.9, 0.85]), roughness=0.1, emission=np.array([0.05, 0.05, 0.04])),
        Material("taillight", base_color=np.array([0.5, 0.02, 0.02]), roughness=0.15),
        Material("chain", base_color=np.array([0.15, 0.15, 0.15]), metallic=1.0, roughness=0.5),
    )


def procedural_bicycle(seed: int, wlh=None, variant: str | None = None) -> Asset:
    """A bicycle (optionally ridden), deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (frame style, colours, crank phase, rider).
        wlh: target box [w, l, h] metres (rider included), or None (a typical size for the variant).
        variant: ``with_rider`` / ``without_rider`` or None (drawn; from the target height when given).

    Returns:
        An :class:`Asset` (category ``vehicle.bicycle``, attribute ``cycle.with_rider`` /
        ``cycle.without_rider``) whose ``wlh`` matches the target within 1 %; tyres on z = 0.

    Raises:
        ValueError: unknown variant, or a wlh that is not 3 positive numbers.
    """
    name = "procedural_bicycle"
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xB1C7])
    target = target_wlh(wlh, name)
    variant = _choose_variant(rng, variant, target, name, 1.30)
    ridden = variant == "with_rider"
    u = rng.random(8)
    if target is None:
        size = read_class_sizes()["vehicle.bicycle"]
        target = np.array([0.56 + 0.14 * u[0] if not ridden else 0.62 + 0.12 * u[0], 1.70 + 0.14 * u[1],
                           1.02 + 0.1 * u[2] if not ridden else 1.62 + 0.16 * u[2]])
        target = np.clip(target, size.min_wlh, size.max_wlh)
    w, l, h = (float(x) for x in target)
    r_cap = 0.2 * h if ridden else 0.36 * h
    r = float(np.clip(min(0.19 * l + 0.02 * (u[3] - 0.5), r_cap), 0.16, 0.36))
    tyre_r = float(np.clip(0.014 + 0.016 * u[4], 0.012, 0.1 * r))
    mats = _bike_materials(rng)
    rider_seed = int(rng.integers(0, 2 ** 31))
    geom_u = rng.random(4)
    bar_half = max(0.5 * w - 0.012, 0.12)

    if not ridden:
        bar_z = h - 0.011
        saddle_z = min(bar_z - 0.02 - 0.05 * u[5], max(0.55 * h, r * 2.1))
        wb = l - 2 * r
        for _ in range(2):
            g = _bike_geometry(r, tyre_r, wb, saddle_z, bar_z, bar_half, geom_u)
            parts, _ = _bike_parts(g)
            V = np.concatenate([p.vertices for p in parts])
            wb += l - np.ptp(V[:, 0])
        all_parts, all_mats = parts, mats
    else:
        Hr = h / 1.0
        for _ in range(5):
            saddle_z = 0.53 * Hr * (0.97 + 0.06 * u[5])
            bar_z = saddle_z + (0.02 + 0.08 * u[6]) * Hr
            wb = l - 2 * r
            g = _bike_geometry(r, tyre_r, wb, saddle_z, bar_z, bar_half, geom_u)
            parts, grips = _bike_parts(g)
            pedals = _pedals(g) + np.array([0.0, 0.0, 0.013])
            rparts, rmats = rider_parts(rider_seed, g.saddle, grips, pedals, Hr)
            top = max(p.vertices[:, 2].max() for p in rparts + parts)
            if abs(h / top - 1.0) < 0.002:
                break
            Hr *= h / top
        all_parts, all_mats = _combine(parts, mats, rparts, rmats)
    return _finish(all_parts, all_mats, target, f"procedural-bicycle-{variant}-{seed}", "vehicle.bicycle",
                   _ATTRIBUTE[variant], ridden)


def _combine(parts: list[MeshPart], mats: tuple[Material, ...], rparts: list[MeshPart],
             rmats: tuple[Material, ...]) -> tuple[list[MeshPart], tuple[Material, ...]]:
    off = len(mats)
    shifted = [with_material(p, p.face_material + off) for p in rparts]
    return parts + shifted, mats + tuple(Material(f"rider_{m.name}", m.base_color, m.metallic, m.roughness, m.specular,
                                                    m.opacity, m.emission, m.clearcoat, m.retroreflective)
                                           for m in rmats)


def _finish(parts: list[MeshPart], mats: tuple[Material, ...], target: np.ndarray, name: str, category: str,
            attribute: str, ridden: bool) -> Asset:
    """Merge, put the box's bottom centre at the origin and meet the target box exactly.

    Length: already the tyres' span.  Height: a rider is scaled about its seat (< 1 %), a riderless
    vehicle's top is its bar / mirror, built to the height.  Width: a scale along y (wheels stay round).
    """
    V, F, M = merge_parts(parts)
    N = np.concatenate([p.normals for p in parts])
    lo, hi = V.min(axis=0), V.max(axis=0)
    V = V - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    ext = V.max(axis=0) - V.min(axis=0)
    w, l, h = target
    if abs(ext[2] - h) > 1e-9:
        # stretch only what lies above the wheels' top (rider or bars), keeping the tyres round
        z0 = min(0.95 * h, max(0.5 * ext[2], 0.0))
        above = V[:, 2] > z0
        V[above, 2] = z0 + (V[above, 2] - z0) * (h - z0) / (ext[2] - z0)
    sx, sy = l / ext[0], w / ext[1]  # sx is within a fraction of a per cent (the tyres set the length)
    V[:, 0] *= sx
    V[:, 1] *= sy
    N = N / np.array([sx, sy, 1.0])
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    asset = Asset(name=name, vertices=V, faces=F, face_material=M, materials=mats, vertex_normals=N,
                  category=category, attribute=attribute)
    return validate_asset(asset)


# ----------------------------------------------------------------------------- motorcycle


def _moto_materials(rng: np.random.Generator) -> tuple[Material, ...]:
    u = rng.random(3)
    paint = _hex(_MOTO_PAINT[int(u[0] * len(_MOTO_PAINT)) % len(_MOTO_PAINT)])
    return (
        Material("body_paint", base_color=paint, metallic=0.4 * u[1], roughness=0.25 + 0.1 * u[2], clearcoat=1.0),
        Material("tyre", base_color=np.array([0.022, 0.022, 0.022]), roughness=0.85, specular=0.5),
        Material("rim", base_color=np.array([0.05, 0.05, 0.055]) if u[1] < 0.6 else np.array([0.6, 0.6, 0.62]),
                 metallic=1.0, roughness=0.35),
        Material("chrome", base_color=np.array([0.75, 0.75, 0.77]), metallic=1.0, roughness=0.15),
        Material("black_plastic", base_color=np.array([0.02, 0.02, 0.022]), roughness=0.6),
        Material("headlight", base_color=np.array([0.9, 0.9, 0.88]), roughness=0.05,
                 emission=np.array([0.08, 0.08, 0.07])),
        Material("taillight", base_color=np.array([0.5, 0.015, 0.02]), roughness=0.12),
        Material("engine_metal", base_color=np.array([0.12, 0.12, 0.13]), metallic=1.0, roughness=0.45),
    )


@dataclass(frozen=True)
class _MotoGeometry:
    scooter: bool
    r: float
    tyre_r: float
    wheelbase: float
    bar: np.ndarray  # handlebar centre
    bar_half: float
    seat: np.ndarray  # where the rider sits (seat top)
    pegs: np.ndarray  # (2, 3) left/right feet
    mirror_half: float  # lateral offset of the mirror heads' outer edge
    mirror_z: float  # top of the mirror heads


def _moto_parts(g: _MotoGeometry, u: np.ndarray) -> tuple[list[MeshPart], np.ndarray]:
    """The motorcycle's parts and its (2, 3) grip centres."""
    rear = np.array([-g.wheelbase / 2, 0.0, g.r])
    front = np.array([g.wheelbase / 2, 0.0, g.r])
    parts: list[MeshPart] = []
    ws = 1.1 if g.scooter else 1.0
    parts += moto_wheel(rear, g.r, g.tyre_r, ws, disc=False)
    parts += moto_wheel(front, g.r, g.tyre_r, ws, disc=True)
    rake = np.radians(26 if g.scooter else 25)
    fdir = np.array([-np.sin(rake), 0.0, np.cos(rake)])
    steer_top = front + (g.bar[2] - 0.05 - front[2]) / fdir[2] * fdir
    wb = g.wheelbase
    # fork legs
    for s in (1.0, -1.0):
        off = np.array([0.0, s * (g.tyre_r + 0.035), 0.0])
        parts.append(tube(np.stack([front + off, steer_top + 0.25 * off - 0.05 * fdir]), 0.022, STEEL, n_around=8))
    parts.append(ellipsoid(steer_top, np.array([0.06, 0.12, 0.035]), ENGINE, n_around=10, n_rings=6))  # clamp
    # handlebar, grips, mirrors
    bar_parts, grips = _grip_bar(g.bar, g.bar_half, 0.03, 0.05, 0.012, 0.13, STEEL, BLACK)
    parts += bar_parts
    parts.append(tube(np.stack([steer_top, g.bar]), 0.015, STEEL, n_around=8))
    for s in (1.0, -1.0):
        base = g.bar + np.array([-0.02, s * 0.55 * g.bar_half, 0.0])
        head_r = np.array([0.02, 0.055, 0.04])
        head_c = np.array([base[0] - 0.04, s * (g.mirror_half - head_r[1]), g.mirror_z - head_r[2]])
        parts.append(tube(np.stack([base, head_c - np.array([0.0, s * 0.03, 0.0])]), 0.006, STEEL, n_around=6))
        parts.append(ellipsoid(head_c, head_r, BLACK, n_around=10, n_rings=6))
    # headlight
    hl_c = steer_top + np.array([0.09, 0.0, -0.08 if not g.scooter else -0.02])
    parts.append(ellipsoid(hl_c + np.array([-0.03, 0.0, 0.0]), np.array([0.07, 0.085, 0.085]), PAINT if g.scooter else
                           ENGINE, n_around=14, n_rings=8))
    parts.append(ellipsoid(hl_c + np.array([0.02, 0.0, 0.0]), np.array([0.035, 0.075, 0.075]), LIGHT, n_around=14,
                           n_rings=7))
    x_seat = g.seat[0]
    if g.scooter:
        floor_z = g.r + 0.02
        fl_front = front[0] - g.r - 0.02
        parts.append(box(np.array([x_seat - 0.05, -0.17, 0.16]), np.array([fl_front, 0.17, floor_z]), PAINT))
        # front shield: loft of ellipses rising from the floor to below the bars, leaning with the steering
        zs = np.linspace(0.16, g.bar[2] - 0.08, 6)
        xs = fl_front + (zs - zs[0]) * np.tan(rake) * -0.2 + np.linspace(0.0, 0.35, 6) * 0 + \
            np.interp(zs, [zs[0], zs[-1]], [0.04, (steer_top[0] - fl_front) - 0.02])
        a = np.array([0.0, 0.09, 0.1, 0.1, 0.09, 0.0])
        b = np.array([0.0, 0.21, 0.22, 0.2, 0.17, 0.0])
        xs[0], xs[-1] = xs[1], xs[-2]
        cen = np.stack([xs, np.zeros(6), zs], 1)
        parts.append(loft(ellipse_rings(cen, np.array([1.0, 0, 0]), np.array([0.0, 1, 0]), a, b, 16), PAINT))
        # rear body over the rear wheel and the engine
        rb_len = (x_seat + 0.25) - (rear[0] - 0.2)
        rb_lo, rb_hi = g.r - 0.04, g.seat[2] - 0.04
        rb_c = np.array([0.5 * (x_seat + 0.25 + rear[0] - 0.2), 0.0, 0.5 * (rb_lo + rb_hi)])
        rb_half = np.array([0.5 * rb_len, 0.17, 0.5 * (rb_hi - rb_lo)])
        parts.append(ellipsoid(rb_c, rb_half * np.array([1.12, 1.3, 1.2]), PAINT, n_around=20, n_rings=11,
                               clamp=rb_half))  # a rounded panel box over the rear wheel and engine
        parts.append(box(np.array([rear[0] - 0.05, -0.14, 0.12]), np.array([rear[0] + 0.35, -0.02, 0.3]), ENGINE))
        seat_c = g.seat + np.array([-0.05, 0.0, -0.04])
        parts.append(ellipsoid(seat_c, np.array([0.3, 0.15, 0.055]), BLACK, n_around=14, n_rings=7))
        tail = np.array([rear[0] - 0.2 + 0.02 - rb_half[0] * 0.0, 0.0, rb_hi - 0.06])
        parts.append(ellipsoid(tail, np.array([0.02, 0.08, 0.03]), TAIL, n_around=8, n_rings=5))
    else:
        # engine block and cylinder, tank, seat, tail, exhaust, side frame rails
        eng_c = np.array([0.05 * wb - 0.02, 0.0, g.r + 0.05])
        parts.append(box(eng_c - np.array([0.2, 0.15, 0.19]), eng_c + np.array([0.18, 0.15, 0.12]), ENGINE))
        parts.append(box(eng_c + np.array([-0.02, -0.11, 0.10]), eng_c + np.array([0.17, 0.11, 0.28]), ENGINE,
                         rotation=rot_y(-0.35), pivot=eng_c))
        tank_c = np.array([g.seat[0] + 0.36, 0.0, g.seat[2] + 0.03])
        parts.append(ellipsoid(tank_c, np.array([0.26, 0.17, 0.12]), PAINT, rotation=rot_y(0.12), n_around=16,
                               n_rings=9))
        seat_c = g.seat + np.array([-0.08, 0.0, -0.04])
        parts.append(ellipsoid(seat_c, np.array([0.30, 0.14, 0.05]), BLACK, n_around=14, n_rings=7))
        tail_end = rear[0] - 0.05 * u[0]
        tail_c = np.array([0.5 * (seat_c[0] + tail_end), 0.0, g.seat[2] - 0.05])
        parts.append(ellipsoid(tail_c, np.array([0.5 * (seat_c[0] - tail_end) + 0.05, 0.11, 0.07]), PAINT,
                               rotation=rot_y(-0.15), n_around=12, n_rings=7))
        parts.append(ellipsoid(np.array([tail_end - 0.02, 0.0, g.seat[2] - 0.04]), np.array([0.02, 0.07, 0.025]), TAIL,
                               n_around=8, n_rings=5))
        for s in (1.0, -1.0):
            rail = [steer_top - 0.1 * fdir, eng_c + np.array([0.15, s * 0.1, -0.1]),
                    eng_c + np.array([-0.22, s * 0.1, -0.12]), rear + np.array([0.05, s * 0.09, 0.0])]
            parts.append(tube(np.stack(rail), 0.016, ENGINE, n_around=6))
            sub = [np.array([x_seat - 0.05, s * 0.1, g.seat[2] - 0.08]), rear + np.array([0.0, s * 0.09, 0.02])]
            parts.append(tube(np.stack(sub), 0.012, ENGINE, n_around=6))
        ex0 = eng_c + np.array([0.12, -0.1, -0.05])
        ex1 = np.array([rear[0] + 0.25, -0.16, g.r - 0.05])
        parts.append(tube(np.stack([ex0, eng_c + np.array([0.0, -0.16, -0.16]), ex1]), 0.022, STEEL, n_around=8))
        parts.append(capsule(ex1, ex1 + np.array([-0.38, 0.0, 0.1]), 0.05, 0.045, STEEL, n_around=12, n_cap=2))
        # front mudguard
        mg = [front + g.r * 1.08 * np.array([np.cos(a), 0.0, np.sin(a)]) for a in np.radians([20, 60, 100, 140])]
        parts.append(tube(np.stack(mg), 0.025, PAINT, n_around=8))
    # foot pegs
    for p in g.pegs:
        parts.append(box(p - np.array([0.04, 0.04, 0.012]), p + np.array([0.04, 0.04, 0.012]), BLACK))
    return parts, grips


def procedural_motorcycle(seed: int, wlh=None, variant: str | None = None) -> Asset:
    """A motorcycle or scooter (optionally ridden), deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (scooter or standard bike, colours, proportions, rider).
        wlh: target box [w, l, h] metres (rider included), or None (a typical size for the variant).
        variant: ``with_rider`` / ``without_rider`` or None (drawn; from the target height when given).

    Returns:
        An :class:`Asset` (category ``vehicle.motorcycle``, attribute ``cycle.with_rider`` /
        ``cycle.without_rider``) whose ``wlh`` matches the target within 1 %; the rider wears a helmet.

    Raises:
        ValueError: unknown variant, or a wlh that is not 3 positive numbers.
    """
    name = "procedural_motorcycle"
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x3070])
    target = target_wlh(wlh, name)
    variant = _choose_variant(rng, variant, target, name, 1.32)
    ridden = variant == "with_rider"
    u = rng.random(10)
    size = read_class_sizes()["vehicle.motorcycle"]
    if target is None:
        typical_h = 1.15 + 0.1 * u[2] if not ridden else 1.38 + 0.12 * u[2]
        target = np.array([0.6 + 0.12 * u[0], 1.85 + 0.4 * u[1], typical_h])
        target = np.clip(target, size.min_wlh, size.max_wlh)
    w, l, h = (float(x) for x in target)
    scooter = bool(u[3] < (0.7 if l < 1.9 else 0.25))
    r = float(np.clip((0.115 if scooter else 0.15) * l + 0.02 * (u[4] - 0.5), 0.2, min(0.36, 0.29 * h)))
    tyre_r = (0.05 if scooter else 0.06) * r / 0.3
    wb = l - 2 * r
    mats = _moto_materials(rng)
    rider_seed = int(rng.integers(0, 2 ** 31))
    helmet = _hex(_MOTO_PAINT[int(u[5] * len(_MOTO_PAINT)) % len(_MOTO_PAINT)])
    part_u = rng.random(4)

    def geometry(bar_z: float, seat_z: float, mirror_z: float) -> _MotoGeometry:
        bar = np.array([wb / 2 - (0.33 if not scooter else 0.22) * wb / 1.3, 0.0, bar_z])
        seat = np.array([-0.12 * wb if not scooter else -0.15 * wb, 0.0, seat_z])
        if scooter:
            pegs = np.array([[bar[0] - 0.12, s * 0.12, r + 0.045] for s in (1.0, -1.0)])
        else:
            pegs = np.array([[seat[0] + 0.12 * wb / 1.3, s * 0.17, r + 0.02] for s in (1.0, -1.0)])
        mirror_half = max(0.5 * w, 0.3)
        return _MotoGeometry(scooter, r, tyre_r, wb, bar, min(0.38, max(0.28, 0.5 * w - 0.1)), seat, pegs,
                             mirror_half, mirror_z)

    if not ridden:
        mirror_z = h
        bar_z = min(h - 0.12 - 0.05 * u[6], max(0.75 * h, 2 * r + 0.35))
        seat_z = min(0.66 * h + 0.04 * u[7], bar_z - 0.12)
        g = geometry(bar_z, seat_z, mirror_z)
        all_parts, all_mats = _moto_parts(g, part_u)[0], mats
    else:
        Hr = h / 0.85
        bar_z = 1.0 + 0.06 * u[6] if not scooter else 0.98 + 0.06 * u[6]
        seat_z = 0.78 + 0.06 * u[7] if not scooter else 0.76 + 0.05 * u[7]
        scale_v = float(np.clip((h - 0.2) / 1.25, 0.6, 1.1))  # a low box: a smaller bike under a smaller rider
        bar_z, seat_z = bar_z * scale_v, seat_z * scale_v
        mirror_z = bar_z + 0.2
        g = geometry(bar_z, seat_z, mirror_z)
        parts, grips = _moto_parts(g, part_u)
        for _ in range(5):
            rparts, rmats = rider_parts(rider_seed, g.seat, grips, g.pegs + np.array([0.0, 0.0, 0.02]), Hr, helmet=True,
                                        helmet_color=helmet)
            top = max(p.vertices[:, 2].max() for p in rparts + parts)
            if abs(h / top - 1.0) < 0.002:
                break
            Hr *= (h - g.seat[2]) / (top - g.seat[2])  # the seat stays: only the part above it scales
        all_parts, all_mats = _combine(parts, mats, rparts, rmats)
    return _finish(all_parts, all_mats, target, f"procedural-{'scooter' if scooter else 'motorcycle'}-{variant}-{seed}",
                   "vehicle.motorcycle", _ATTRIBUTE[variant], ridden)


__all__ = ["moto_wheel", "procedural_bicycle", "procedural_bicycle_variants", "procedural_motorcycle",
           "procedural_motorcycle_variants", "spoked_wheel"]
