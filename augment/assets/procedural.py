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

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from .asset import Asset, Material
from .validate import face_normals, smooth_vertex_normals, validate_asset

# ----------------------------------------------------------------------------- body specifications


@dataclass(frozen=True)
class BodySpec:
    """Dimensions (metres) and side profile of a body type.

    ``top`` / ``bottom`` are control points (distance from the nose d, height z) of the roof line
    and the underbody (without arches); d runs from 0 (front) to ``length`` (rear).  ``d_ws``,
    ``d_roof_front``, ``d_roof_back``, ``d_rear`` mark windscreen base, windscreen top, roof end
    and rear-window base; ``pillars`` are the d of the B (and C) pillars between side windows.
    """

    length: float
    width: float
    height: float
    wheel_radius: float
    front_overhang: float
    rear_overhang: float
    belt_front: float
    belt_rear: float
    d_ws: float
    d_roof_front: float
    d_roof_back: float
    d_rear: float
    pillars: tuple[float, ...]
    top: tuple[tuple[float, float], ...]
    bottom: tuple[tuple[float, float], ...]
    tumblehome: float  # fraction by which the roof is narrower than the belt line
    plan_exponent: float  # superellipse exponent of the plan view (larger = squarer corners)


def _sedan() -> BodySpec:
    L, H = 4.60, 1.45
    return BodySpec(
        length=L, width=1.80, height=H, wheel_radius=0.32, front_overhang=0.92, rear_overhang=1.00,
        belt_front=0.90, belt_rear=0.98, d_ws=1.55, d_roof_front=2.25, d_roof_back=3.20, d_rear=3.85,
        pillars=(2.75,),
        top=((0.0, 0.58), (0.06, 0.70), (0.30, 0.78), (1.55, 0.90), (2.25, H - 0.02), (2.60, H), (3.20, H - 0.03),
             (3.85, 1.00), (4.45, 0.98), (4.56, 0.90), (L, 0.72)),
        bottom=((0.0, 0.42), (0.12, 0.28), (0.55, 0.20), (L - 0.6, 0.21), (L - 0.12, 0.30), (L, 0.45)),
        tumblehome=0.22, plan_exponent=4.0,
    )


def _hatchback() -> BodySpec:
    L, H = 4.10, 1.50
    return BodySpec(
        length=L, width=1.75, height=H, wheel_radius=0.31, front_overhang=0.82, rear_overhang=0.68,
        belt_front=0.92, belt_rear=1.00, d_ws=1.35, d_roof_front=2.00, d_roof_back=3.25, d_rear=3.92,
        pillars=(2.55,),
        top=((0.0, 0.58), (0.06, 0.70), (0.28, 0.79), (1.35, 0.92), (2.00, H - 0.02), (2.50, H), (3.25, H - 0.05),
             (3.92, 1.02), (4.04, 0.95), (L, 0.78)),
        bottom=((0.0, 0.42), (0.12, 0.28), (0.50, 0.20), (L - 0.5, 0.22), (L - 0.10, 0.32), (L, 0.48)),
        tumblehome=0.20, plan_exponent=4.0,
    )


def _suv() -> BodySpec:
    L, H = 4.70, 1.75
    return BodySpec(
        length=L, width=1.90, height=H, wheel_radius=0.37, front_overhang=0.92, rear_overhang=0.98,
        belt_front=1.08, belt_rear=1.14, d_ws=1.40, d_roof_front=2.10, d_roof_back=4.35, d_rear=4.62,
        pillars=(2.75, 3.75),
        top=((0.0, 0.72), (0.06, 0.88), (0.30, 0.98), (1.40, 1.08), (2.10, H - 0.02), (2.60, H), (4.35, H - 0.03),
             (4.62, 1.10), (L, 0.95)),
        bottom=((0.0, 0.52), (0.15, 0.36), (0.60, 0.28), (L - 0.6, 0.30), (L - 0.12, 0.38), (L, 0.52)),
        tumblehome=0.17, plan_exponent=5.0,
    )


