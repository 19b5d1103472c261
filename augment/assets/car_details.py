"""Exterior details of a procedural car: mirrors, door handles, wipers, a slatted grille, lamps, plates.

Everything is placed on the lofted body (:func:`~.car_body.body_part`, object frame before centring:
x = L/2 - d, y left, z up, metres) by casting rays at the body mesh (:class:`BodySurface`), so parts sit
on its real surface.  Grille and lamps are layered sheets following the body's curve: a near-black
opening under slats; a dark bezel, a bright reflector and a transparent tinted lens over it.
"""

from __future__ import annotations

import numpy as np

from .car_body import (CHROME, GAP, HEADLIGHT, PAINT, REFLECTOR, TAILLIGHT, TRIM, BodySpec, _bumper_line,
                       body_profiles, panel_gaps, section_half_width, side_window_edges)
from .mesh_parts import MeshPart, grid_faces
from .number_plates import PlateStyle, plate_part
from .revolve import box, ellipsoid, tube
from .validate import face_normals, smooth_vertex_normals

from ..core.raycast import RayScene


LAMP_WRAP_M = 0.28  # how far a lamp may reach along the body from its end (m)


class BodySurface:
    """Ray queries against the body shell: where its outer surface is along an axis."""

    def __init__(self, part: MeshPart) -> None:
        self.scene = RayScene(part.vertices, part.faces)

    def hit(self, points: np.ndarray, direction: np.ndarray, reach_m: float = 5.0) -> np.ndarray:
        """(N,) coordinate along ``direction`` of the first surface met coming from ``points`` + reach
        x ``-direction`` (outside) towards ``points``: e.g. ``direction`` = -x gives the front surface's x.
        NaN where the ray misses."""
        P = np.atleast_2d(np.asarray(points, dtype=np.float64))
        u = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
        hits = self.scene.intersect(P - reach_m * u, np.broadcast_to(u, P.shape))
        p = P - reach_m * u + hits.t[:, None] * u
        out = np.abs(u) @ p.T
        return np.where(hits.hit, out, np.nan)


def _part(V: np.ndarray, F: np.ndarray, fm: np.ndarray) -> MeshPart:
    return MeshPart(V, F, fm, smooth_vertex_normals(V, F))


def paint_over_loft_lamps(body: MeshPart) -> MeshPart:
    """The body with the loft's own (staircased) lamp faces painted: the lamps are :func:`lamp_parts`."""
    fm = body.face_material.copy()
    fm[(fm == HEADLIGHT) | (fm == TAILLIGHT)] = PAINT
    return MeshPart(body.vertices, body.faces, fm, body.normals)


def _sheet(P: np.ndarray, mat: int, outward: np.ndarray) -> MeshPart:
    """An open grid surface through points P (rows, cols, 3), faces turned towards ``outward`` (3,)."""
    r, c = P.shape[:2]
    V = P.reshape(-1, 3)
    F = grid_faces(r, c, wrap_cols=False)
    fn, _ = face_normals(V, F)
    if (fn @ outward).mean() < 0:
        F = F[:, ::-1].copy()
    return MeshPart(V, F, np.full(len(F), mat, dtype=np.int64), smooth_vertex_normals(V, F))


