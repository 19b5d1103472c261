"""The body of a procedural car: body types (dimensions, side profile), the lofted body and its materials.

The body is a loft along x of rounded cross-sections (superellipses in y-z whose width narrows
above the belt line: the "tumblehome"), between a side-profile roof curve ``z_top(x)`` and an
underbody curve ``z_bot(x)`` that rises into wheel arches; its plan-view width rounds off at both
ends, closing the surface.  Materials are assigned per face from its position and normal
(windscreen / side windows / rear window with pillars in between, bumpers, grille, head and tail
lights); the outlines of the windows, the B pillar and the bumpers' lip (:func:`outline_levels`)
first cut the triangles they cross, so those edges are clean lines, not the loft grid's staircase; a shoulder
(character) line along both sides (:func:`shoulder_crease`) turns the shading normal within 5 mm.
Distances ``d`` run from the nose (0) to the rear (``length``); the object frame has x front.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .mesh_parts import MeshPart, cut_along_levels, grid_faces, signed_volume, weld_vertices
from .validate import face_normals, smooth_vertex_normals

# Material slots of a procedural car (indices into its material table).  The first seven are the
# original body / wheel slots; the rest are the details (:mod:`.car_details`, :mod:`.car_interior`,
# :mod:`.number_plates`): rear (privacy) glass, panel gaps, the lower (dirtier) paint, plates, the
# interior, chrome, lamp reflectors and brake discs.
PAINT, GLASS, TRIM, TYRE, RIM, HEADLIGHT, TAILLIGHT = range(7)
(GLASS_REAR, GAP, PAINT_LOWER, PLATE_FRONT, PLATE_REAR, PLATE_INK, PLATE_BAND, INTERIOR, DASH, CHROME, REFLECTOR,
 BRAKE) = range(7, 19)
N_SLOTS = 19
GAP_HALF_M = 0.006  # half width of a panel gap (a 12 mm dark line: about a pixel at 15 m)


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


def sedan_spec() -> BodySpec:
    L, H = 4.60, 1.45
    return BodySpec(
        length=L, width=1.80, height=H, wheel_radius=0.32, front_overhang=0.92, rear_overhang=1.00,
        belt_front=0.90, belt_rear=0.98, d_ws=1.36, d_roof_front=2.50, d_roof_back=3.20, d_rear=3.85,
        pillars=(2.75,),
        top=((0.0, 0.58), (0.06, 0.70), (0.30, 0.78), (1.36, 0.90), (2.50, H - 0.02), (2.75, H), (3.20, H - 0.03),
             (3.85, 1.00), (4.45, 0.98), (4.56, 0.90), (L, 0.72)),
        bottom=((0.0, 0.42), (0.12, 0.28), (0.55, 0.20), (L - 0.6, 0.21), (L - 0.12, 0.30), (L, 0.45)),
        tumblehome=0.22, plan_exponent=5.5,
    )


def hatchback_spec() -> BodySpec:
    L, H = 4.10, 1.50
    return BodySpec(
        length=L, width=1.75, height=H, wheel_radius=0.31, front_overhang=0.82, rear_overhang=0.68,
        belt_front=0.92, belt_rear=1.00, d_ws=1.18, d_roof_front=2.32, d_roof_back=3.25, d_rear=3.92,
        pillars=(2.55,),
        top=((0.0, 0.58), (0.06, 0.70), (0.28, 0.79), (1.18, 0.92), (2.32, H - 0.02), (2.62, H), (3.25, H - 0.05),
             (3.92, 1.02), (4.04, 0.95), (L, 0.78)),
        bottom=((0.0, 0.42), (0.12, 0.28), (0.50, 0.20), (L - 0.5, 0.22), (L - 0.10, 0.32), (L, 0.48)),
        tumblehome=0.20, plan_exponent=4.0,
    )


def suv_spec() -> BodySpec:
    L, H = 4.70, 1.75
    return BodySpec(
        length=L, width=1.90, height=H, wheel_radius=0.37, front_overhang=0.92, rear_overhang=0.98,
        belt_front=1.08, belt_rear=1.14, d_ws=1.30, d_roof_front=2.30, d_roof_back=4.35, d_rear=4.62,
        pillars=(2.75, 3.75),
        top=((0.0, 0.72), (0.06, 0.88), (0.30, 0.98), (1.30, 1.08), (2.30, H - 0.02), (2.75, H), (4.35, H - 0.03),
             (4.62, 1.10), (L, 0.95)),
        bottom=((0.0, 0.52), (0.15, 0.36), (0.60, 0.28), (L - 0.6, 0.30), (L - 0.12, 0.38), (L, 0.52)),
        tumblehome=0.17, plan_exponent=6.5,
    )


def van_spec() -> BodySpec:
    L, H = 5.00, 1.95
    return BodySpec(
        length=L, width=2.00, height=H, wheel_radius=0.34, front_overhang=0.95, rear_overhang=1.05,
        belt_front=1.10, belt_rear=1.12, d_ws=0.75, d_roof_front=1.85, d_roof_back=4.90, d_rear=4.96,
        pillars=(2.30, 3.60),
        top=((0.0, 0.72), (0.06, 0.88), (0.25, 0.98), (0.75, 1.10), (1.85, H - 0.03), (2.40, H), (4.85, H - 0.02),
             (4.97, H - 0.12), (L, H - 0.30)),
        bottom=((0.0, 0.48), (0.15, 0.32), (0.55, 0.24), (L - 0.55, 0.26), (L - 0.12, 0.34), (L, 0.48)),
        tumblehome=0.10, plan_exponent=7.5,
    )


# Plan exponents (issue #20): sedans 5.5, SUVs 6.5, vans 7.5 (were 4 / 5 / 6): real cars seen end-on show a broad,
# flat front and rear face with lamps out to the corners, the procedural ones a rounded "bubble"; the hatchback
# keeps 4 (its short rear's bumper lip turned too sharply at its corners).
BODY_SPECS = {"sedan": sedan_spec, "hatchback": hatchback_spec, "suv": suv_spec, "van": van_spec}
BODY_WEIGHTS = {"sedan": 0.38, "hatchback": 0.22, "suv": 0.30, "van": 0.10}


def jitter_spec(spec: BodySpec, rng: np.random.Generator) -> BodySpec:
    """Scale a spec by a few percent (length, width, height independently).

    Ranges: length and width +-4 %, height -3..+7 %: over 200 seeds the mean box then matches nuScenes'
    vehicle.car (class_sizes.json) within ~1 % (with +-4 % the height was 2.7 % low).
    """
    sl, sw, sh = rng.uniform([0.96, 0.96, 0.97], [1.04, 1.04, 1.07], size=3)

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


def axle_distances(spec: BodySpec) -> tuple[float, float]:
    return spec.front_overhang, spec.length - spec.rear_overhang


def loft_stations(spec: BodySpec) -> np.ndarray:
    """Sorted distances from the nose d (S,) for the loft, dense at the ends and over the arches,
    with stations on every window / pillar boundary so material edges are straight."""
    L = spec.length
    t = np.linspace(0.0, 1.0, 29)
    d = [L * (1 - np.cos(np.pi * t)) / 2]  # cosine spacing: dense at both ends
    d.append(np.linspace(0.0, L, 34))
    ra = spec.wheel_radius + 0.05
    for dw in axle_distances(spec):
        d.append(dw + ra * np.cos(np.linspace(np.pi, 0.0, 13)))
    edges = [spec.d_ws, spec.d_roof_front, spec.d_roof_back, spec.d_rear, *side_window_edges(spec)]
    d.append(np.array(edges))
    d = np.unique(np.clip(np.concatenate(d), 0.0, L))
    keep = np.concatenate([[True], np.diff(d) > 0.02])
    d = d[keep]
    d[-1] = L
    # Panel gaps: a pair of stations 2 GAP_HALF_M apart around each cut line (nothing else close by,
    # except the window edges, which stay).
    gaps = np.array([g for g, _ in panel_gaps(spec)])
    near = np.min(np.abs(d[:, None] - gaps[None, :]), axis=1) < 0.025
    protected = np.min(np.abs(d[:, None] - np.array(edges)[None, :]), axis=1) < 1e-9
    d = d[~near | protected | (d == 0.0) | (d == L)]
    d = np.unique(np.concatenate([d, gaps - GAP_HALF_M, gaps + GAP_HALF_M]))
    return d


def panel_gaps(spec: BodySpec) -> list[tuple[float, str]]:
    """Cut lines across the body (distance from the nose d, where): ``"side"`` (door shut lines, below
    the belt line) or ``"top"`` (bonnet front and rear edge, boot lid front edge)."""
    d_front, d_rear_axle = axle_distances(spec)
    ra = spec.wheel_radius + 0.05
    door_front = max(spec.d_ws + 0.05, d_front + ra + 0.06)
    cuts = [(door_front, "side"), (spec.pillars[0] - 0.03, "side")]
    rear_door_end = spec.pillars[1] - 0.03 if len(spec.pillars) > 1 else min(spec.d_roof_back, d_rear_axle - 0.3 * ra)
    if rear_door_end > spec.pillars[0] + 0.5:
        cuts.append((rear_door_end, "side"))
    top = [0.12 * spec.front_overhang + 0.08, spec.d_ws - 0.07]
    if spec.length - spec.d_rear > 0.35:  # a boot lid (sedans)
        top.append(spec.d_rear + 0.05)
    return cuts + [(t, "top") for t in top]


def side_window_edges(spec: BodySpec) -> list[float]:
    """d of the side-window edges: front (A pillar foot), pillar sides, rear."""
    edges = [spec.d_ws + 0.10, spec.d_rear - 0.10]
    for dp in spec.pillars:
        edges += [dp - 0.06, dp + 0.06]
    return edges


def side_window_limits(spec: BodySpec, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d of the side glass's front and rear edges at height z: from :func:`side_window_edges` at the belt
    line, leaning back / forward with the windscreen and rear window towards the roof."""
    e = side_window_edges(spec)
    belt = 0.5 * (spec.belt_front + spec.belt_rear)
    f = np.clip((z - belt) / (spec.height - _RAIL - belt), 0.0, 1.0)
    return (e[0] + 0.8 * f * (spec.d_roof_front - spec.d_ws),
            e[1] - 0.5 * f * (spec.d_rear - spec.d_roof_back))


