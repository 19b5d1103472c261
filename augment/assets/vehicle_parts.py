"""Shared parts of the procedural large vehicles (trucks, buses, trailers, construction vehicles).

Every function returns :class:`~.mesh_parts.MeshPart` objects in the object frame (x front, y left,
z up, metres) built around the box centre line (y = 0) with the ground at z = 0; :func:`finish_vehicle`
merges them into a validated :class:`~.asset.Asset` whose box is the requested ``wlh``.

Parts: axis-aligned and oriented boxes, convex prisms, tubes, lofts along x of rounded-rectangle
cross-sections (bodies, cabs, cargo boxes: wheel arches from a varying underside, rounded ends,
per-face materials from :class:`Region` rules such as window bands), revolved wheels (tyre + dished
rim) for any radius and width, mirrors and light clusters.  All parts are closed surfaces with
outward faces, so a ray caster sees them as solids.

Material slots (indices into the table :func:`vehicle_materials` returns) are the module constants
``PAINT``, ``ACCENT`` (second colour: cargo box, livery skirt, tarp), ``GLASS``, ``TRIM`` (black
plastic), ``TYRE``, ``RIM``, ``METAL`` (dark chassis steel), ``CHROME``, ``HEADLIGHT``, ``TAILLIGHT``,
``INDICATOR`` (amber) and ``CARGO`` (a load's colour).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .asset import Asset, Material
from .mesh_parts import MeshPart, box_mesh, grid_faces, merge_parts, orient_outward
from .procedural import srgb_to_linear
from .validate import face_normals, smooth_vertex_normals, validate_asset

PAINT, ACCENT, GLASS, TRIM, TYRE, RIM, METAL, CHROME, HEADLIGHT, TAILLIGHT, INDICATOR, CARGO = range(12)

# (name, sRGB hex, weight): loads on flatbeds (wood, tarps, painted steel, plastic wrap)
CARGO_PALETTE: tuple[tuple[str, str, float], ...] = (
    ("timber", "9C7A4E", 3.0), ("blue tarp", "2A4F8C", 2.0), ("green tarp", "3B5E3A", 1.0),
    ("grey tarp", "6E7074", 2.0), ("white wrap", "D8D8D2", 1.5), ("cardboard", "A88558", 1.5),
    ("rusty steel", "6B4A34", 1.0), ("orange", "D9621C", 0.5),
)

# ----------------------------------------------------------------------------- inputs


def choose_variant(rng: np.random.Generator, variant: str | None, weights: dict[str, float], where: str) -> str:
    """``variant`` checked against ``weights``' names, or one drawn with those weights when None.

    Always draws one number from ``rng`` so the stream is the same whether or not a variant is given.

    Raises:
        ValueError: an unknown variant (the message names the valid ones).
    """
    names = list(weights)
    u = rng.random()
    if variant is None:
        w = np.cumsum([weights[n] for n in names])
        return names[int(np.searchsorted(w / w[-1], u, side="right").clip(0, len(names) - 1))]
    if variant not in weights:
        raise ValueError(f"{where}: unknown variant {variant!r}; expected one of {', '.join(names)}")
    return variant


def hex_to_linear(hexcode: str) -> np.ndarray:
    """An sRGB hex colour ``"RRGGBB"`` as linear RGB (3,)."""
    return srgb_to_linear(np.array([int(hexcode[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)


def pick_colour(rng: np.random.Generator, palette: tuple[tuple[str, str, float], ...]) -> tuple[str, np.ndarray]:
    """A weighted draw from ``palette`` ((name, sRGB hex, weight) entries): (name, linear RGB (3,))."""
    w = np.array([p[2] for p in palette], dtype=np.float64)
    i = int(rng.choice(len(palette), p=w / w.sum()))
    return palette[i][0], np.clip(hex_to_linear(palette[i][1]) * rng.uniform(0.94, 1.06), 0.0, 1.0)


# ----------------------------------------------------------------------------- materials


def vehicle_materials(rng: np.random.Generator, paint: np.ndarray, accent: np.ndarray, paint_metallic: float = 0.1,
                      accent_clearcoat: float = 1.0) -> tuple[Material, ...]:
    """The material table of a large vehicle, in slot order (``PAINT`` ... ``CARGO``).

    Args:
        paint, accent: linear RGB (3,) of the main and the second colour.
        paint_metallic: how metallic the main paint looks (commercial paints are mostly solid: ~0-0.2): the
            share of its base coat that is flakes (``Material.flake``; its UE4 metallic stays 0, as for cars).
        accent_clearcoat: clear-coat of the accent (0 for tarps and painted steel boxes).
    """
    return (
        Material("paint", base_color=np.asarray(paint, float), metallic=0.0, flake=float(paint_metallic),
                 roughness=float(rng.uniform(0.32, 0.48)), clearcoat=1.0),
        Material("accent", base_color=np.asarray(accent, float), metallic=0.0, roughness=float(rng.uniform(0.4, 0.6)),
                 clearcoat=accent_clearcoat),
        Material("glass", base_color=np.array([0.015, 0.02, 0.022]) * rng.uniform(0.8, 1.2), roughness=0.05,
                 opacity=float(rng.uniform(0.30, 0.50))),
        Material("trim", base_color=np.array([0.025, 0.025, 0.027]), roughness=0.75),
        Material("tyre", base_color=np.array([0.02, 0.02, 0.02]), roughness=0.9, specular=0.5),  # rubber n ~1.5: 4 %
        Material("rim", base_color=np.array([0.55, 0.55, 0.57]) * rng.uniform(0.8, 1.1), metallic=1.0,
                 roughness=0.35),
        Material("metal", base_color=np.array([0.05, 0.05, 0.055]), metallic=0.6, roughness=0.6),
        Material("chrome", base_color=np.array([0.75, 0.75, 0.77]), metallic=1.0, roughness=0.12),
        Material("headlight", base_color=np.array([0.85, 0.85, 0.85]), roughness=0.06,
                 emission=np.array([0.05, 0.05, 0.05])),
        Material("taillight", base_color=np.array([0.45, 0.015, 0.02]), roughness=0.12),
        Material("indicator", base_color=np.array([0.8, 0.35, 0.02]), roughness=0.12),
        Material("cargo", base_color=pick_colour(rng, CARGO_PALETTE)[1], roughness=float(rng.uniform(0.6, 0.9))),
    )


# ----------------------------------------------------------------------------- generic parts


def make_part(V: np.ndarray, F: np.ndarray, mat, normals: np.ndarray | None = None) -> MeshPart:
    """A part from vertices (V, 3), faces (F, 3) and a material slot (int) or per-face slots (F,)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    fm = np.broadcast_to(np.asarray(mat, dtype=np.int64), (len(F),)).copy()
    return MeshPart(V, F, fm, smooth_vertex_normals(V, F) if normals is None else normals)