def lamp_parts(surface: BodySurface, spec: BodySpec) -> list[MeshPart]:
    """Head and tail lamps: a dark bezel (6 mm out), a bright reflector sheet (8 mm) and a tinted
    transparent lens (16 mm over the body) (``HEADLIGHT`` / ``TAILLIGHT``), all following the body's curve.

    The sheets are offset along the body's normal (not along x: where a lamp wraps round a corner the
    surface runs nearly along x and an x offset left the sheets in it) from a grid dense enough that
    their chords stay out of the curved body; the bezel's grown rim is put back on the surface.

    Outlines (y, z): heights over the bumper line / under the rear belt line (headlights slant up
    towards the car's corners, tail lights are bands); across, from a fixed share of the width out
    towards the corner, but never wrapping more than ``LAMP_WRAP_M`` along the side (no streaks).
    """
    W = spec.width
    zb = _bumper_line(spec)
    zt = spec.belt_rear - (0.12 if spec.length - spec.d_rear > 0.35 else 0.05)  # under a boot lid's rounded edge
    n_y, n_z = 17, 7  # 17 columns keep the sheets out of the body (13: 1.1 mm into a van; 15: 3.7 mm into squarer ends)
    t_y = np.linspace(0.0, 1.0, n_y)
    t_z = np.linspace(0.0, 1.0, n_z)
    parts = []
    for rear in (False, True):
        u = np.array([1.0, 0.0, 0.0]) if rear else np.array([-1.0, 0.0, 0.0])  # into the body
        y0 = (0.17 if rear else 0.22) * W
        for s in (1.0, -1.0):
            for y1 in np.linspace(0.46, 0.30, 9) * W:  # shrink the outer end until the lamp stays at the end
                ys = s * (y0 + (y1 - y0) * t_y)
                if rear:
                    z_lo, z_hi = np.full(n_y, zt - 0.15), np.full(n_y, zt)
                else:
                    z_lo = zb + 0.03 + 0.05 * t_y  # rising towards the corner
                    z_hi = z_lo + 0.11 - 0.03 * t_y
                Y = np.broadcast_to(ys[None, :], (n_z, n_y))
                Z = z_lo[None, :] + (z_hi - z_lo)[None, :] * t_z[:, None]
                base = _on_body(surface, Y, Z, u, spec.length)
                if base is not None and np.ptp(base[..., 0]) <= LAMP_WRAP_M:
                    break
            else:
                continue
            out = -u
            rim = _grown(base, 0.015)
            hit = _on_body(surface, rim[..., 1], rim[..., 2], u, spec.length, allow_miss=True)
            rim[..., 0] = np.where(np.isnan(hit[..., 0]), rim[..., 0], hit[..., 0])
            parts.append(_sheet(_lifted(rim, 0.006, out), TRIM, out))  # the dark bezel around the lamp
            parts.append(_sheet(_lifted(base, 0.008, out), REFLECTOR, out))
            parts.append(_sheet(_lifted(base, 0.016, out), TAILLIGHT if rear else HEADLIGHT, out))
    return parts


def _on_body(surface: BodySurface, Y: np.ndarray, Z: np.ndarray, u: np.ndarray, length_m: float,
             allow_miss: bool = False) -> np.ndarray | None:
    """Grid points (rows, cols, 3) on the body's front / rear surface (rays along ``u``) at (Y, Z); None
    where a ray misses (NaN x with ``allow_miss``)."""
    pts = np.stack([np.full(Y.size, -u[0] * length_m), Y.ravel(), Z.ravel()], -1)
    x = surface.hit(pts, u, reach_m=0.0)
    if np.isnan(x).any() and not allow_miss:
        return None
    return np.stack([x, Y.ravel(), Z.ravel()], 1).reshape(Y.shape + (3,))


def _lifted(P: np.ndarray, offset_m: float, outward: np.ndarray) -> np.ndarray:
    """Grid points (rows, cols, 3) moved ``offset_m`` along the grid surface's normal (turned to ``outward``)."""
    r, c = P.shape[:2]
    V = P.reshape(-1, 3)
    n = smooth_vertex_normals(V, grid_faces(r, c, wrap_cols=False))
    n *= np.sign(n @ outward + 1e-12)[:, None]
    return (V + offset_m * n).reshape(P.shape)


def _grown(P: np.ndarray, margin_m: float) -> np.ndarray:
    """Grid points (rows, cols, 3) with a ring of points around them, ``margin_m`` further out in y-z
    ((rows + 2, cols + 2, 3); x copied from the edge: put it back on the surface)."""
    G = np.pad(P, ((1, 1), (1, 1), (0, 0)), mode="edge")
    for axis in (0, 1):
        for idx, inner in ((0, 2), (-1, -3)):
            edge = np.take(G, idx, axis=axis)
            step = edge - np.take(G, inner, axis=axis)
            step[..., 0] = 0.0
            step /= np.maximum(np.linalg.norm(step, axis=-1, keepdims=True), 1e-12)
            sl = [slice(None)] * 3
            sl[axis] = idx
            G[tuple(sl)] += margin_m * step
    return G


