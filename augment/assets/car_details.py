"""Exterior details of a procedural car: mirrors, door handles, wipers, a slatted grille, lamps, plates.

Everything is placed on the lofted body (:func:`~.car_body.body_part`, object frame before centring:
x = L/2 - d, y left, z up, metres) by casting rays at the body mesh (:class:`BodySurface`), so parts sit
on its real surface.  The grille and the lamps are recessed into the body: the vertices inside those
regions move inwards (the shell stays closed); the lamps get a lens (the old surface, transparent and
tinted) over a bright reflector (the recessed surface).
"""

from __future__ import annotations

import numpy as np

from .car_body import (CHROME, HEADLIGHT, PAINT, REFLECTOR, TAILLIGHT, TRIM, BodySpec, _bumper_line, body_profiles,
                       panel_gaps, section_half_width, side_window_edges)
from .mesh_parts import MeshPart
from .number_plates import PlateStyle, plate_part
from .revolve import box, ellipsoid, tube
from .validate import face_normals, smooth_vertex_normals

from ..core.raycast import RayScene


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


def recess_lamps_and_grille(body: MeshPart, spec: BodySpec) -> tuple[MeshPart, list[MeshPart]]:
    """The body with its grille and lamp regions pushed in, plus the lamp lenses over the recesses.

    The grille (the dark front faces above the bumper line) recedes 3 cm, each lamp 2 cm; the lamp
    faces become the ``REFLECTOR`` and a copy of their original surface the lens (``HEADLIGHT`` /
    ``TAILLIGHT``, transparent).  Only vertices all of whose faces are in a region move.
    """
    V, F, fm = body.vertices.copy(), body.faces, body.face_material.copy()
    fn, _ = face_normals(V, F)
    cen = V[F].mean(axis=1)
    x_front = spec.length / 2
    grille = (fm == TRIM) & (cen[:, 0] > x_front - 0.45) & (fn[:, 0] > 0.25) & (cen[:, 2] > _bumper_line(spec))
    lenses = []
    for region, depth, axis_sign in ((grille, 0.03, -1.0), (fm == HEADLIGHT, 0.02, -1.0), (fm == TAILLIGHT, 0.02, 1.0)):
        if not region.any():
            continue
        inside = np.ones(len(V), bool)
        np.logical_and.at(inside, F[~region].ravel(), False)  # vertices touching a face outside the region
        move = inside & np.isin(np.arange(len(V)), F[region].ravel())
        if region is not grille:
            lens_F = F[region]
            keep = np.unique(lens_F)
            remap = np.full(len(V), -1)
            remap[keep] = np.arange(len(keep))
            lens_V = V[keep].copy()
            lens_V[:, 0] -= axis_sign * 0.002  # 2 mm proud: never coincident with an unmoved reflector face
            lenses.append(_part(lens_V, remap[lens_F], fm[region]))
            fm[region] = REFLECTOR
        V[move, 0] += axis_sign * depth
    return MeshPart(V, F, fm, smooth_vertex_normals(V, F)), lenses


def grille_slats(surface: BodySurface, spec: BodySpec, chrome: bool) -> list[MeshPart]:
    """Horizontal slats across the (recessed) grille opening, on the body's front surface."""
    zb = _bumper_line(spec)
    top, _, _, belt = body_profiles(spec, np.array([0.05]))
    z_hi = min(float(top[0]) - 0.05, zb + 0.45 * (spec.belt_front - zb))
    hw = 0.21 * spec.width
    ys = np.linspace(-hw, hw, 7)
    parts = []
    for z in np.linspace(zb + 0.035, z_hi - 0.02, 4):
        pts = np.stack([np.full(7, spec.length), ys, np.full(7, z)], 1)
        x = surface.hit(pts, np.array([-1.0, 0.0, 0.0]))
        if np.isnan(x).any():
            continue
        # At the opening's edges the surface is the paint around it: keep the slat inside the opening.
        pts[:, 0] = x - 0.012
        parts.append(tube(pts, 0.007, CHROME if chrome else TRIM, n_around=4))
    return parts


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


def plate_parts(surface: BodySurface, spec: BodySpec, style: PlateStyle, rng: np.random.Generator) -> list[MeshPart]:
    """Front plate under the bumper line, rear plate just over it: 2 cm thick boxes whose face is 6 mm
    proud of the body's outermost point behind them (on a curved bumper their edges stand off it)."""
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
        parts.append(plate_part(style, x_face, x_back, zc, rear, rng))
    return parts


__all__ = ["BodySurface", "door_handle_parts", "grille_slats", "mirror_parts", "plate_parts",
           "recess_lamps_and_grille", "wiper_parts"]