def _unit_box() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    V, F = box_mesh(np.zeros(3), np.ones(3))
    fn, _ = face_normals(V, F)
    N = np.zeros_like(V)
    N[F[:, 0]] = fn  # each vertex belongs to one face (flat shading)
    for a in (V, F, N):
        a.flags.writeable = False
    return V, F, N


_UNIT_BOX = _unit_box()


def box(lo, hi, mat) -> MeshPart:
    """An axis-aligned box between corners ``lo`` (3,) and ``hi`` (3,) (either order per axis), flat-shaded."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    V0, F, N = _UNIT_BOX
    return MeshPart(lo + V0 * (hi - lo), F, np.full(len(F), mat, dtype=np.int64), N)


def _axes(axis: str) -> tuple[int, int, int]:
    """(index of u, index of v, index of the extrusion axis) for outlines in the plane across ``axis``."""
    return {"x": (1, 2, 0), "y": (0, 2, 1), "z": (0, 1, 2)}[axis]


def prism(outline, axis: str, a0: float, a1: float, mat, smooth: bool = False) -> MeshPart:
    """A convex polygon ``outline`` (N, 2) extruded along ``axis`` from ``a0`` to ``a1``.

    The outline's coordinates are (x, z) for axis ``"y"``, (y, z) for ``"x"`` and (x, y) for ``"z"``;
    either winding. ``smooth`` shares the side vertices (a round outline: cylinders, track loops).
    """
    P = np.asarray(outline, dtype=np.float64)
    n = len(P)
    iu, iv, ia = _axes(axis)
    ring = np.zeros((2, n, 3))
    ring[..., iu], ring[..., iv] = P[:, 0], P[:, 1]
    ring[0, :, ia], ring[1, :, ia] = a0, a1
    parts_V, parts_F = [], []
    if smooth:
        parts_V.append(ring.reshape(-1, 3))
        parts_F.append(grid_faces(2, n, wrap_cols=True))
    else:
        for i in range(n):
            j = (i + 1) % n
            q = np.array([ring[0, i], ring[0, j], ring[1, j], ring[1, i]])
            parts_V.append(q)
            parts_F.append(np.array([[0, 1, 2], [0, 2, 3]]))
    for k in (0, 1):
        c = ring[k].mean(axis=0)
        parts_V.append(np.concatenate([ring[k], c[None]]))
        i = np.arange(n)
        parts_F.append(np.stack([np.full(n, n), i, (i + 1) % n], 1))
    offs = np.cumsum([0] + [len(v) for v in parts_V[:-1]])
    V = np.concatenate(parts_V)
    F = np.concatenate([f + o for f, o in zip(parts_F, offs)])
    centre = V.mean(axis=0)
    F = orient_outward(V - centre, F)
    if smooth:
        # side normals radial in the outline plane, caps flat
        N = smooth_vertex_normals(V, F)
        side = 2 * n
        ns = smooth_vertex_normals(V[:side], F[np.all(F < side, axis=1)])  # sides only: no bend towards caps
        ns[:, ia] = 0.0
        N[:side] = ns / np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
        return make_part(V, F, mat, N)
    return make_part(V, F, mat)


def circle(centre_uv, radius: float, n: int = 16, start: float = 0.0) -> np.ndarray:
    """(n, 2) points of a circle in an outline plane."""
    a = start + np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.asarray(centre_uv, float) + radius * np.stack([np.cos(a), np.sin(a)], 1)


def stadium(x0: float, x1: float, z0: float, z1: float, n_end: int = 8) -> np.ndarray:
    """Convex (N, 2) outline of a stadium (a rectangle with round ends) spanning [x0, x1] x [z0, z1]."""
    r = 0.5 * (z1 - z0)
    zc = z0 + r
    a = np.linspace(-np.pi / 2, np.pi / 2, n_end + 1)
    front = np.stack([x1 - r + r * np.cos(a), zc + r * np.sin(a)], 1)
    back = np.stack([x0 + r - r * np.cos(a), zc - r * np.sin(a)], 1)
    return np.concatenate([front, back])


def tube(p0, p1, radius: float, mat, n: int = 12) -> MeshPart:
    """A closed cylinder of ``radius`` from point ``p0`` (3,) to ``p1`` (3,), smooth sides."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    length = float(np.linalg.norm(d))
    d = d / max(length, 1e-12)
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    local = prism(circle((0, 0), radius, n), "z", 0.0, length, mat, smooth=True)
    R = np.stack([e1, e2, d], 1)
    return MeshPart(local.vertices @ R.T + p0, local.faces, local.face_material, local.normals @ R.T)