def grille_parts(surface: BodySurface, spec: BodySpec, chrome: bool) -> list[MeshPart]:
    """The grille: a near-black opening on the nose between the headlights (a sheet 2 mm over the body)
    with four horizontal slats 1.2 cm in front of it (chrome or black), both following the nose's curve."""
    zb = _bumper_line(spec)
    hw = 0.22 * spec.width
    ys = np.linspace(-hw, hw, 9)
    z0, z1 = zb + 0.02, zb + 0.14
    Y, Z = np.meshgrid(ys, np.linspace(z0, z1, 4))
    pts = np.stack([np.full(Y.size, spec.length), Y.ravel(), Z.ravel()], 1)
    x = surface.hit(pts, np.array([-1.0, 0.0, 0.0]), reach_m=0.0)
    if np.isnan(x).any():
        return []
    out = np.array([1.0, 0.0, 0.0])
    base = np.stack([x, Y.ravel(), Z.ravel()], 1).reshape(Y.shape + (3,))
    parts = [_sheet(base + 0.002 * out, GAP, out)]
    for z in np.linspace(z0 + 0.02, z1 - 0.02, 4):
        row = np.stack([np.full(9, spec.length), ys[None].ravel() * 0.97, np.full(9, z)], 1)
        xr = surface.hit(row, np.array([-1.0, 0.0, 0.0]), reach_m=0.0)
        if np.isnan(xr).any():
            continue
        row[:, 0] = xr + 0.012
        parts.append(tube(row, 0.006, CHROME if chrome else TRIM, n_around=4))
    intake = lower_intake_part(surface, spec)
    return parts + ([intake] if intake is not None else [])


INTAKE_HALF_WIDTH = 0.34  # the lower intake's half width, a share of the car's width
INTAKE_Z_M = (0.17, 0.05)  # its bottom and top edge under the bumper line (m)


def lower_intake_part(surface: BodySurface, spec: BodySpec) -> MeshPart | None:
    """The front bumper's lower air intake: a near-black band (``GAP``) across most of the nose under the bumper
    line, a sheet 3 mm over the body following its curve (the real cars of scene-0916 seen from the front show
    a wide dark intake under the grille: a strong horizontal edge the procedural nose lacked).  None where the
    nose does not reach that low."""
    hw = INTAKE_HALF_WIDTH * spec.width
    zb = _bumper_line(spec)
    ys = np.linspace(-hw, hw, 11)
    Y, Z = np.meshgrid(ys, np.linspace(zb - INTAKE_Z_M[0], zb - INTAKE_Z_M[1], 3))
    pts = np.stack([np.full(Y.size, spec.length), Y.ravel(), Z.ravel()], 1)
    x = surface.hit(pts, np.array([-1.0, 0.0, 0.0]), reach_m=0.0)
    if np.isnan(x).any():
        return None
    out = np.array([1.0, 0.0, 0.0])
    base = np.stack([x, Y.ravel(), Z.ravel()], 1).reshape(Y.shape + (3,))
    return _sheet(_lifted(base, 0.003, out), GAP, out)


def mirror_parts(spec: BodySpec, y_out: float, paint_housing: bool) -> list[MeshPart]:
    """Side mirrors at the foot of the A pillars reaching out to |y| = ``y_out``: housing, stalk, glass."""
    d = side_window_edges(spec)[0] + 0.03
    _, _, _, belt = body_profiles(spec, np.array([d]))
    zc = float(belt[0]) + 0.10
    radii, clamp = np.array([0.075, 0.115, 0.085]), np.array([0.05, 0.1, 0.065])
    x = spec.length / 2 - d
    parts = []
    mat = PAINT if paint_housing else TRIM
    for s in (1.0, -1.0):
        yc = s * (y_out - clamp[1])
        parts.append(ellipsoid(np.array([x, yc, zc]), radii, mat, n_around=14, n_rings=8, clamp=clamp))
        y_body = float(section_half_width(spec, np.array([d]), np.array([zc - 0.06]))[0])
        lo = np.array([x - 0.03, min(s * (y_body - 0.03), yc), zc - 0.085])
        hi = np.array([x + 0.03, max(s * (y_body - 0.03), yc), zc - 0.045])
        parts.append(box(lo, hi, TRIM))
        # The mirror glass faces backwards, slightly proud of the housing's rear face.
        g_lo = np.array([x - clamp[0] - 0.004, yc - 0.085, zc - 0.05])
        g_hi = np.array([x - clamp[0] + 0.01, yc + 0.085, zc + 0.05])
        parts.append(box(g_lo, g_hi, CHROME))
    return parts


