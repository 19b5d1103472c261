"""Procedural temporary road barriers: concrete jersey barriers, water-filled plastic barriers, fences.

A barrier's long side runs along y (the box's w) and its thin side along x (the box's l, facing the
road), as nuScenes annotates them.  ``concrete``: a New Jersey profile (610 mm base, 55 deg then 84 deg
faces, narrow top) extruded along y, grey concrete with optional painted stripes; ``water_filled``: a
rounded plastic profile with interlocking knuckles at the ends and a fill cap, red / white / orange /
yellow; ``fence``: a framed mesh panel on two feet with red-white retro-reflective boards.
Object frame: x front, y left, z up, metres, origin at the bottom centre, the base flat on z = 0.
"""

from __future__ import annotations

import numpy as np

from .asset import Asset, Material
from .class_sizes import read_class_sizes
from .mesh_parts import MeshPart, merge_parts, target_wlh
from .procedural import srgb_to_linear
from .revolve import box, loft, revolve, tube, with_material
from .validate import validate_asset

_VARIANTS = ("concrete", "water_filled", "fence")
_WEIGHTS = (0.45, 0.35, 0.20)
BODY, STRIPE, DARK, PANEL = range(4)
_PLASTIC = ("C8141E", "F2F2EE", "F26A0C", "F0C419")


def procedural_barrier_variants() -> tuple[str, ...]:
    """Variants of :func:`procedural_barrier` (``concrete``, ``water_filled``, ``fence``)."""
    return _VARIANTS