class MonotoneCubic:
    """Piecewise cubic Hermite interpolation that keeps the data's monotonicity (PCHIP, Fritsch-Carlson with the
    weighted harmonic mean of Fritsch-Butland at inner knots and the three-point end rule): what
    ``scipy.interpolate.PchipInterpolator(x, y)`` computes (same slopes, same polynomials, extrapolated with
    the end pieces), in numpy only, so importing the car body does not import ``scipy.interpolate`` (~0.25 s of
    the CLI's start-up, issue #19).

    Args:
        x: (K,) strictly increasing knots, K >= 2. y: (K,) values.
    """

    def __init__(self, x, y) -> None:
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        if x.ndim != 1 or x.shape != y.shape or len(x) < 2 or not np.all(np.diff(x) > 0):
            raise ValueError(f"MonotoneCubic: x must be (K,) strictly increasing with K >= 2 and y (K,), got "
                             f"shapes {x.shape} and {y.shape}")
        h = np.diff(x)
        m = np.diff(y) / h
        d = np.zeros_like(y)
        if len(x) == 2:
            d[:] = m[0]
        else:
            w1, w2 = 2.0 * h[1:] + h[:-1], h[1:] + 2.0 * h[:-1]
            same = (np.sign(m[:-1]) * np.sign(m[1:])) > 0
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = (w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)
                d[1:-1] = np.where(same, 1.0 / inv, 0.0)
            d[0] = self._end_slope(h[0], h[1], m[0], m[1])
            d[-1] = self._end_slope(h[-1], h[-2], m[-1], m[-2])
        self.x, self.y, self.d, self.h, self.m = x, y, d, h, m

    @staticmethod
    def _end_slope(h0: float, h1: float, m0: float, m1: float) -> float:
        """A non-centred three-point slope at an end, kept shape-preserving (SciPy's ``_edge_case``)."""
        d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        if np.sign(d) != np.sign(m0):
            return 0.0
        if np.sign(m0) != np.sign(m1) and abs(d) > abs(3.0 * m0):
            return 3.0 * m0
        return float(d)

    def __call__(self, t) -> np.ndarray:
        """Values at ``t`` (any shape); outside the knots the end pieces are extrapolated."""
        t = np.asarray(t, np.float64)
        k = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        h, m = self.h[k], self.m[k]
        d0, d1 = self.d[k], self.d[k + 1]
        s = t - self.x[k]
        # The Hermite piece's power-basis coefficients and their sum, in SciPy's order of operations
        # (CubicHermiteSpline's coefficients, PPoly's term-by-term sum): the same floats, not just close ones.
        c = (d0 + d1 - 2.0 * m) / h
        c3, c2 = c / h, (m - d0) / h - c
        return ((self.y[k] + d0 * s) + c2 * (s * s)) + c3 * (s * s * s)