def door_handle_parts(spec: BodySpec, chrome: bool) -> list[MeshPart]:
    """A handle just ahead of each door's rear shut line, 9 cm under the belt line, both sides."""
    cuts = [g for g, where in panel_gaps(spec) if where == "side"][1:]
    parts = []
    for dg in cuts:
        d = dg - 0.15
        _, _, _, belt = body_profiles(spec, np.array([d]))
        z = float(belt[0]) - 0.09
        y_s = float(section_half_width(spec, np.array([d - 0.07, d + 0.07]), np.array([z, z])).min())
        x = spec.length / 2 - d
        for s in (1.0, -1.0):
            y0, y1 = s * (y_s - 0.012), s * (y_s + 0.012)
            parts.append(box(np.array([x - 0.07, min(y0, y1), z - 0.016]), np.array([x + 0.07, max(y0, y1), z + 0.016]),
                             CHROME if chrome else PAINT))
    return parts


def wiper_parts(surface: BodySurface, spec: BodySpec, right_hand_drive: bool) -> list[MeshPart]:
    """Two wiper arms resting along the bottom of the windscreen, 12 mm over the glass."""
    d0 = spec.d_ws + 0.06
    x0 = spec.length / 2 - d0
    s = -1.0 if right_hand_drive else 1.0  # the wipers sweep towards the driver's side
    parts = []
    for y_pivot in (-s * 0.30 * spec.width, -s * 0.02 * spec.width):
        t = np.linspace(0.0, 1.0, 5)
        ys = y_pivot + s * 0.27 * spec.width * t
        xs = x0 - 0.06 * t
        pts = np.stack([xs, ys, np.full(5, spec.height + 1.0)], 1)
        z = surface.hit(pts, np.array([0.0, 0.0, -1.0]))
        if np.isnan(z).any():
            continue
        pts[:, 2] = z + 0.012
        parts.append(tube(pts, 0.008, TRIM, n_around=4))
    return parts


def plate_parts(surface: BodySurface, spec: BodySpec, style: PlateStyle, rng: np.random.Generator,
                anonymised: bool = False) -> list[MeshPart]:
    """Front plate under the bumper line, rear plate just over it: 2 cm thick boxes whose face is 6 mm
    proud of the body's outermost point behind them (on a curved bumper their edges stand off it);
    ``anonymised``: without characters (see :func:`~.number_plates.plate_part`)."""
    w, h = style.size_m
    zb = _bumper_line(spec)
    parts = []
    for rear, zc in ((False, zb - 0.03 - h / 2), (True, zb + 0.05 + h / 2)):
        u = np.array([1.0, 0.0, 0.0]) if rear else np.array([-1.0, 0.0, 0.0])  # ray direction into the body
        yy, zz = np.meshgrid([-w / 2, 0.0, w / 2], [zc - h / 2, zc, zc + h / 2])
        pts = np.stack([np.zeros(yy.size), yy.ravel(), zz.ravel()], 1)
        pts[:, 0] = -u[0] * spec.length  # outside, in front of / behind the car
        c = surface.hit(pts, u, reach_m=0.0)
        if np.isnan(c).any():
            continue
        x_face = float(c.min()) - 0.006 if rear else float(c.max()) + 0.006
        x_back = x_face + (0.02 if rear else -0.02)
        parts.append(plate_part(style, x_face, x_back, zc, rear, rng, anonymised))
    return parts


__all__ = ["BodySurface", "door_handle_parts", "grille_parts", "lamp_parts", "lower_intake_part", "mirror_parts",
           "paint_over_loft_lamps", "plate_parts", "wiper_parts"]