def _hex(h: str) -> np.ndarray:
    return srgb_to_linear(np.array([int(h[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)


def _extrude_y(profile_xz: np.ndarray, y0: float, y1: float, n_seg: int, material: int,
               sharp: np.ndarray | None = None) -> MeshPart:
    """A profile (N, 2) of (x, z) points (counter-clockwise seen from +y) extruded from y0 to y1 in
    ``n_seg`` segments (so faces can be painted per y); points flagged in ``sharp`` are doubled (sharp edges)."""
    P = np.asarray(profile_xz, dtype=np.float64)
    if sharp is not None:
        P = np.repeat(P, np.where(sharp, 2, 1), axis=0)
    ys = np.linspace(y0, y1, n_seg + 1)
    rings = np.stack([np.stack([P[:, 0], np.full(len(P), y), P[:, 1]], 1) for y in ys])
    return loft(rings, material, caps="flat", weld=False)


def _paint_by(part: MeshPart, mask: np.ndarray, material: int) -> MeshPart:
    return with_material(part, np.where(mask, material, part.face_material))


def _jersey(l: float, h: float, w: float, u: np.ndarray) -> list[MeshPart]:
    """A jersey barrier: base ``l`` wide (x), ``h`` tall, ``w`` long (y)."""
    hb = l / 2
    top_half = max(0.25 * hb, 0.05)
    z1, z2 = 0.093 * h, 0.41 * h
    x2 = hb - (hb - top_half) * 0.78  # 78 % of the inward run on the 55 deg face
    ch = 0.015  # chamfer of the top edges
    half = np.array([[hb, 0.0], [hb, z1], [x2, z2], [top_half, h - ch], [top_half - ch, h]])
    prof = np.concatenate([half, (half * np.array([-1.0, 1.0]))[::-1]])  # +x side up, then -x side down
    prof = prof[::-1]  # counter-clockwise seen from +y: x -> -z turns ... (orientation is fixed by loft anyway)
    n_seg = 12
    part = _extrude_y(prof, -w / 2, w / 2, n_seg, BODY, sharp=np.ones(len(prof), dtype=bool))
    if u[0] < 0.45:  # painted stripes: alternating blocks on the upper faces
        c = part.vertices[part.faces].mean(axis=1)
        k = np.floor((c[:, 1] + w / 2) / (w / n_seg)).astype(int)
        mask = (k % 2 == 0) & (c[:, 2] > 0.45 * h) & (c[:, 2] < 0.9 * h)
        part = _paint_by(part, mask, STRIPE)
    return [part]


def _water_filled(l: float, h: float, w: float, u: np.ndarray) -> list[MeshPart]:
    """A water-filled plastic barrier with interlocking knuckles at both ends and a fill cap."""
    hb = l / 2
    lug_r = min(0.06, 0.1 * hb + 0.03)
    body_y = w / 2 - lug_r  # the knuckles' outer edge is the box's end
    # smooth rounded profile (x, z): wide foot, waist, narrower rounded top
    zf = np.array([0.0, 0.0, 0.08, 0.16, 0.30, 0.45, 0.62, 0.80, 0.92, 0.98, 1.0]) * h
    xf = np.array([0.0, 1.0, 1.0, 0.86, 0.72, 0.64, 0.6, 0.56, 0.5, 0.35, 0.0]) * hb
    xf[-1] = 0.12 * hb  # a narrow flat ridge at the top
    half = np.stack([xf, zf], 1)[1:]
    prof = np.concatenate([half, (half * np.array([-1.0, 1.0]))[::-1]])
    sharp = np.zeros(len(prof), dtype=bool)
    sharp[[0, -1]] = True
    n_seg = 8
    part = _extrude_y(prof, -body_y, body_y, n_seg, BODY, sharp=sharp)
    parts = [part]
    z_axis = np.array([0.0, 0.0, 1.0])
    for s in (1.0, -1.0):
        for z0, z1 in ((0.05 * h, 0.3 * h), (0.55 * h, 0.8 * h)) if s > 0 else ((0.3 * h, 0.55 * h),):
            parts.append(revolve(np.array([0.0, 0.0, z1 - z0, z1 - z0]), np.array([0.0, lug_r, lug_r, 0.0]),
                                 np.array([0.0, s * body_y, z0]), z_axis, BODY, n_around=16, caps="pole"))
        parts.append(tube(np.stack([np.array([0.0, s * (body_y + lug_r * 0.3), 0.02 * h]),
                                    np.array([0.0, s * (body_y + lug_r * 0.3), 0.98 * h])]), 0.012, DARK, n_around=8))
    cap_r = min(0.07, 0.3 * hb)
    parts.append(revolve(np.array([0.0, 0.0, 0.035, 0.035]), np.array([0.0, cap_r, cap_r, 0.0]),
                         np.array([0.0, 0.0, h - 0.05]), z_axis, DARK, n_around=14))
    # the cap must not poke above h: it sits 0.015 below the top
    return parts


def _fence(l: float, h: float, w: float, u: np.ndarray) -> list[MeshPart]:
    """A fence panel on two feet: frame posts, a mesh panel and red-white striped boards."""
    foot_h = 0.08 + 0.05 * u[1]
    foot_w = 0.16
    parts: list[MeshPart] = []
    post_r = 0.02
    ends = np.array([-1.0, 1.0]) * (w / 2 - foot_w / 2)
    for y in ends:
        parts.append(box(np.array([-l / 2, y - foot_w / 2, 0.0]), np.array([l / 2, y + foot_w / 2, foot_h]), DARK))
        parts.append(tube(np.stack([np.array([0.0, y, foot_h * 0.5]), np.array([0.0, y, h - post_r])]), post_r, DARK,
                          n_around=8))
    # top rail
    parts.append(tube(np.stack([np.array([0.0, ends[0], h - post_r]), np.array([0.0, ends[1], h - post_r])]), post_r,
                      DARK, n_around=8))
    # boards: two (top and middle) with alternating red / white segments along y
    board_h = min(0.2, 0.18 * h)
    n_stripes = max(3, int(round((ends[1] - ends[0]) / 0.25)))
    edges = np.linspace(ends[0] + post_r, ends[1] - post_r, n_stripes + 1)
    for zc in (h - 2 * post_r - board_h / 2, 0.55 * h):
        for i in range(n_stripes):
            lo = np.array([-0.012, edges[i], zc - board_h / 2])
            hi = np.array([0.012, edges[i + 1], zc + board_h / 2])
            parts.append(box(lo, hi, BODY if i % 2 == 0 else STRIPE))
    # mesh panel below the boards (translucent plastic mesh)
    parts.append(box(np.array([-0.006, ends[0] + post_r, foot_h + 0.05]),
                     np.array([0.006, ends[1] - post_r, 0.55 * h - board_h / 2]), PANEL))
    return parts


def procedural_barrier(seed: int, wlh=None, variant: str | None = None) -> Asset:
    """A temporary road barrier, deterministic in (seed, wlh, variant).

    Args:
        seed: random seed (colours, stripes, proportions).
        wlh: target box [w, l, h] metres (w: the long side along y; l: the thin side along x), or None.
        variant: one of :func:`procedural_barrier_variants` or None (drawn: concrete 45 %,
            water_filled 35 %, fence 20 %).

    Returns:
        An :class:`Asset` (category ``movable_object.barrier``) with ``wlh`` equal to the target;
        a flat base on z = 0.  A few hundred to ~1 k triangles.

    Raises:
        ValueError: unknown variant, or a wlh that is not 3 positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xBA44])
    u = rng.random(8)
    if variant is None:
        variant = _VARIANTS[int(np.searchsorted(np.cumsum(_WEIGHTS), u[7] * sum(_WEIGHTS)))]
    if variant not in _VARIANTS:
        raise ValueError(f"procedural_barrier: unknown variant {variant!r}; expected one of {', '.join(_VARIANTS)}")
    if wlh is None:
        size = read_class_sizes()["movable_object.barrier"]
        typical = {"concrete": (2.0, 0.62, 0.85), "water_filled": (1.9, 0.5, 1.0), "fence": (2.2, 0.6, 1.1)}[variant]
        target = np.clip(np.array(typical) * (0.92 + 0.16 * rng.random(3)), size.min_wlh, size.max_wlh)
    else:
        target = target_wlh(wlh, "procedural_barrier")
        rng.random(3)
    w, l, h = (float(x) for x in target)
    if variant == "concrete":
        grey = np.array([0.42, 0.41, 0.39]) * (0.8 + 0.4 * u[2])
        stripe = _hex("F0C419") if u[3] < 0.5 else _hex("E8E8E4")
        materials = (Material("concrete", base_color=grey, roughness=0.9, specular=0.4),
                     Material("paint_stripe", base_color=stripe, roughness=0.6, retroreflective=0.3),
                     Material("dark_slot", base_color=np.array([0.03, 0.03, 0.03]), roughness=0.9),
                     Material("unused", base_color=grey, roughness=0.9))
        parts = _jersey(l, h, w, u)
    elif variant == "water_filled":
        color = _hex(_PLASTIC[int(u[2] * len(_PLASTIC)) % len(_PLASTIC)])
        materials = (Material("plastic", base_color=color, roughness=0.4),
                     Material("plastic_alt", base_color=color, roughness=0.4),
                     Material("plastic_dark", base_color=np.array([0.04, 0.04, 0.04]), roughness=0.5),
                     Material("unused", base_color=color, roughness=0.4))
        parts = _water_filled(l, h, w, u)
    else:
        materials = (Material("reflective_red", base_color=_hex("C8141E"), roughness=0.35, retroreflective=0.9),
                     Material("reflective_white", base_color=np.array([0.82, 0.82, 0.8]), roughness=0.35,
                              retroreflective=0.9),
                     Material("frame_dark", base_color=np.array([0.05, 0.05, 0.05]), roughness=0.6),
                     Material("mesh_panel", base_color=_hex("F26A0C"), roughness=0.6, opacity=0.5))
        parts = _fence(l, h, w, u)
    V, F, M = merge_parts(parts)
    N = np.concatenate([p.normals for p in parts])
    lo, hi = V.min(axis=0), V.max(axis=0)
    V = V - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    asset = Asset(name=f"procedural-barrier-{variant}-{seed}", vertices=V, faces=F, face_material=M,
                  materials=materials, vertex_normals=N, category="movable_object.barrier")
    return validate_asset(asset)


__all__ = ["procedural_barrier", "procedural_barrier_variants"]