def beam(p0, p1, y0: float, y1: float, t0: float, t1: float | None = None, mat=0) -> MeshPart:
    """A (tapered) beam in the x-z plane from ``p0`` to ``p1`` ((x, z) points), thickness t0 -> t1, y in [y0, y1]."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    t1 = t0 if t1 is None else t1
    d = p1 - p0
    nrm = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-12)
    outline = [p0 - nrm * t0 / 2, p1 - nrm * t1 / 2, p1 + nrm * t1 / 2, p0 + nrm * t0 / 2]
    return prism(outline, "y", y0, y1, mat)


# ----------------------------------------------------------------------------- lofted bodies


@dataclass(frozen=True)
class Region:
    """A material rule for the faces of a loft: faces whose centroid lies in [lo, hi] (3,) each and whose
    normal n has ``n . normal > min_dot`` (``both_sides``: ``|n . normal|``) get material ``mat``."""

    mat: int
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    normal: tuple[float, float, float] | None = None
    min_dot: float = 0.5
    both_sides: bool = False


def apply_regions(centroids: np.ndarray, normals: np.ndarray, base: int, regions: list[Region]) -> np.ndarray:
    """Per-face material (F,) int64: ``base``, overridden by each matching :class:`Region` in order."""
    fm = np.full(len(centroids), base, dtype=np.int64)
    for r in regions:
        m = np.all((centroids >= np.asarray(r.lo)) & (centroids <= np.asarray(r.hi)), axis=1)
        if r.normal is not None:
            d = normals @ np.asarray(r.normal, dtype=np.float64)
            m &= (np.abs(d) if r.both_sides else d) > r.min_dot
        fm[m] = r.mat
    return fm


def rounded_rect_ring(lo: float, hi: float, hw: float, rc: float, z_cuts: np.ndarray, n_corner: int) -> np.ndarray:
    """(M, 2) (y, z) points around a rounded rectangle, counter-clockwise seen from +x; the sides hold
    extra points at the heights ``z_cuts`` (clipped to the straight part) so materials can change there."""
    rc = max(min(rc, 0.49 * (hi - lo), 0.49 * hw), 0.0)
    a = np.linspace(0.0, np.pi / 2, n_corner + 1)
    cuts = np.clip(np.asarray(z_cuts, float), lo + rc, hi - rc)
    right_side = np.stack([np.full(len(cuts), hw), cuts], 1)
    pts = [
        np.stack([hw - rc + rc * np.sin(a), lo + rc - rc * np.cos(a)], 1),  # bottom right corner
        right_side,
        np.stack([hw - rc + rc * np.cos(a), hi - rc + rc * np.sin(a)], 1),  # top right
        np.stack([-(hw - rc) - rc * np.sin(a), hi - rc + rc * np.cos(a)], 1),  # top left
        right_side[::-1] * np.array([-1.0, 1.0]),
        np.stack([-(hw - rc) - rc * np.cos(a), lo + rc - rc * np.sin(a)], 1),  # bottom left
    ]
    return np.concatenate(pts)


def loft_x(xs, z_lo, z_hi, half_w, radius: float, mat=PAINT, regions: list[Region] | None = None,
           z_cuts=(), end_round: tuple[float, float] = (0.0, 0.0), n_corner: int = 3) -> MeshPart:
    """A closed body lofted along x through rounded-rectangle cross-sections.

    Args:
        xs: (n,) increasing stations (m); ``z_lo``, ``z_hi``, ``half_w``: (n,) bottom, top and half width there
            (scalars broadcast).  A varying ``z_lo`` makes wheel arches (see :func:`arch_bottom`).
        radius: corner radius of the cross-sections (m, clipped to fit).
        mat, regions: base material slot and :class:`Region` rules (window bands, grilles, skirts).
        z_cuts: heights where every side gets a vertex row (material boundaries stay straight).
        end_round: (rear, front) rounding radius e (m) of the ends, which are closed by flat caps; a rounded
            end reaches e beyond ``xs[0]`` / ``xs[-1]``.
        n_corner: segments per rounded corner.
    """
    xs = np.asarray(xs, dtype=np.float64)
    lo, hi, hw = (np.broadcast_to(np.asarray(v, float), xs.shape) for v in (z_lo, z_hi, half_w))
    # extra stations rounding the ends: inset d = e (1 - cos t) at x = end +/- e sin t, t in (0, 90 deg]
    t = np.linspace(0.0, np.pi / 2, 4)[1:]
    e_rear, e_front = end_round
    st_x, st_lo, st_hi, st_hw, st_in = list(xs), list(lo), list(hi), list(hw), [0.0] * len(xs)
    if e_front > 0:
        for tk in t:
            st_x.append(xs[-1] + e_front * np.sin(tk))
            st_lo.append(lo[-1]), st_hi.append(hi[-1]), st_hw.append(hw[-1])
            st_in.append(e_front * (1 - np.cos(tk)))
    if e_rear > 0:
        for tk in t:
            st_x.insert(0, xs[0] - e_rear * np.sin(tk))
            st_lo.insert(0, lo[0]), st_hi.insert(0, hi[0]), st_hw.insert(0, hw[0])
            st_in.insert(0, e_rear * (1 - np.cos(tk)))
    rings = []
    for x, zl, zh, h, d in zip(st_x, st_lo, st_hi, st_hw, st_in):
        d = min(d, 0.45 * (zh - zl), 0.45 * h)
        ring = rounded_rect_ring(zl + d, zh - d, h - d, max(radius - d, 0.0), z_cuts, n_corner)
        rings.append(np.column_stack([np.full(len(ring), x), ring]))
    R = np.stack(rings)  # (S, M, 3)
    S, M = R.shape[:2]
    V = R.reshape(-1, 3)
    F = grid_faces(S, M, wrap_cols=True)
    # caps: horizontal strips between each ring point and its mirror image (ring index M - 1 - i), so the
    # cap's rows lie at the ring's heights (z_cuts) and materials change there on the end faces too
    i = np.arange(M // 2 - 1)
    j = M - 1 - i
    cap_F = np.concatenate([np.stack([i, i + 1, j - 1], 1), np.stack([i, j - 1, j], 1)])
    body_V, body_F = V, F
    fn, _ = face_normals(V, F)
    away = V[F].mean(axis=1) * np.array([0.0, 1.0, 1.0]) - np.array([0.0, 0.0, 0.5 * (min(st_lo) + max(st_hi))])
    if np.einsum("ij,ij->", fn, away) < 0:
        body_F = body_F[:, ::-1]
    caps = []
    for k, ring, sign in ((0, R[0], -1.0), (1, R[-1], 1.0)):
        cf = cap_F if face_normals(ring, cap_F)[0][:, 0].sum() * sign > 0 else cap_F[:, ::-1]
        caps.append(cf + len(body_V) + k * M)
    V = np.concatenate([body_V, R[0], R[-1]])
    F = np.concatenate([body_F, *caps])
    N = np.zeros_like(V)
    # caps are flat: their own vertices get the cap normal
    nb = len(body_V)
    N[nb:nb + M] = [-1.0, 0.0, 0.0]
    N[nb + M:] = [1.0, 0.0, 0.0]
    N[:nb] = smooth_vertex_normals(body_V, F[np.all(F < nb, axis=1)])
    fn, _ = face_normals(V, F)
    fm = apply_regions(V[F].mean(axis=1), fn, mat, regions or [])
    return MeshPart(V, F, fm, N)


def arch_stations(x0: float, x1: float, arches: list[tuple[float, float]], cuts=(), n_arch: int = 10,
                  step: float = 0.6) -> np.ndarray:
    """Sorted unique stations (n,) in [x0, x1]: a regular spacing <= ``step``, ``n_arch`` points across each
    arch ((x centre, radius) pairs) and the ``cuts`` (material boundaries)."""
    xs = [np.linspace(x0, x1, max(int(np.ceil((x1 - x0) / step)) + 1, 2))]
    for xa, ra in arches:
        xs.append(xa + ra * np.cos(np.linspace(np.pi, 0.0, n_arch)))
    xs.append(np.asarray(cuts, float))
    x = np.concatenate(xs)
    x = np.unique(np.round(x[(x >= x0) & (x <= x1)], 6))
    return x


def arch_bottom(xs: np.ndarray, clearance: float, arches: list[tuple[float, float]], z_centre: float) -> np.ndarray:
    """Underside heights (n,) at ``xs``: ``clearance`` except half-circle arches (x centre, radius) about z_centre."""
    z = np.full(len(xs), clearance, dtype=np.float64)
    for xa, ra in arches:
        inside = np.abs(xs - xa) < ra
        z[inside] = np.maximum(z[inside], z_centre + np.sqrt(ra ** 2 - (xs[inside] - xa) ** 2))
    return z


def taper(part: MeshPart, x_lo: float, x_hi: float, z_lo: float, z_hi: float, front_setback: float = 0.0,
          rear_setback: float = 0.0, tumble: float = 0.0) -> MeshPart:
    """A part bent into a glasshouse shape: at height z_hi its front moves back by ``front_setback``, its rear
    forward by ``rear_setback`` and its width shrinks by the fraction ``tumble`` (linear in z from z_lo)."""
    V = part.vertices.copy()
    t = np.clip((V[:, 2] - z_lo) / max(z_hi - z_lo, 1e-9), 0.0, 1.0)
    u = np.clip((V[:, 0] - x_lo) / max(x_hi - x_lo, 1e-9), 0.0, 1.0)
    V[:, 0] -= t * (u * front_setback - (1.0 - u) * rear_setback)
    V[:, 1] *= 1.0 - tumble * t
    N = smooth_vertex_normals(V, part.faces)
    return MeshPart(V, part.faces, part.face_material, N)


# ----------------------------------------------------------------------------- wheels


def wheel(centre, radius: float, width: float, side: float, rim_frac: float = 0.58, n_around: int = 24,
          holes: int = 8) -> list[MeshPart]:
    """A tyre (revolved rounded profile, axis along y) with a dished steel rim on its outer face.

    Args:
        centre: (3,) wheel centre; ``side`` +1 for a wheel on the left (outer face towards +y), -1 right.
        radius, width: tyre outer radius and section width (m); ``rim_frac``: rim radius / tyre radius.
        holes: hand holes of the rim disc (0: a plain disc, for the inner tyre of a twin pair).
    """
    centre = np.asarray(centre, dtype=np.float64)
    out = []
    for V, F, fm, N in _wheel_local(float(radius), float(width), float(rim_frac), int(n_around), int(holes)):
        if side < 0:  # mirror y: positions, normals and the winding
            V, N, F = V * (1.0, -1.0, 1.0), N * (1.0, -1.0, 1.0), F[:, ::-1]
        out.append(MeshPart(V + centre, F, fm, N))
    return out


@lru_cache(maxsize=64)
def _wheel_local(r: float, width: float, rim_frac: float, n_around: int, holes: int) -> tuple:
    """The parts of a left wheel centred at the origin, as read-only (V, F, face materials, normals) tuples."""
    hw = width / 2
    r_rim = rim_frac * r
    rc = min(0.06 * r + 0.015, 0.3 * hw)
    a = np.linspace(0.0, np.pi / 2, 3)
    prof = np.concatenate([
        np.stack([np.linspace(r_rim, r - rc, 2, endpoint=False), np.full(2, hw)], 1),  # outer sidewall
        np.stack([r - rc + rc * np.sin(a), hw - rc + rc * np.cos(a)], 1),  # shoulder
        np.array([[r, 0.0]]),  # tread
        np.stack([r - rc + rc * np.cos(a), -(hw - rc) - rc * np.sin(a)], 1),  # inner shoulder
        np.array([[0.5 * (r - rc + r_rim), -hw]]),  # inner sidewall
        np.stack([np.full(2, r_rim), np.linspace(-hw, hw, 3, endpoint=False)[1:]], 1),  # rim seat
    ])
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False) - np.pi / 2  # includes the lowest point
    ct, st = np.cos(theta), np.sin(theta)
    X, Z = prof[None, :, 0] * ct[:, None], prof[None, :, 0] * st[:, None]
    Y = np.broadcast_to(prof[None, :, 1], X.shape)
    V = np.stack([X, Y, Z], -1).reshape(-1, 3)
    F = grid_faces(n_around + 1, len(prof), wrap_cols=True) % (n_around * len(prof))  # last row = first
    F = orient_outward(V, F)
    parts = [(V, F, np.full(len(F), TYRE, dtype=np.int64), smooth_vertex_normals(V, F))]

    if holes:
        rings = np.array([0.16, 0.3, 0.5, 0.75, 0.93, 1.0]) * r_rim
        recess = np.array([0.005, 0.03, 0.05, 0.06, 0.02, 0.0]) + 0.012
    else:  # an inner twin tyre: a plain disc
        rings, recess = np.array([1.0]) * r_rim, np.full(1, 0.03)
    for face_side, radii, rec in ((1.0, rings, recess), (-1.0, rings[-1:], np.full(1, 0.02))):
        # a disc: a centre point fanned to the first ring, then quads between rings
        Xc, Zc = radii[None, :] * ct[:, None], radii[None, :] * st[:, None]
        Yc = np.broadcast_to(face_side * (hw - rec)[None, :], Xc.shape)
        ring_V = np.stack([Xc, Yc, Zc], -1).reshape(-1, 3)
        Vc = np.concatenate([[[0.0, face_side * (hw - rec[0] + (0.01 if holes and face_side > 0 else 0.0)), 0.0]],
                             ring_V])
        m = len(radii)
        k = np.arange(n_around)
        Fc = [np.stack([np.zeros(n_around, np.int64), 1 + k * m, 1 + ((k + 1) % n_around) * m], 1)]
        if m > 1:
            Fc.append(grid_faces(n_around + 1, m, wrap_cols=False) % (n_around * m) + 1)
        Fc = np.concatenate(Fc)
        fn, _ = face_normals(Vc, Fc)
        if (fn[:, 1] * face_side).mean() < 0:
            Fc = Fc[:, ::-1].copy()
        cen = Vc[Fc].mean(axis=1)
        ang, rr = np.arctan2(cen[:, 2], cen[:, 0]), np.hypot(cen[:, 0], cen[:, 2]) / r_rim
        fm = np.full(len(Fc), RIM, dtype=np.int64)
        if holes and face_side > 0:
            fm[(rr > 0.5) & (rr < 0.75) & (np.cos(holes * ang) > 0.4)] = TRIM
            fm[rr < 0.2] = CHROME
        parts.append((Vc, Fc, fm, smooth_vertex_normals(Vc, Fc)))
    for part in parts:
        for arr in part:
            arr.flags.writeable = False
    return tuple(parts)


def axle_wheels(x: float, radius: float, width: float, y_outer: float, dual: bool, rim_frac: float = 0.58,
                gap: float = 0.03, n_around: int = 24) -> list[MeshPart]:
    """The wheels of one axle at x, outer tyre faces at y = +-``y_outer``, single or dual (twin) tyres."""
    parts = []
    for side in (1.0, -1.0):
        yc = y_outer - width / 2
        parts += wheel((x, side * yc, radius), radius, width, side, rim_frac, n_around)
        if dual:
            parts += wheel((x, side * (yc - width - gap), radius), radius, width, side, rim_frac, n_around, holes=0)
    return parts


def wheel_well(x: float, radius: float, half_y: float, z_top: float) -> MeshPart:
    """A dark box between an axle's tyres, filling the arch above them."""
    return box((x - 0.95 * radius, -half_y, 0.45 * radius), (x + 0.95 * radius, half_y, z_top), TRIM)


