"""The body of a procedural car: body types (dimensions, side profile), the lofted body and its materials.

The body is a loft along x of rounded cross-sections (superellipses in y-z whose width narrows
above the belt line: the "tumblehome"), between a side-profile roof curve ``z_top(x)`` and an
underbody curve ``z_bot(x)`` that rises into wheel arches; its plan-view width rounds off at both
ends, closing the surface.  Materials are assigned per face from its position and normal
(windscreen / side windows / rear window with pillars in between, bumpers, grille, head and tail
lights).  Distances ``d`` run from the nose (0) to the rear (``length``); the object frame has x front.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from .mesh_parts import MeshPart, crease_normals, grid_faces, signed_volume, weld_vertices
from .validate import face_normals

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
    plan_exponent: float  # superellipse exponent of the plan view's rounded ends (larger = squarer corners)
    nose_m: float = 0.55  # length over which the plan view rounds off at the front ...
    tail_m: float = 0.45  # ... and at the rear (the sides between are straight)


def sedan_spec() -> BodySpec:
    L, H = 4.60, 1.45
    return BodySpec(
        length=L, width=1.80, height=H, wheel_radius=0.32, front_overhang=0.92, rear_overhang=1.00,
        belt_front=0.90, belt_rear=0.98, d_ws=1.45, d_roof_front=2.35, d_roof_back=3.05, d_rear=3.95,
        pillars=(2.75,),
        top=((0.0, 0.66), (0.04, 0.74), (0.25, 0.80), (1.45, 0.90), (2.35, H - 0.02), (2.65, H), (3.05, H - 0.03),
             (3.95, 1.00), (4.45, 0.98), (4.57, 0.93), (L, 0.86)),
        bottom=((0.0, 0.36), (0.10, 0.27), (0.55, 0.20), (L - 0.6, 0.21), (L - 0.12, 0.30), (L, 0.40)),
        tumblehome=0.28, plan_exponent=2.6, nose_m=0.80, tail_m=0.60,
    )


def hatchback_spec() -> BodySpec:
    L, H = 4.10, 1.50
    return BodySpec(
        length=L, width=1.75, height=H, wheel_radius=0.31, front_overhang=0.82, rear_overhang=0.68,
        belt_front=0.92, belt_rear=1.00, d_ws=1.35, d_roof_front=2.00, d_roof_back=3.10, d_rear=3.92,
        pillars=(2.55,),
        top=((0.0, 0.66), (0.04, 0.74), (0.25, 0.80), (1.35, 0.92), (2.00, H - 0.02), (2.50, H), (3.10, H - 0.04),
             (3.92, 1.02), (4.04, 0.97), (L, 0.88)),
        bottom=((0.0, 0.36), (0.10, 0.27), (0.50, 0.20), (L - 0.5, 0.22), (L - 0.10, 0.32), (L, 0.42)),
        tumblehome=0.26, plan_exponent=2.6, nose_m=0.75, tail_m=0.45,
    )


def suv_spec() -> BodySpec:
    L, H = 4.70, 1.75
    return BodySpec(
        length=L, width=1.90, height=H, wheel_radius=0.37, front_overhang=0.92, rear_overhang=0.98,
        belt_front=1.08, belt_rear=1.14, d_ws=1.40, d_roof_front=2.10, d_roof_back=4.25, d_rear=4.62,
        pillars=(2.75, 3.75),
        top=((0.0, 0.80), (0.05, 0.90), (0.30, 0.98), (1.40, 1.08), (2.10, H - 0.02), (2.60, H), (4.25, H - 0.03),
             (4.62, 1.10), (L, 1.02)),
        bottom=((0.0, 0.52), (0.15, 0.36), (0.60, 0.28), (L - 0.6, 0.30), (L - 0.12, 0.38), (L, 0.52)),
        tumblehome=0.22, plan_exponent=2.8, nose_m=0.75, tail_m=0.45,
    )


def van_spec() -> BodySpec:
    L, H = 5.00, 1.95
    return BodySpec(
        length=L, width=2.00, height=H, wheel_radius=0.34, front_overhang=0.95, rear_overhang=1.05,
        belt_front=1.10, belt_rear=1.12, d_ws=0.85, d_roof_front=1.70, d_roof_back=4.90, d_rear=4.96,
        pillars=(2.30, 3.60),
        top=((0.0, 0.72), (0.06, 0.88), (0.25, 0.98), (0.85, 1.10), (1.70, H - 0.03), (2.30, H), (4.85, H - 0.02),
             (4.97, H - 0.12), (L, H - 0.30)),
        bottom=((0.0, 0.48), (0.15, 0.32), (0.55, 0.24), (L - 0.55, 0.26), (L - 0.12, 0.34), (L, 0.48)),
        tumblehome=0.14, plan_exponent=3.0, nose_m=0.65, tail_m=0.35,
    )


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
        tumblehome=spec.tumblehome, plan_exponent=spec.plan_exponent, nose_m=spec.nose_m * sl, tail_m=spec.tail_m * sl,
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
    bend = 1.0 - np.cos(np.linspace(0.0, np.pi / 2, 7))  # the plan view's rounded ends
    d += [spec.nose_m * bend, L - spec.tail_m * bend]
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


@functools.lru_cache(maxsize=64)
def _profile_curves(spec: BodySpec) -> tuple[PchipInterpolator, PchipInterpolator]:
    """The roof line and underbody curves z(d) of a spec (cached: the details query them often)."""
    return PchipInterpolator(*np.array(spec.top).T), PchipInterpolator(*np.array(spec.bottom).T)


def side_window_limits(spec: BodySpec, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d of the side glass's front and rear edges at height z: from :func:`side_window_edges` at the belt
    line, leaning back / forward with the windscreen and rear window towards the roof."""
    e = side_window_edges(spec)
    belt = 0.5 * (spec.belt_front + spec.belt_rear)
    f = np.clip((z - belt) / (spec.height - _RAIL - belt), 0.0, 1.0)
    return (e[0] + 0.8 * f * (spec.d_roof_front - spec.d_ws),
            e[1] - 0.5 * f * (spec.d_rear - spec.d_roof_back))


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
    # Plan view: straight sides, ends rounded as superellipse quadrants nose_m / tail_m long.
    xi = np.clip(np.maximum((spec.nose_m - d) / spec.nose_m, (d - spec.length + spec.tail_m) / spec.tail_m), 0.0, 1.0)
    p = spec.plan_exponent
    half_w = 0.5 * spec.width * (1.0 - xi**p) ** (1.0 / p)
    belt = np.interp(d, [spec.d_ws, spec.d_rear], [spec.belt_front, spec.belt_rear])
    return top, bot, half_w, belt