def _van() -> BodySpec:
    L, H = 5.00, 1.95
    return BodySpec(
        length=L, width=2.00, height=H, wheel_radius=0.34, front_overhang=0.95, rear_overhang=1.05,
        belt_front=1.10, belt_rear=1.12, d_ws=0.85, d_roof_front=1.70, d_roof_back=4.90, d_rear=4.96,
        pillars=(2.30, 3.60),
        top=((0.0, 0.72), (0.06, 0.88), (0.25, 0.98), (0.85, 1.10), (1.70, H - 0.03), (2.30, H), (4.85, H - 0.02),
             (4.97, H - 0.12), (L, H - 0.30)),
        bottom=((0.0, 0.48), (0.15, 0.32), (0.55, 0.24), (L - 0.55, 0.26), (L - 0.12, 0.34), (L, 0.48)),
        tumblehome=0.10, plan_exponent=6.0,
    )


_BODIES = {"sedan": _sedan, "hatchback": _hatchback, "suv": _suv, "van": _van}
_BODY_WEIGHTS = {"sedan": 0.38, "hatchback": 0.22, "suv": 0.30, "van": 0.10}


def procedural_car_variants() -> tuple[str, ...]:
    """Names of the body types :func:`procedural_car` builds."""
    return tuple(_BODIES)


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
    names = list(_BODIES)
    if body is None:
        w = np.array([_BODY_WEIGHTS[n] for n in names])
        body = names[int(rng.choice(len(names), p=w / w.sum()))]
    else:
        rng.random()  # keep the stream aligned with the body=None case
    if body not in _BODIES:
        raise ValueError(f"procedural_car: unknown body {body!r}; expected one of {', '.join(names)}")
    spec = _jitter(_BODIES[body](), rng)
    materials, paint_name = _materials(rng, paint)

    parts = [_body_part(spec)]
    parts += _wheel_parts(spec)
    parts += _wheel_well_parts(spec)
    vertices, faces, face_material = _merge(parts)

    # Origin at the bottom centre of the box, tyres on z = 0.
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = vertices - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    normals = np.concatenate([p.normals for p in parts]) if all(p.normals is not None for p in parts) else None
    if normals is None:
        normals = smooth_vertex_normals(vertices, faces)
    asset = Asset(
        name=f"procedural-{body}-{seed}-{paint_name.replace(' ', '_')}",
        vertices=vertices, faces=faces, face_material=face_material, materials=materials,
        vertex_normals=normals, uv=None, category="vehicle.car",
    )
    return validate_asset(asset)


# ----------------------------------------------------------------------------- materials

PAINT, GLASS, TRIM, TYRE, RIM, HEADLIGHT, TAILLIGHT = range(7)


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


# ----------------------------------------------------------------------------- geometry helpers


@dataclass
class _Part:
    vertices: np.ndarray  # (V, 3)
    faces: np.ndarray  # (F, 3)
    face_material: np.ndarray  # (F,)
    normals: np.ndarray | None = None


