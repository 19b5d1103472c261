"""The wheels of a procedural car: revolved tyre profiles (tread, shoulders, sidewalls) with a spoked rim
cap whose windows are open onto a brake disc and caliper, and dark wheel wells."""

from __future__ import annotations

import numpy as np

from .car_body import BRAKE, RIM, TRIM, TYRE, BodySpec, axle_distances
from .mesh_parts import MeshPart, box_mesh, grid_faces, orient_outward, weld_vertices
from .revolve import revolve
from .validate import face_normals, smooth_vertex_normals


def wheel_parts(spec: BodySpec) -> list[MeshPart]:
    """The four wheels (a tyre and two rim caps each) at the axles, tyres touching z = 0."""
    r = spec.wheel_radius
    tyre_w = 0.19 + 0.06 * (spec.width - 1.75) / 0.25
    y_out = 0.5 * spec.width - 0.035
    y_c = y_out - tyre_w / 2
    parts = []
    for dw in axle_distances(spec):
        x = spec.length / 2 - dw
        for side in (1.0, -1.0):
            parts.extend(wheel(np.array([x, side * y_c, r]), side, r, tyre_w))
    return parts


def wheel(centre: np.ndarray, side: float, r: float, width: float, brake: bool = True) -> list[MeshPart]:
    """Tyre (revolved rounded profile) plus a spoked rim cap on the outer face; axis along y.

    With ``brake`` the outer cap's windows between the spokes are open and a brake disc (with its
    caliper towards the rear) sits behind them, in front of a dark inner cap.
    """
    n_around = 32
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False) - np.pi / 2  # includes the bottom point
    r_rim = 0.66 * r
    hw = width / 2
    # Closed profile (radius, axial) going around the tyre cross-section, outer side first.
    a = np.linspace(0.0, np.pi / 2, 3)  # 45 deg steps round the 4.5 cm shoulders (4 points: 512 more triangles a car)
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
    F = grid_faces(n_around, len(prof), wrap_cols=True)
    # close the around-direction (last ring to first ring)
    last = (n_around - 1) * len(prof) + np.arange(len(prof))
    first = np.arange(len(prof))
    nxt = (np.arange(len(prof)) + 1) % len(prof)
    F = np.concatenate([F, np.stack([last, last[nxt], first[nxt]], 1), np.stack([last, first[nxt], first], 1)])
    V, F, _ = weld_vertices(V, F)
    F = orient_about(V, F, centre)
    tyre = MeshPart(V, F, np.full(len(F), TYRE), smooth_vertex_normals(V, F))

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
        Fc = grid_faces(n_around, len(radii), wrap_cols=False)
        last = (n_around - 1) * len(radii) + np.arange(len(radii) - 1)
        first = np.arange(len(radii) - 1)
        Fc = np.concatenate([Fc, np.stack([last, first, first + 1], 1), np.stack([last, first + 1, last + 1], 1)])
        Vc, Fc, _ = weld_vertices(Vc, Fc)
        outward = np.array([0.0, side * face_side, 0.0])
        fn, _ = face_normals(Vc, Fc)
        if (fn @ outward).mean() < 0:
            Fc = Fc[:, ::-1].copy()
        cen = Vc[Fc].mean(axis=1) - centre
        ang = np.arctan2(cen[:, 2], cen[:, 0])
        rr = np.hypot(cen[:, 0], cen[:, 2])
        if face_side < 0:
            fm = np.full(len(Fc), TRIM if brake else RIM)
        else:
            spoke = (np.cos(5 * ang) > -0.25) | (rr < 0.3 * r_rim) | (rr > 0.86 * r_rim)
            fm = np.where(spoke, RIM, TRIM)
            if brake:  # open windows between the spokes
                Fc, fm = Fc[spoke], fm[spoke]
        caps.append(MeshPart(Vc, Fc, fm, smooth_vertex_normals(Vc, Fc)))
    if not brake:
        return [tyre, *caps]
    # Brake disc (a flat cylinder) behind the spokes and a caliper box gripping its rear edge.
    axis = np.array([0.0, side, 0.0])
    disc_face = hw - 0.065
    disc = revolve(np.array([disc_face - 0.025, disc_face]), np.full(2, 0.8 * r_rim), centre, axis, BRAKE,
                   n_around=24, caps="flat")
    lo = centre + np.array([-0.86 * r_rim, 0.0, -0.22 * r_rim])
    hi = centre + np.array([-0.58 * r_rim, 0.0, 0.22 * r_rim])
    lo[1], hi[1] = sorted((centre[1] + side * (disc_face - 0.045), centre[1] + side * (disc_face + 0.012)))
    Vb, Fb = box_mesh(lo, hi)
    caliper = MeshPart(Vb, Fb, np.full(len(Fb), TRIM), smooth_vertex_normals(Vb, Fb))
    return [tyre, *caps, disc, caliper]


def orient_about(V: np.ndarray, F: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Orient a closed surface around ``centre`` so its signed volume is positive."""
    return orient_outward(V - centre, F)


def wheel_well_parts(spec: BodySpec) -> list[MeshPart]:
    """Dark boxes between each axle's tyres, so the arches look deep rather than see-through."""
    r = spec.wheel_radius
    ra = r + 0.05
    tyre_w = 0.19 + 0.06 * (spec.width - 1.75) / 0.25
    half_y = 0.5 * spec.width - 0.035 - tyre_w - 0.02
    parts = []
    for dw in axle_distances(spec):
        x = spec.length / 2 - dw
        lo = np.array([x - 0.9 * ra, -half_y, 0.12])
        hi = np.array([x + 0.9 * ra, half_y, r + ra + 0.02])
        V, F = box_mesh(lo, hi)
        parts.append(MeshPart(V, F, np.full(len(F), TRIM), smooth_vertex_normals(V, F)))
    return parts


__all__ = ["orient_about", "wheel", "wheel_parts", "wheel_well_parts"]