# Rows per half section, bottom to top: underbody, lower side up to the bumper line, up to the belt
# line, side glass, roof (or windscreen / bonnet).  Row edges lie on those lines at every station, so
# material boundaries along them are straight, not staircased.
_SEG_ROWS = (3, 3, 6, 6, 6)
_RAIL = 0.07  # roof rail height above the side glass (m)
_ROOF_F = (0.78, 0.56, 0.34, 0.12)  # roof rows: fractions of the roof edge's half width
CREASE_DEG = 35.0  # faces meeting at more than this angle get separate (hard) vertex normals


def _bumper_line(spec: BodySpec) -> float:
    return 0.47 * spec.belt_front


def cabin_weight(top: np.ndarray, belt: np.ndarray) -> np.ndarray:
    """0 where the section has no cabin (bonnet, boot deck), 1 under the full greenhouse, per station."""
    return np.clip((top - belt - 0.05) / 0.15, 0.0, 1.0)


def section_rows(spec: BodySpec, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half section points (|y|, z), each (S, 22), bottom centre -> roof edge (the roof centre excluded).

    A polygon with planes and crisp creases, not a blob: flat underbody; rounded sill whose top (row 4)
    is a crease; a near-vertical flat side up to the shoulder (character) line (row 9); the shoulder
    rounds in to the belt line (row 11); the side glass stands 6.5 cm inboard (the belt ledge, rows
    11-12), flat and leaning in by the tumblehome up to the window frame (rows 15-16); a narrow rail to
    the roof edge (row 17) and a gently crowned roof.  Where there is no cabin (bonnet, boot deck)
    the glass rows collapse onto the ledge and the roof rows become the (flat, crowned) lid.
    Offsets shrink with the plan width near the ends, so sections there stay valid.
    """
    top, bot, hw, belt = body_profiles(spec, d)
    be = np.minimum(belt, top - 0.015)
    w = cabin_weight(top, belt)
    zb = _bumper_line(spec)

    def o(m):  # an inward offset (m), at most 30 % of the half width
        return np.minimum(m, 0.3 * hw)

    zsh = be - 0.11
    z = [bot, bot, bot, bot + 0.03, bot + 0.08]
    z.append(0.5 * (z[-1] + zb))
    z += [np.full_like(bot, zb), zb + 0.4 * (zsh - zb), zb + 0.75 * (zsh - zb), zsh, be - 0.04, be]
    zr = be + 0.006 + w * (top - _RAIL - be - 0.006)
    t_glass = np.linspace(0.0, 1.0, _SEG_ROWS[3])
    z += [be + 0.006 + t * (zr - be - 0.006) for t in t_glass]
    crown = 0.045 * w + 0.02 * (1.0 - w)
    z += [zr + 0.02 * w, top - np.maximum(0.012 * w, 0.8 * crown)]
    z += [top - crown * f**2 for f in _ROOF_F]
    gb = hw - o(0.085)
    gt = gb - w * spec.tumblehome * 0.85 * hw
    edge = np.maximum(gt - 0.035 * w - o(0.04) * (1.0 - w), 0.0)
    y = [np.zeros_like(hw), 0.55 * hw, hw - o(0.14), hw - o(0.075), hw - o(0.04), hw - o(0.02), hw - o(0.01),
         hw - o(0.003), hw, hw - o(0.004), hw - o(0.025), hw - o(0.06)]
    y += [gb + t * (gt - gb) for t in t_glass]
    y += [gt - 0.008 * w, edge]
    y += [f * edge for f in _ROOF_F]
    Z = np.clip(np.stack(z, axis=1), bot[:, None], top[:, None])
    Z = np.maximum.accumulate(Z, axis=1)  # rows never go down (squeezed sections: arches, nose, tail)
    Y = np.clip(np.stack(y, axis=1), 0.0, hw[:, None])
    return Y, Z


def body_part(spec: BodySpec) -> MeshPart:
    d = loft_stations(spec)
    top = body_profiles(spec, d)[0]
    Yh, Zh = section_rows(spec, d)  # bottom centre -> roof edge, |y|
    n_half = Yh.shape[1]
    seg = np.concatenate([np.full(n, k) for k, n in enumerate(_SEG_ROWS)])
    pos = np.concatenate([np.arange(n) for n in _SEG_ROWS])
    # Full loop: bottom centre -> right side (y < 0) -> top centre -> left side (y > 0) -> back.
    y = np.concatenate([-Yh, np.zeros((len(d), 1)), Yh[:, ::-1][:, :-1]], axis=1)
    z = np.concatenate([Zh, top[:, None], Zh[:, ::-1][:, :-1]], axis=1)
    seg = np.concatenate([seg, [len(_SEG_ROWS) - 1], seg[::-1][:-1]])
    pos = np.concatenate([pos, [_SEG_ROWS[-1]], pos[::-1][:-1]])
    assert len(seg) == 2 * n_half
    x = spec.length / 2 - d
    V = np.stack([np.broadcast_to(x[:, None], y.shape), y, z], axis=-1).reshape(-1, 3)
    n_sec = y.shape[1]
    F = grid_faces(len(d), n_sec, wrap_cols=True)
    n_quads = len(F) // 2
    quad_mat = body_materials(spec, V, F[:n_quads], F[n_quads:], seg, pos, n_sec)
    fm = np.concatenate([quad_mat, quad_mat])
    V, F, keep = weld_vertices(V, F)
    fm = fm[keep]
    if signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    V, F, N = crease_normals(V, F, CREASE_DEG)
    return MeshPart(V, F, fm, N)


def tumblehome_taper(spec: BodySpec, z: np.ndarray, belt: np.ndarray) -> np.ndarray:
    """Tumblehome: width factor (<= 1) of the cabin at height z over the belt line (the glass leans in)."""
    cabin_h = spec.height - _RAIL - 0.5 * (spec.belt_front + spec.belt_rear)
    return 1.0 - spec.tumblehome * 0.85 * np.clip((z - belt) / cabin_h, 0.0, 1.0)


def body_materials(spec: BodySpec, V: np.ndarray, tri_a: np.ndarray, tri_b: np.ndarray, seg: np.ndarray,
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
    top_d, _, plan_hw, belt = body_profiles(spec, d)
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
    e = side_window_edges(spec)
    # The side glass's front / rear edges lean with the windscreen / rear window (A and C pillars).
    e0, e1 = side_window_limits(spec, z)
    in_side_x = (d > e0) & (d < e1)
    for dp in spec.pillars:
        in_side_x &= np.abs(d - dp) > 0.06
    side = (kind == 3) & (kind_hi == 3) & in_side_x & (np.abs(n[:, 1]) > 0.3)
    d_mid = np.full_like(d, 0.5 * (spec.d_roof_front + spec.d_roof_back))
    full_hw = section_half_width(spec, d_mid, z)  # the cabin's width at this height, mid-roof
    above_belt = kind >= 3
    windscreen = (above_belt & (n[:, 0] > 0.3) & (ay < full_hw - 0.12)
                  & (d > spec.d_ws - 0.02) & (d < spec.d_roof_front + 0.02))
    # The rear window: inside D / C pillars measured from the section's own (plan-rounded) half width,
    # so it does not wrap round the rear corners.
    local_hw = plan_hw * tumblehome_taper(spec, z, belt)
    rear = (above_belt & (n[:, 0] < -0.3) & (ay < np.minimum(full_hw - 0.15, local_hw - 0.12))
            & (d > spec.d_roof_back - 0.02) & (z > belt + 0.04))
    mat[side | windscreen] = GLASS
    # Behind the B pillar (rear doors, rear quarter) and the rear window: the (often tinted) rear glass.
    mat[(side & (d > spec.pillars[0])) | rear] = GLASS_REAR
    # Black window surround: the frame above the side glass, the belt seal under it and the B pillar.
    cabin = (cabin_weight(top_d, belt) > 0.5) & (d > e0 - 0.03) & (d < e1 + 0.03) & (np.abs(n[:, 1]) > 0.3)
    frame = cabin & (((kind == 3) & (kind_hi == 4)) | ((kind == 2) & (row == _SEG_ROWS[2] - 1) & (kind_hi == 3)))
    b_pillar = (kind == 3) & (kind_hi == 3) & (np.abs(d - spec.pillars[0]) <= 0.06) & (np.abs(n[:, 1]) > 0.3)
    # Estates (SUVs, vans): the D pillar between the rear side glass and the tailgate glass is black too.
    d_pillar = ((kind == 3) & (kind_hi == 3) & (d > e1) & (np.abs(n[:, 1]) > 0.3) & (mat == PAINT)
                & (len(spec.pillars) > 1))
    mat[frame | b_pillar | d_pillar] = TRIM

    # Panel gaps: thin dark strips at the cut lines (door shut lines on the sides below the belt line,
    # bonnet and boot edges on top).
    for dg, where in panel_gaps(spec):
        strip = np.abs(d - dg) < GAP_HALF_M + 1e-6
        if where == "side":
            strip &= (kind >= 1) & (kind <= 2) & (np.abs(n[:, 1]) > 0.5) & (z < belt - 0.01)
        else:
            strip &= (n[:, 2] > 0.3) & (ay < 0.46 * spec.width) & (kind >= 2)
        mat[strip & (mat == PAINT)] = GAP

    # Trim: underbody (and inner arches), bumpers below the bumper line, grille.
    d_front, d_rear_axle = axle_distances(spec)
    ra = spec.wheel_radius + 0.05
    under = (n[:, 2] < -0.55) | (kind == 0)
    bumper = (kind <= 1) & ((d < d_front - ra - 0.02) | (d > d_rear_axle + ra + 0.02))
    front = (d < 0.45) & (n[:, 0] > 0.25)
    grille = front & (kind == 2) & (row <= 1) & (ay < 0.22 * spec.width)
    sill = (kind == 1) & (row == 0) & (d > d_front + ra) & (d < d_rear_axle - ra)  # the dark rocker under the doors
    mat[under | bumper | grille | sill] = TRIM

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
    (same shapes, broadcast); 0 above the roof or below the underbody.  Linear between the rows of
    :func:`section_rows` (the shell's own polygon)."""
    d, z = np.broadcast_arrays(np.asarray(d, dtype=np.float64), np.asarray(z, dtype=np.float64))
    zq = z.ravel()
    top = body_profiles(spec, d.ravel())[0]
    Y, Z = section_rows(spec, d.ravel())
    Y = np.concatenate([Y, np.zeros((len(zq), 1))], axis=1)
    Z = np.concatenate([Z, top[:, None]], axis=1)
    k = np.clip((Z <= zq[:, None]).sum(axis=1), 1, Z.shape[1] - 1)
    i = np.arange(len(zq))
    z0, z1, y0, y1 = Z[i, k - 1], Z[i, k], Y[i, k - 1], Y[i, k]
    t = np.clip((zq - z0) / np.maximum(z1 - z0, 1e-9), 0.0, 1.0)
    out = np.where((zq >= Z[:, 0]) & (zq <= top), y0 + t * (y1 - y0), 0.0)
    return out.reshape(d.shape)


__all__ = [
    "BODY_SPECS", "BODY_WEIGHTS", "BRAKE", "BodySpec", "CHROME", "DASH", "GAP", "GAP_HALF_M", "GLASS", "GLASS_REAR",
    "HEADLIGHT", "INTERIOR", "N_SLOTS", "PAINT", "PAINT_LOWER", "PLATE_BAND", "PLATE_FRONT", "PLATE_INK",
    "PLATE_REAR", "REFLECTOR", "RIM", "TAILLIGHT", "TRIM", "TYRE", "axle_distances", "body_materials", "body_part",
    "body_profiles", "cabin_weight", "hatchback_spec", "jitter_spec", "loft_stations", "panel_gaps", "section_half_width",
    "section_rows", "sedan_spec", "side_window_edges", "side_window_limits", "suv_spec", "tumblehome_taper", "van_spec",
]