# ----------------------------------------------------------------------------- small parts


def mirror_pair(x: float, y_attach: float, y_out: float, z: float, height: float, drop: float = 0.0) -> list[MeshPart]:
    """Side mirrors: an arm from the body side at (x, +-y_attach, z) out to a housing whose outer face is at
    +-``y_out`` (the widest point of the vehicle), ``height`` tall; ``drop`` lowers the housing below z."""
    parts = []
    depth, wide = 0.09, min(0.22, max(0.6 * (y_out - y_attach), 0.08))
    for s in (1.0, -1.0):
        y0, y1 = sorted((s * (y_out - wide), s * y_out))
        zh0, zh1 = z - drop - height, z - drop
        parts.append(box((x - depth, y0, zh0), (x, y1, zh1), TRIM))
        parts.append(box((x - depth - 0.012, y0 + 0.015, zh0 + 0.015), (x - depth, y1 - 0.015, zh1 - 0.015),
                         CHROME))
        ya = s * (y_out - 0.5 * wide)
        parts.append(tube((x - depth / 2, s * (y_attach - 0.02), z), (x - depth / 2, ya, zh1 - 0.02), 0.018, METAL, 8))
    return parts


def light_pair(x: float, facing: float, y_centre: float, z0: float, z1: float, width: float, mat: int,
               depth: float = 0.03) -> list[MeshPart]:
    """Two lamp boxes mirrored about y = 0 on a face at x (``facing`` +1 front, -1 rear), protruding by depth."""
    xa, xb = sorted((x, x + facing * depth))
    return [box((xa, s * y_centre - width / 2, z0), (xb, s * y_centre + width / 2, z1), mat) for s in (1.0, -1.0)]