@functools.lru_cache(maxsize=64)
def _profile_curves(spec: BodySpec) -> tuple[MonotoneCubic, MonotoneCubic]:
    """The roof line and underbody curves z(d) of a spec (cached: the details query them often)."""
    return MonotoneCubic(*np.array(spec.top).T), MonotoneCubic(*np.array(spec.bottom).T)


def body_profiles(spec: BodySpec, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Roof line z_top, underbody z_bot (with arches), plan half width and belt height at stations d."""
    top_curve, bot_curve = _profile_curves(spec)
    top, bot = top_curve(d), bot_curve(d)
    r = spec.wheel_radius
    ra = r + 0.05
    for dw in axle_distances(spec):
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
LIP_TOP = 0.75  # the bumpers' black lower lip reaches at most this fraction of the bumper line's height
REAR_TURN_DEG = 45.0  # the rear window's side edges: where the plan outline has turned this far from straight back
_NORMAL_M = 0.1  # metres per unit of normal change in the outline functions
A_PILLAR_M = 0.10  # least length of the A pillar between the windscreen's slope and the side glass (m)
C_PILLAR_M = 0.15  # least length of the C (D) pillar between the side glass and the rear window's slope (m)


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


def body_part(spec: BodySpec) -> MeshPart:
    d = loft_stations(spec)
    top, bot, half_w, belt = body_profiles(spec, d)
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
    taper = tumblehome_taper(spec, z, belt[:, None])
    y = half_w[:, None] * ys * taper
    x = spec.length / 2 - d
    V = np.stack([np.broadcast_to(x[:, None], y.shape), y, z], axis=-1).reshape(-1, 3)
    n_sec = phi.shape[1]
    F = grid_faces(len(d), n_sec, wrap_cols=True)
    n_quads = len(F) // 2
    quads = _quad_frame(spec, V, F[:n_quads], F[n_quads:], seg, pos, n_sec)
    quads = {k: np.concatenate([v, v]) for k, v in quads.items()}  # both triangles of a quad
    V, F, keep = weld_vertices(V, F)
    quads = {k: v[keep] for k, v in quads.items()}
    if signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    # Window, pillar and lip outlines cut the triangles they cross (their edges follow the outlines, not the
    # loft's grid: per-face materials had left sawtooth edges where an outline ran diagonally across it).
    N = smooth_vertex_normals(V, F)
    V, F, N, levels, parent = cut_along_levels(V, F, N, outline_levels(spec, V, N), zero_tol=1e-4)
    lv = levels[F]  # (F, 3 vertices, regions)
    inside = lv.mean(axis=1) < 0.0
    # A face with all three vertices on an outline (e.g. in a window's corner, two on the pillar line and one on the
    # belt line) has no side by its vertices: the function at its centre decides.
    tie = np.flatnonzero((np.abs(lv).max(axis=1) < 1e-9).any(axis=1))
    if len(tie):
        n_c = N[F[tie]].sum(axis=1)
        at_centre = outline_levels(spec, V[F[tie]].mean(axis=1), n_c / np.linalg.norm(n_c, axis=1, keepdims=True))
        on = np.abs(lv[tie]).max(axis=1) < 1e-9
        inside[tie] = np.where(on, at_centre < 0.0, inside[tie])
    fm = body_materials(spec, {k: v[parent] for k, v in quads.items()}, inside)
    return shoulder_crease(spec, MeshPart(V, F, fm, N))


SHOULDER_BELOW_BELT_M = 0.12  # the shoulder (character) line's height under the belt line
SHOULDER_STRIP_M = 0.005  # the crease's width: the normal turns across it (sub-pixel beyond ~5 m)
# The surfaces either side of the crease dip inwards (depth, reach from the line), tangent to the loft again at
# the reach: the kink at the line is 27/4 depth / reach per side, ~19 deg above and ~8 deg below.
SHOULDER_UP_M = (0.006, 0.12)
SHOULDER_DOWN_M = (0.005, 0.25)


def shoulder_height(spec: BodySpec, d: np.ndarray) -> np.ndarray:
    """Height z (m) of the shoulder line at distances from the nose ``d``: :data:`SHOULDER_BELOW_BELT_M` under the
    belt line."""
    return body_profiles(spec, np.asarray(d, np.float64))[3] - SHOULDER_BELOW_BELT_M


def _dip(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The crease's dip profile and its slope at u >= 0: 1 at u = 1/3, 0 with slope 27/4 at u = 0, 0 with zero slope
    at u >= 1."""
    u = np.clip(u, 0.0, 1.0)
    return 6.75 * u * (1.0 - u) ** 2, np.where(u < 1.0, 6.75 * (1.0 - u) * (1.0 - 3.0 * u), 0.0)


def shoulder_crease(spec: BodySpec, part: MeshPart) -> MeshPart:
    """The body with a shoulder (character) line along both sides: the loft is cut along the line and along a
    parallel line :data:`SHOULDER_STRIP_M` above it, and the side surfaces above and below dip inwards (at most a
    few mm: the box does not grow).  Normals are the moved surface's own (the loft's plus the dip's slope), so
    the two lines carry the kink's two sides and the shading turns across the strip (a crisp line in the sky's
    reflection) instead of over a loft row (the chords of 4-8 cm rows would have spread it).  Only side-facing
    surface (|n_y| > 0.5, fading in to 0.8) is moved; the mesh stays closed."""
    V, F, N = part.vertices, part.faces, part.normals
    d = spec.length / 2 - V[:, 0]
    z0 = shoulder_height(spec, d)
    levels = np.stack([V[:, 2] - z0, V[:, 2] - z0 - SHOULDER_STRIP_M], axis=1)
    V, F, N, lv, parent = cut_along_levels(V, F, N, levels, snap=0.01, zero_tol=1e-6)  # the strip is ~5 % of a row
    d = spec.length / 2 - V[:, 0]
    z0 = shoulder_height(spec, d)
    side = np.clip((np.abs(N[:, 1]) - 0.5) / 0.3, 0.0, 1.0)
    (depth_up, reach_up), (depth_dn, reach_dn) = SHOULDER_UP_M, SHOULDER_DOWN_M
    g_up, s_up = _dip((V[:, 2] - z0 - SHOULDER_STRIP_M) / reach_up)
    g_dn, s_dn = _dip((z0 - V[:, 2]) / reach_dn)
    above, below = lv[:, 1] >= 0.0, lv[:, 0] <= 0.0  # the upper line belongs to the upper side, the lower to the lower
    inward = side * np.where(above, depth_up * g_up, 0.0) + side * np.where(below, depth_dn * g_dn, 0.0)
    # d(inward)/dz: the outward normal of y = f(x, z) - inward(z) (per unit |n_y|) gains + d(inward)/dz in z.
    slope = side * (np.where(above, depth_up / reach_up * s_up, 0.0) - np.where(below, depth_dn / reach_dn * s_dn, 0.0))
    V = V.copy()
    V[:, 1] -= np.sign(V[:, 1]) * inward
    n = N / np.maximum(np.abs(N[:, 1:2]), 1e-6) + np.outer(slope, [0.0, 0.0, 1.0])
    N = np.where((side > 0)[:, None], n / np.linalg.norm(n, axis=1, keepdims=True), N)
    return MeshPart(V, F, part.face_material[parent], N)


# Columns of :func:`outline_levels`.
SIDE_GLASS, B_PILLAR, WINDSCREEN, REAR_WINDOW, UNDERSIDE, BUMPER_LIP = range(6)


def outline_levels(spec: BodySpec, V: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Per body vertex (V, 6), a function that is < 0 inside the region and 0 on its outline: side glass, B
    pillar, windscreen, rear window, underside (faces looking down) and the bumpers' lower lip (columns
    ``SIDE_GLASS`` ... ``BUMPER_LIP``).  Mostly distances (m) to straight or leaning lines on the body, with
    the smooth normal ``N`` (V, 3) for where a region turns round the body (glass faces sideways / forwards /
    backwards); a region is the intersection of its terms (their maximum)."""
    x, y, z = np.asarray(V, np.float64).T
    nx, ny, nz = np.asarray(N, np.float64).T
    d = spec.length / 2 - x
    ay = np.abs(y)
    top, bot, _, belt = body_profiles(spec, d)
    taper = tumblehome_taper(spec, z, belt)
    full_hw = 0.5 * spec.width * taper
    # Normal terms are scaled to about metres (the normal turns by ~1 over the body's tightest corners' 10 cm), so
    # where two terms meet at a region's corner the cut (linear along each edge) stays close to both.
    # The windscreen narrows towards the roof (8 cm each side more at the top than at the belt line), keeping an A
    # pillar between it and the side glass where the roof's sides curve in.
    up = np.clip((z - belt) / (spec.height - _RAIL - belt), 0.0, 1.0)
    windscreen = np.max([_NORMAL_M * (0.3 - nx), ay - (full_hw - 0.13 - 0.08 * up), spec.d_ws - 0.02 - d,
                         d - spec.d_roof_front - 0.02, belt - z], axis=0)
    # The rear window: inside D / C pillars, and 5 cm narrower than the rear end's flat part (in plan view, where
    # the outline's normal is within REAR_TURN_DEG of straight back; times the tumblehome), so it does not wrap
    # round the rear corners.  Both bounds are linear in y: the rear face of a van or an SUV is one fan of
    # triangles from the end line, and a margin from the section's own half width (0 at the very end, with an
    # infinite slope) or from the normal's turn left holes or wavy edges in the window once sampled at vertices.
    rear = np.max([_NORMAL_M * (nx + 0.3), ay - (full_hw - 0.16), ay - (plan_corner_y(spec) * taper - 0.05),
                   spec.d_roof_back - 0.02 - d, belt + 0.04 - z], axis=0)
    e0, e1 = side_window_limits(spec, z)
    band = np.maximum(belt - z, z - (top - _RAIL))  # between the belt line and the roof rail
    sideways = _NORMAL_M * (0.3 - np.abs(ny))
    pillars = np.max([0.06 - np.abs(d - dp) for dp in spec.pillars], axis=0)
    # The A and C (D) pillars: the side glass starts A_PILLAR_M behind the windscreen's slope and ends C_PILLAR_M
    # before the rear window's slope come down to its height (without them the glass areas met at their corners).
    roof = _profile_curves(spec)[0]
    a_pillar = z + _RAIL - roof(np.clip(d - A_PILLAR_M, 0.0, spec.length))
    c_pillar = z + _RAIL - roof(np.clip(d + C_PILLAR_M, 0.0, spec.length))
    side = np.max([e0 - d, d - e1, band, sideways, pillars, a_pillar, c_pillar], axis=0)
    b_pillar = np.max([np.abs(d - spec.pillars[0]) - 0.06, band, sideways], axis=0)
    under = nz + 0.8
    # The lip: the bumpers' underbody rows (below the section's -45 deg row: their faces tilt down), not over the
    # arches, and at most LIP_TOP x the bumper line high: where the body closes at its ends the rows rise (by
    # ~15 cm over the last 30 cm), and following them (or a normal threshold) left a spike under the plates.
    d_front, d_rear_axle = axle_distances(spec)
    ra = spec.wheel_radius + 0.05
    zc, hz = (top + bot) / 2, (top - bot) / 2
    z_q = zc - hz * np.sin(np.pi / 4) ** (2.0 / _N_LOW)
    ends = np.minimum(d - (d_front - ra - 0.02), d_rear_axle + ra + 0.02 - d)
    lip = np.maximum(ends, z - np.minimum(z_q, LIP_TOP * _bumper_line(spec)))
    return np.stack([side, b_pillar, windscreen, rear, under, lip], axis=1)


def tumblehome_taper(spec: BodySpec, z: np.ndarray, belt: np.ndarray) -> np.ndarray:
    """Tumblehome: width factor (<= 1) of the section at height z (the cabin leans inwards)."""
    cabin_h = spec.height - 0.5 * (spec.belt_front + spec.belt_rear)
    return 1.0 - spec.tumblehome * np.clip((z - belt) / cabin_h, 0.0, 1.0) ** 1.1


def plan_corner_y(spec: BodySpec) -> float:
    """|y| (m) where the plan view's superellipse outline (half axes L / 2, W / 2) has turned ``REAR_TURN_DEG``
    from facing straight back: the end of the rear's flat part."""
    a, b, p = spec.length / 2, spec.width / 2, spec.plan_exponent
    r = (np.tan(np.radians(REAR_TURN_DEG)) * b / a) ** (1.0 / (p - 1.0))  # (y / b) / (x / a) there
    return float(b * r * (1.0 + r**p) ** (-1.0 / p))


def _quad_frame(spec: BodySpec, V: np.ndarray, tri_a: np.ndarray, tri_b: np.ndarray, seg: np.ndarray,
                pos: np.ndarray, n_sec: int) -> dict[str, np.ndarray]:
    """Per loft quad (triangles ``tri_a``, ``tri_b``): outward unit normal ``n`` (Q, 3), centroid ``d``, ``y``,
    ``z`` (Q,), and ``kind`` / ``kind_hi`` / ``row`` (Q,): the lower and upper row segment (0 underbody, 1 lower
    side, 2 up to the belt line, 3 side glass, 4 roof) and the lower row's index in its segment, from ``seg`` /
    ``pos`` (per section vertex)."""
    na, aa = face_normals(V, tri_a)
    nb, ab = face_normals(V, tri_b)
    n = na * aa[:, None] + nb * ab[:, None]
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    cen = (V[tri_a].sum(axis=1) + V[tri_b].sum(axis=1)) / 6.0
    x, y, z = cen.T
    # Outward normal: the loft winding may be inverted; fix the sign by the section centre.
    outward = np.sign(np.einsum("ij,ij->i", n[:, 1:], np.stack([y, z - 0.7], 1)) + 1e-12)
    c0 = tri_a[:, 0] % n_sec
    c1 = (c0 + 1) % n_sec
    # The quad's lower row (its two columns are mirror-symmetric on the left / right halves).
    lower_first = (seg[c0] < seg[c1]) | ((seg[c0] == seg[c1]) & (pos[c0] <= pos[c1]))
    return {"n": n * outward[:, None], "d": spec.length / 2 - x, "y": y, "z": z,
            "kind": np.where(lower_first, seg[c0], seg[c1]), "kind_hi": np.maximum(seg[c0], seg[c1]),
            "row": np.where(lower_first, pos[c0], pos[c1])}


def body_materials(spec: BodySpec, quad: dict[str, np.ndarray], inside: np.ndarray) -> np.ndarray:
    """Material per body face from its loft quad's frame ``quad`` (:func:`_quad_frame`, one row per face) and
    the regions it lies in, ``inside`` (F, 6) bool (columns of :func:`outline_levels`)."""
    n, d, y, z, kind, row = (quad[k] for k in ("n", "d", "y", "z", "kind", "row"))
    _, _, _, belt = body_profiles(spec, d)
    ay = np.abs(y)
    mat = np.full(len(d), PAINT, dtype=np.int64)

    # Greenhouse: side glass between the window edges (leaning with the windscreen and rear window: A and C
    # pillars) and the B (C) pillars; windscreen / rear window facing forwards / backwards above the belt.
    side = inside[:, SIDE_GLASS]
    mat[side | inside[:, WINDSCREEN]] = GLASS
    # Behind the B pillar (rear doors, rear quarter) and the rear window: the (often tinted) rear glass.
    mat[(side & (d > spec.pillars[0])) | inside[:, REAR_WINDOW]] = GLASS_REAR
    # The B pillar between the side windows: black.
    mat[inside[:, B_PILLAR]] = TRIM

    # Panel gaps: thin dark strips at the cut lines (door shut lines on the sides below the belt line,
    # bonnet and boot edges on top).
    for dg, where in panel_gaps(spec):
        strip = np.abs(d - dg) < GAP_HALF_M + 1e-6
        if where == "side":
            strip &= (kind >= 1) & (kind <= 2) & (np.abs(n[:, 1]) > 0.5) & (z < belt - 0.01)
        else:
            strip &= (n[:, 2] > 0.3) & (ay < 0.46 * spec.width) & (kind >= 2)
        mat[strip & (mat == PAINT)] = GAP

    # Trim: the underbody (faces looking down, and inner arches), the bumpers' lower lip (the underbody rows'
    # faces that tilt down: a black valance), grille.  The bumpers and sills above are painted: black trim up
    # to the bumper line and along the whole sill made ~half of the lowest 30 % of a car's image black (L* ~18
    # vs ~32 for the real cars of scene-0916, whose bumpers and sills are mostly body-coloured).
    under = inside[:, UNDERSIDE]  # the sill's rounded lower edge (visible from a camera's height) is painted
    front = (d < 0.45) & (n[:, 0] > 0.25)
    grille = front & (kind == 2) & (row <= 1) & (ay < 0.22 * spec.width)
    mat[under | inside[:, BUMPER_LIP] | grille] = TRIM

    # Lights: head lights in the lowest rows above the bumper line at the front corners,
    # tail lights just under the belt line at the rear corners.
    head = front & (kind == 2) & (row <= 1) & (ay > 0.25 * spec.width) & (ay < 0.47 * spec.width)
    # Tail lights: a cluster on the rear face just under the belt line.  Only faces that look backwards
    # (not the rounded rear quarters: they made red streaks along the sides) in a band of fixed height.
    belt_r = spec.belt_rear
    tail = ((d > spec.length - 0.35) & (n[:, 0] < -0.3) & (np.abs(n[:, 1]) < 0.7) & (kind >= 2)
            & (z > belt_r - 0.26) & (z < belt_r - 0.02) & (ay > 0.25 * spec.width))
    mat[head & ~under] = HEADLIGHT
    mat[tail & ~under] = TAILLIGHT
    # Lower body paint (sills, lower doors and wings): the slightly dirtier, rougher paint.
    mat[(mat == PAINT) & (kind <= 1)] = PAINT_LOWER
    return mat


def section_half_width(spec: BodySpec, d: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Half width (m) of the body's outer surface at distance from the nose ``d`` and height ``z``
    (same shapes, broadcast); 0 above the roof or below the underbody."""
    d, z = np.broadcast_arrays(np.asarray(d, dtype=np.float64), np.asarray(z, dtype=np.float64))
    top, bot, half_w, belt = body_profiles(spec, d.ravel())
    zc, hz = (top + bot) / 2, (top - bot) / 2
    f = (z.ravel() - zc) / hz
    n = np.where(f > 0, _N_UP, _N_LOW)
    ys = np.where(np.abs(f) < 1.0, np.clip(1.0 - np.abs(np.clip(f, -1, 1)) ** n, 0.0, 1.0) ** (1.0 / n), 0.0)
    return (half_w * ys * tumblehome_taper(spec, z.ravel(), belt)).reshape(d.shape)


__all__ = [
    "BODY_SPECS", "BODY_WEIGHTS", "BRAKE", "BUMPER_LIP", "B_PILLAR", "BodySpec", "CHROME", "DASH", "GAP", "GAP_HALF_M",
    "GLASS", "GLASS_REAR", "HEADLIGHT", "INTERIOR", "MonotoneCubic", "N_SLOTS", "PAINT", "PAINT_LOWER", "PLATE_BAND",
    "PLATE_FRONT",
    "PLATE_INK", "PLATE_REAR", "REAR_WINDOW", "REFLECTOR", "RIM", "SIDE_GLASS", "TAILLIGHT", "TRIM", "TYRE",
    "UNDERSIDE", "WINDSCREEN", "axle_distances", "body_materials", "body_part", "body_profiles", "hatchback_spec",
    "jitter_spec", "loft_stations", "outline_levels", "panel_gaps", "plan_corner_y", "section_half_width",
    "sedan_spec", "shoulder_crease", "shoulder_height", "side_window_edges", "side_window_limits", "suv_spec",
    "tumblehome_taper", "van_spec",
]