def _merge(parts: list[_Part]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    V = np.concatenate([p.vertices for p in parts])
    F = np.concatenate([p.faces + o for p, o in zip(parts, offsets)])
    M = np.concatenate([p.face_material for p in parts])
    return V, F.astype(np.int64), M.astype(np.int64)


def _grid_faces(n_rows: int, n_cols: int, wrap_cols: bool) -> np.ndarray:
    """Two triangles per quad of a (n_rows, n_cols) vertex grid (row-major), (F, 3) int64."""
    cols = n_cols if wrap_cols else n_cols - 1
    r, c = np.meshgrid(np.arange(n_rows - 1), np.arange(cols), indexing="ij")
    r, c = r.ravel(), c.ravel()
    c1 = (c + 1) % n_cols
    a, b, cc, d = r * n_cols + c, r * n_cols + c1, (r + 1) * n_cols + c1, (r + 1) * n_cols + c
    return np.concatenate([np.stack([a, b, cc], 1), np.stack([a, cc, d], 1)])


def _signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    tri = V[F]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def _orient_outward(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip all faces if the (closed-ish) surface has negative signed volume."""
    return F if _signed_volume(V, F) >= 0 else F[:, ::-1].copy()


def _weld(V: np.ndarray, F: np.ndarray, tol: float = 1e-7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge coincident vertices; drop triangles that became degenerate (returns V, F, kept-face mask)."""
    key = np.round(V / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    F = inverse.reshape(-1)[F]
    ok = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    return V[first], F[ok], ok


# ----------------------------------------------------------------------------- body


def _jitter(spec: BodySpec, rng: np.random.Generator) -> BodySpec:
    """Scale a spec by a few percent (length, width, height independently)."""
    sl, sw, sh = rng.uniform(0.96, 1.04, size=3)

    def scale_pts(pts: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
        return tuple((d * sl, z * sh) for d, z in pts)

    return BodySpec(
        length=spec.length * sl, width=spec.width * sw, height=spec.height * sh,
        wheel_radius=spec.wheel_radius * float(np.sqrt(sl * sh)),
        front_overhang=spec.front_overhang * sl, rear_overhang=spec.rear_overhang * sl,
        belt_front=spec.belt_front * sh, belt_rear=spec.belt_rear * sh,
        d_ws=spec.d_ws * sl, d_roof_front=spec.d_roof_front * sl, d_roof_back=spec.d_roof_back * sl,
        d_rear=spec.d_rear * sl, pillars=tuple(p * sl for p in spec.pillars),
        top=scale_pts(spec.top), bottom=scale_pts(spec.bottom),
        tumblehome=spec.tumblehome, plan_exponent=spec.plan_exponent,
    )


def _axles_d(spec: BodySpec) -> tuple[float, float]:
    return spec.front_overhang, spec.length - spec.rear_overhang


def _stations(spec: BodySpec) -> np.ndarray:
    """Sorted distances from the nose d (S,) for the loft, dense at the ends and over the arches,
    with stations on every window / pillar boundary so material edges are straight."""
    L = spec.length
    t = np.linspace(0.0, 1.0, 29)
    d = [L * (1 - np.cos(np.pi * t)) / 2]  # cosine spacing: dense at both ends
    d.append(np.linspace(0.0, L, 34))
    ra = spec.wheel_radius + 0.05
    for dw in _axles_d(spec):
        d.append(dw + ra * np.cos(np.linspace(np.pi, 0.0, 13)))
    edges = [spec.d_ws, spec.d_roof_front, spec.d_roof_back, spec.d_rear, *_side_window_edges(spec)]
    d.append(np.array(edges))
    d = np.unique(np.clip(np.concatenate(d), 0.0, L))
    keep = np.concatenate([[True], np.diff(d) > 0.02])
    d = d[keep]
    d[-1] = L
    return d


def _side_window_edges(spec: BodySpec) -> list[float]:
    """d of the side-window edges: front (A pillar foot), pillar sides, rear."""
    edges = [spec.d_ws + 0.10, spec.d_rear - 0.10]
    for dp in spec.pillars:
        edges += [dp - 0.06, dp + 0.06]
    return edges


def _profiles(spec: BodySpec, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Roof line z_top, underbody z_bot (with arches), plan half width and belt height at stations d."""
    top = PchipInterpolator(*np.array(spec.top).T)(d)
    bot = PchipInterpolator(*np.array(spec.bottom).T)(d)
    r = spec.wheel_radius
    ra = r + 0.05
    for dw in _axles_d(spec):
        inside = np.abs(d - dw) < ra
        arch = r + np.sqrt(np.clip(ra**2 - (d - dw) ** 2, 0.0, None))
        bot = np.where(inside, np.maximum(bot, arch), bot)
    bot = np.minimum(bot, top - 0.08)
    xi = np.clip(np.abs(2.0 * d / spec.length - 1.0), 0.0, 1.0)
    p = spec.plan_exponent
    half_w = 0.5 * spec.width * (1.0 - xi**p) ** (1.0 / p)
    belt = np.interp(d, [spec.d_ws, spec.d_rear], [spec.belt_front, spec.belt_rear])
    return top, bot, half_w, belt


# Superellipse exponents of the cross-section: lower half boxier, upper half rounder.
_N_LOW, _N_UP = 5.0, 3.2
# Rows per half section, bottom to top: underbody, lower side up to the bumper line, up to the belt
# line, side glass, roof (or windscreen / bonnet).  Row edges lie on those lines at every station, so
# material boundaries along them are straight, not staircased.
_SEG_ROWS = (3, 3, 6, 4, 6)
_RAIL = 0.07  # roof rail height above the side glass (m)


def _bumper_line(spec: BodySpec) -> float:
    return 0.47 * spec.belt_front


def _angle_for_height(z: np.ndarray, zc: np.ndarray, hz: np.ndarray) -> np.ndarray:
    """Superellipse angle in [-pi/2, pi/2] of the section point at height z."""
    f = np.clip((z - zc) / hz, -1.0, 1.0)
    n = np.where(f > 0, _N_UP, _N_LOW)
    return np.sign(f) * np.arcsin(np.abs(f) ** (n / 2.0))


def _section_angles(spec: BodySpec, top, bot, belt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles (S, K) of one half section from the bottom centre (-pi/2) up to (excluding) the top,
    with the segment id (K,) and row position in its segment (K,) of every row."""
    zc, hz = (top + bot) / 2, (top - bot) / 2
    eps = 1e-3
    a_q = np.full_like(top, -np.pi / 4)
    a_bump = np.clip(_angle_for_height(np.full_like(top, _bumper_line(spec)), zc, hz), -np.pi / 4 + eps, None)
    a_belt = np.clip(_angle_for_height(belt, zc, hz), a_bump + eps, np.pi / 2 - 3 * eps)
    a_rail = np.clip(_angle_for_height(np.maximum(top - _RAIL, belt), zc, hz), a_belt + eps, np.pi / 2 - eps)
    a_top = np.full_like(top, np.pi / 2)

    def lin(a0, a1, n):
        t = np.linspace(0.0, 1.0, n, endpoint=False)
        return a0[:, None] + (a1 - a0)[:, None] * t[None, :]

    r = _SEG_ROWS
    lower = np.concatenate([lin(-a_top, a_q, r[0]), lin(a_q, a_bump, r[1])], axis=1)
    aligned = np.concatenate([lin(a_bump, a_belt, r[2]), lin(a_belt, a_rail, r[3]), lin(a_rail, a_top, r[4])], axis=1)
    uniform = lin(a_bump, a_top, aligned.shape[1])
    w = np.clip((top - belt - 0.05) / 0.15, 0.0, 1.0)[:, None]  # no cabin (bonnet, boot): even rows
    angles = np.concatenate([lower, w * aligned + (1.0 - w) * uniform], axis=1)
    seg = np.concatenate([np.full(n, k) for k, n in enumerate(r)])
    pos = np.concatenate([np.arange(n) for n in r])
    return angles, seg, pos


def _body_part(spec: BodySpec) -> _Part:
    d = _stations(spec)
    top, bot, half_w, belt = _profiles(spec, d)
    zc, hz = (top + bot) / 2, (top - bot) / 2
    right, seg, pos = _section_angles(spec, top, bot, belt)  # y < 0 side, bottom -> top
    # Full loop: bottom centre -> right side (y < 0) -> top centre -> left side (y > 0) -> back.
    phi = np.concatenate([right, np.full((len(d), 1), np.pi / 2), np.pi - right[:, ::-1][:, :-1]], axis=1)
    seg = np.concatenate([seg, [len(_SEG_ROWS) - 1], seg[::-1][:-1]])
    pos = np.concatenate([pos, [_SEG_ROWS[-1]], pos[::-1][:-1]])
    c, s = np.cos(phi), np.sin(phi)
    n_exp = np.where(s > 0, _N_UP, _N_LOW)
    ys = -np.sign(c) * np.abs(c) ** (2.0 / n_exp)
    zs = np.sign(s) * np.abs(s) ** (2.0 / n_exp)
    z = zc[:, None] + hz[:, None] * zs
    taper = _taper(spec, z, belt[:, None])
    y = half_w[:, None] * ys * taper
    x = spec.length / 2 - d
    V = np.stack([np.broadcast_to(x[:, None], y.shape), y, z], axis=-1).reshape(-1, 3)
    n_sec = phi.shape[1]
    F = _grid_faces(len(d), n_sec, wrap_cols=True)
    n_quads = len(F) // 2
    quad_mat = _body_materials(spec, V, F[:n_quads], F[n_quads:], seg, pos, n_sec)
    fm = np.concatenate([quad_mat, quad_mat])
    V, F, keep = _weld(V, F)
    fm = fm[keep]
    if _signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    return _Part(V, F, fm, smooth_vertex_normals(V, F))


def _taper(spec: BodySpec, z: np.ndarray, belt: np.ndarray) -> np.ndarray:
    """Tumblehome: width factor (<= 1) of the section at height z (the cabin leans inwards)."""
    cabin_h = spec.height - 0.5 * (spec.belt_front + spec.belt_rear)
    return 1.0 - spec.tumblehome * np.clip((z - belt) / cabin_h, 0.0, 1.0) ** 1.1


def _body_materials(spec: BodySpec, V: np.ndarray, tri_a: np.ndarray, tri_b: np.ndarray, seg: np.ndarray,
                    pos: np.ndarray, n_sec: int) -> np.ndarray:
    """Material per loft quad (triangles ``tri_a``, ``tri_b``) from its position, normal and section row.

    ``seg`` / ``pos``: per section vertex, the row segment (0 underbody, 1 lower side, 2 up to the
    belt line, 3 side glass, 4 roof) and the row index inside it.
    """
    na, aa = face_normals(V, tri_a)
    nb, ab = face_normals(V, tri_b)
    n = na * aa[:, None] + nb * ab[:, None]
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    cen = (V[tri_a].sum(axis=1) + V[tri_b].sum(axis=1)) / 6.0
    x, y, z = cen.T
    # Outward normal: the loft winding may be inverted; fix the sign by the section centre.
    outward = np.sign(np.einsum("ij,ij->i", n[:, 1:], np.stack([y, z - 0.7], 1)) + 1e-12)
    n = n * outward[:, None]
    d = spec.length / 2 - x
    _, _, _, belt = _profiles(spec, d)
    ay = np.abs(y)
    c0 = tri_a[:, 0] % n_sec
    c1 = (c0 + 1) % n_sec
    # The quad's lower row (its two columns are mirror-symmetric on the left / right halves).
    lower_first = (seg[c0] < seg[c1]) | ((seg[c0] == seg[c1]) & (pos[c0] <= pos[c1]))
    kind = np.where(lower_first, seg[c0], seg[c1])
    row = np.where(lower_first, pos[c0], pos[c1])
    kind_hi = np.maximum(seg[c0], seg[c1])
    mat = np.full(len(tri_a), PAINT, dtype=np.int64)

    # Greenhouse: side glass = the glass rows between the window edges; windscreen / rear window =
    # forward / backward facing quads above the belt, inside the pillars (measured from the full width).
    e = _side_window_edges(spec)
    in_side_x = (d > e[0]) & (d < e[1])
    for dp in spec.pillars:
        in_side_x &= np.abs(d - dp) > 0.06
    side = (kind == 3) & (kind_hi == 3) & in_side_x & (np.abs(n[:, 1]) > 0.3)
    full_hw = 0.5 * spec.width * _taper(spec, z, belt)
    above_belt = kind >= 3
    windscreen = (above_belt & (n[:, 0] > 0.3) & (ay < full_hw - 0.13)
                  & (d > spec.d_ws - 0.02) & (d < spec.d_roof_front + 0.02))
    rear = (above_belt & (n[:, 0] < -0.3) & (ay < full_hw - 0.16) & (d > spec.d_roof_back - 0.02)
            & (z > belt + 0.04))
    mat[side | windscreen | rear] = GLASS

    # Trim: underbody (and inner arches), bumpers below the bumper line, grille.
    d_front, d_rear_axle = _axles_d(spec)
    ra = spec.wheel_radius + 0.05
    under = (n[:, 2] < -0.55) | (kind == 0)
    bumper = (kind <= 1) & ((d < d_front - ra - 0.02) | (d > d_rear_axle + ra + 0.02))
    front = (d < 0.45) & (n[:, 0] > 0.25)
    grille = front & (kind == 2) & (row <= 1) & (ay < 0.22 * spec.width)
    mat[under | bumper | grille] = TRIM

    # Lights: head lights in the lowest rows above the bumper line at the front corners,
    # tail lights just under the belt line at the rear corners.
    head = front & (kind == 2) & (row <= 1) & (ay > 0.25 * spec.width) & (ay < 0.47 * spec.width)
    tail = ((d > spec.length - 0.40) & (n[:, 0] < -0.35) & (kind == 2) & (row >= 3) & (row <= 4)
            & (ay > 0.30 * spec.width))
    mat[head & ~under] = HEADLIGHT
    mat[tail & ~under] = TAILLIGHT
    return mat


# ----------------------------------------------------------------------------- wheels


def _wheel_parts(spec: BodySpec) -> list[_Part]:
    r = spec.wheel_radius
    tyre_w = 0.19 + 0.06 * (spec.width - 1.75) / 0.25
    y_out = 0.5 * spec.width - 0.035
    y_c = y_out - tyre_w / 2
    parts = []
    for dw in _axles_d(spec):
        x = spec.length / 2 - dw
        for side in (1.0, -1.0):
            parts.extend(_wheel(np.array([x, side * y_c, r]), side, r, tyre_w))
    return parts


def _wheel(centre: np.ndarray, side: float, r: float, width: float) -> list[_Part]:
    """Tyre (revolved rounded profile) plus a spoked rim cap on the outer face; axis along y."""
    n_around = 32
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False) - np.pi / 2  # includes the bottom point
    r_rim = 0.66 * r
    hw = width / 2
    # Closed profile (radius, axial) going around the tyre cross-section, outer side first.
    a = np.linspace(0.0, np.pi / 2, 4)
    rc = 0.045  # shoulder radius
    prof = np.concatenate([
        np.stack([np.linspace(r_rim, r - rc, 3, endpoint=False), np.full(3, hw)], 1),  # outer sidewall
        np.stack([r - rc + rc * np.sin(a), hw - rc + rc * np.cos(a)], 1),  # outer shoulder
        np.stack([np.full(2, r), np.linspace(hw - rc, -(hw - rc), 4)[1:-1]], 1),  # tread
        np.stack([r - rc + rc * np.cos(a), -(hw - rc) - rc * np.sin(a)], 1),  # inner shoulder
        np.stack([np.linspace(r - rc, r_rim, 3, endpoint=False)[1:], np.full(2, -hw)], 1),  # inner sidewall
        np.stack([np.full(2, r_rim), np.linspace(-hw, hw, 3, endpoint=False)[1:]], 1),  # rim seat
    ])
    rad, ax = prof[:, 0], prof[:, 1]
    ct, st = np.cos(theta), np.sin(theta)
    X = rad[None, :] * ct[:, None]
    Z = rad[None, :] * st[:, None]
    Y = np.broadcast_to(side * ax[None, :], X.shape)
    V = np.stack([X, Y, Z], -1).reshape(-1, 3) + centre
    F = _grid_faces(n_around, len(prof), wrap_cols=True)
    # close the around-direction (last ring to first ring)
    last = (n_around - 1) * len(prof) + np.arange(len(prof))
    first = np.arange(len(prof))
    nxt = (np.arange(len(prof)) + 1) % len(prof)
    F = np.concatenate([F, np.stack([last, last[nxt], first[nxt]], 1), np.stack([last, first[nxt], first], 1)])
    V, F, _ = _weld(V, F)
    F = _orient_about(V, F, centre)
    tyre = _Part(V, F, np.full(len(F), TYRE), smooth_vertex_normals(V, F))

    # Rim: a dished polar cap facing outwards (spokes metallic, gaps dark) plus an inner cap.
    rings = np.array([0.0, 0.18, 0.32, 0.55, 0.80, 0.93, 1.0]) * r_rim
    depth = np.array([0.0, 0.0, 0.012, 0.03, 0.035, 0.02, 0.0]) + 0.01  # recess from the tyre face
    caps = []
    for face_side, radii, recess in ((1.0, rings, depth), (-1.0, rings[[0, -1]], np.full(2, 0.02))):
        ax_pos = face_side * (hw - recess)
        Xc = radii[None, :] * ct[:, None]
        Zc = radii[None, :] * st[:, None]
        Yc = np.broadcast_to(side * ax_pos[None, :], Xc.shape)
        Vc = np.stack([Xc, Yc, Zc], -1).reshape(-1, 3) + centre
        Fc = _grid_faces(n_around, len(radii), wrap_cols=False)
        last = (n_around - 1) * len(radii) + np.arange(len(radii) - 1)
        first = np.arange(len(radii) - 1)
        Fc = np.concatenate([Fc, np.stack([last, first, first + 1], 1), np.stack([last, first + 1, last + 1], 1)])
        Vc, Fc, _ = _weld(Vc, Fc)
        outward = np.array([0.0, side * face_side, 0.0])
        fn, _ = face_normals(Vc, Fc)
        if (fn @ outward).mean() < 0:
            Fc = Fc[:, ::-1].copy()
        cen = Vc[Fc].mean(axis=1) - centre
        ang = np.arctan2(cen[:, 2], cen[:, 0])
        rr = np.hypot(cen[:, 0], cen[:, 2])
        spoke = (np.cos(5 * ang) > -0.25) | (rr < 0.3 * r_rim) | (rr > 0.86 * r_rim) | (face_side < 0)
        fm = np.where(spoke, RIM, TRIM)
        caps.append(_Part(Vc, Fc, fm, smooth_vertex_normals(Vc, Fc)))
    return [tyre, *caps]


def _orient_about(V: np.ndarray, F: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Orient a closed surface around ``centre`` so its signed volume is positive."""
    return _orient_outward(V - centre, F)


def _wheel_well_parts(spec: BodySpec) -> list[_Part]:
    """Dark boxes between each axle's tyres, so the arches look deep rather than see-through."""
    r = spec.wheel_radius
    ra = r + 0.05
    tyre_w = 0.19 + 0.06 * (spec.width - 1.75) / 0.25
    half_y = 0.5 * spec.width - 0.035 - tyre_w - 0.02
    parts = []
    for dw in _axles_d(spec):
        x = spec.length / 2 - dw
        lo = np.array([x - 0.9 * ra, -half_y, 0.12])
        hi = np.array([x + 0.9 * ra, half_y, r + ra + 0.02])
        V, F = _box(lo, hi)
        parts.append(_Part(V, F, np.full(len(F), TRIM), None))
    for p in parts:
        p.normals = smooth_vertex_normals(p.vertices, p.faces)
    return parts


def _box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box: 24 vertices (flat-shaded faces), 12 outward triangles."""
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64)
    P = lo + corners * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    V, F = [], []
    for q in quads:
        base = len(V)
        V.extend(P[list(q)])
        F.extend([(base, base + 1, base + 2), (base, base + 2, base + 3)])
    V, F = np.array(V), np.array(F, dtype=np.int64)
    fn, _ = face_normals(V, F)
    inward = np.einsum("ij,ij->i", fn, V[F].mean(axis=1) - (lo + hi) / 2) < 0
    F[inward] = F[inward][:, ::-1]
    return V, F