# ----------------------------------------------------------------------------- cabs


@dataclass(frozen=True)
class CabSpec:
    """A cab-over-engine lorry cab (metres, object frame: x front).

    Attributes:
        x_front: front of the bumper (the vehicle's front); ``length``: cab length back from there.
        half_w: half width of the cab shell; ``y_mirror``: outer face of the mirrors (half the box width).
        top: roof height; ``floor``: height of the cab floor (top of the wheel arch).
        x_axle, wheel_r: front axle position and its wheel radius (the shell gets an arch over it).
        rake: how far the windscreen top sits back from its base; ``sleeper``: windows only in the front part.
    """

    x_front: float
    length: float
    half_w: float
    y_mirror: float
    top: float
    floor: float
    x_axle: float
    wheel_r: float
    rake: float = 0.1
    sleeper: bool = False


def cab_over(spec: CabSpec, grille_mat: int = TRIM, bumper_mat: int = TRIM) -> list[MeshPart]:
    """The cab shell (windscreen, side windows, arch over the front wheel), bumper, grille, lamps, mirrors."""
    s = spec
    e_f, e_r = 0.10, 0.06
    cab_front = s.x_front - 0.07
    x0, x1 = cab_front - s.length + 0.07 + e_r, cab_front - e_f
    h_cab = s.top - s.floor
    belt = s.floor + float(np.clip(0.30 * h_cab + 0.05, 0.25, 0.75))
    wtop = s.top - float(np.clip(0.12 * h_cab, 0.08, 0.25))
    arches = [(s.x_axle, s.wheel_r + 0.08)]
    win_x0 = x1 - (0.55 if s.sleeper else 0.78) * (x1 - x0)
    xs = arch_stations(x0, x1, arches, cuts=(win_x0, x1 - 0.12), step=0.4)
    clearance = min(0.42 + 0.2 * s.wheel_r, s.floor - 0.05)
    zlo = arch_bottom(xs, clearance, arches, s.wheel_r)
    regions = [
        Region(GLASS, (x1 - 0.3, -s.half_w + 0.08, belt), (np.inf, s.half_w - 0.08, wtop), (1.0, 0.0, 0.0), 0.5),
        Region(GLASS, (win_x0, -np.inf, belt), (x1 - 0.1, np.inf, wtop), (0.0, 1.0, 0.0), 0.6, both_sides=True),
    ]
    rc = min(0.16, 0.15 * h_cab, 0.8 * (s.top - wtop))
    shell = loft_x(xs, zlo, s.top, s.half_w, radius=rc, mat=PAINT, regions=regions, z_cuts=(belt, wtop),
                   end_round=(e_r, e_f))
    shell = taper(shell, x0 - e_r, x1 + e_f, belt, s.top, front_setback=s.rake, tumble=0.02)
    zb0 = clearance - 0.05
    zb1 = min(zb0 + 0.45, belt - 0.1)
    parts = [shell,
             box((s.x_front - 0.3, -s.half_w, zb0), (s.x_front - 0.02, s.half_w, zb1), bumper_mat),
             box((cab_front - 0.03, -0.6 * s.half_w, zb1 + 0.04), (cab_front + 0.03, 0.6 * s.half_w,
                                                                  max(belt - 0.08, zb1 + 0.1)), grille_mat)]
    lz0, lz1 = zb0 + 0.12, min(zb0 + 0.3, zb1 - 0.05)
    parts += light_pair(s.x_front - 0.04, 1.0, s.half_w - 0.2, lz0, lz1, 0.26, HEADLIGHT, depth=0.04)
    parts += light_pair(s.x_front - 0.04, 1.0, s.half_w - 0.42, lz0, lz1, 0.1, INDICATOR, depth=0.04)
    parts += mirror_pair(cab_front - 0.08, s.half_w - 0.02, s.y_mirror, wtop - 0.02,
                         float(np.clip(0.28 * h_cab, 0.2, 0.45)), drop=0.08)
    parts.append(wheel_well(s.x_axle, s.wheel_r, s.half_w - 0.35, s.floor + 0.02))
    return parts


def shifted(part: MeshPart, offset) -> MeshPart:
    """``part`` translated by ``offset`` (3,) metres."""
    return MeshPart(part.vertices + np.asarray(offset, float), part.faces, part.face_material, part.normals)


def glass_cabin(x0: float, x1: float, y_c: float, half_w: float, z0: float, z1: float, belt: float) -> MeshPart:
    """An operator's cabin (construction machines, cranes): a rounded box from x0 to x1 centred at y_c, glazed
    all round between the height ``belt`` and just under its roof at z1."""
    top = z1 - float(np.clip(0.08 * (z1 - z0), 0.05, 0.12))
    rc = float(min(0.08, 0.8 * (z1 - top), 0.3 * (belt - z0)))
    e = min(0.05, 0.2 * (x1 - x0))
    regions = [Region(GLASS, (-np.inf, -np.inf, belt), (np.inf, np.inf, top), None)]
    cab = loft_x([x0 + e, x1 - e], z0, z1, half_w, radius=max(rc, 0.0), mat=PAINT, regions=regions,
                 z_cuts=(belt, top), end_round=(e, e), n_corner=2)
    fn, _ = face_normals(cab.vertices, cab.faces)
    fm = cab.face_material.copy()
    fm[(fm == GLASS) & (np.abs(fn[:, 2]) > 0.7)] = PAINT  # no glass on roof or floor caps
    return shifted(MeshPart(cab.vertices, cab.faces, fm, cab.normals), (0.0, y_c, 0.0))


def rear_doors(x_back: float, x_face: float, hw: float, z0: float, z1: float, rods: int = 4) -> list[MeshPart]:
    """The frame, centre seam and vertical locking rods of a box body's rear doors, on its rear face at
    ``x_face`` and reaching back to ``x_back`` (the vehicle's rear), between heights z0 and z1."""
    parts = [box((x_back, y0, z0 + 0.02), (x_face + 0.01, y1, z1 - 0.03), TRIM)
             for y0, y1 in ((-hw + 0.02, -hw + 0.09), (hw - 0.09, hw - 0.02), (-0.015, 0.015))]
    parts.append(box((x_back, -hw + 0.02, z1 - 0.1), (x_face + 0.01, hw - 0.02, z1 - 0.03), TRIM))
    for yr in np.linspace(-0.55, 0.55, rods) * hw:
        parts.append(tube((x_back + 0.02, yr, z0 + 0.1), (x_back + 0.02, yr, z1 - 0.15), 0.015, CHROME, 6))
    return parts


# ----------------------------------------------------------------------------- assembly


def finish_vehicle(parts: list[MeshPart], materials: tuple[Material, ...], target_wlh: np.ndarray, name: str,
                   category: str) -> Asset:
    """Merge ``parts`` into a validated Asset: origin at the bottom centre, box exactly ``target_wlh``.

    The parts are built to the target size; a residual mismatch of at most 1.5 % per axis (rounding of
    ends, mirror placement) is scaled away.

    Raises:
        RuntimeError: the parts miss the target by more than that (a generator bug).
    """
    V, F, fm = merge_parts(parts)
    N = np.concatenate([p.normals for p in parts])
    lo, hi = V.min(axis=0), V.max(axis=0)
    ext = hi - lo
    want = np.array([target_wlh[1], target_wlh[0], target_wlh[2]])
    scale = want / ext
    if np.any(np.abs(scale - 1.0) > 0.015):
        raise RuntimeError(f"{name}: built extents (l, w, h) {np.round(ext, 3).tolist()} miss the target "
                           f"{np.round(want, 3).tolist()}")
    V = (V - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) * scale
    N = N / scale
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    asset = Asset(name=name, vertices=V, faces=F, face_material=fm, materials=materials, vertex_normals=N,
                  uv=None, category=category)
    return validate_asset(asset)


__all__ = [
    "ACCENT", "CARGO", "CARGO_PALETTE", "CHROME", "GLASS", "HEADLIGHT", "INDICATOR", "METAL", "PAINT", "RIM",
    "TAILLIGHT", "TRIM", "TYRE", "apply_regions", "arch_bottom", "arch_stations", "axle_wheels", "beam", "box",
    "cab_over", "CabSpec", "choose_variant", "circle", "finish_vehicle", "glass_cabin",
    "hex_to_linear", "light_pair", "loft_x", "make_part", "mirror_pair", "pick_colour", "prism", "rear_doors",
    "Region", "rounded_rect_ring", "shifted", "stadium", "taper", "tube", "vehicle_materials", "wheel",
    "wheel_well",
]
