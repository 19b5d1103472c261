"""Closed-surface primitives of the small procedural objects: lofts of ellipses, capsules, tubes, tori, prisms.

Every builder returns a closed :class:`~.mesh_parts.MeshPart` (outward, counter-clockwise faces, one
material slot) in the object frame (metres).  The common form is a *loft*: K rings of N points each,
consecutive rings joined by quads, the ends closed either by a pole (a ring of zero radius, welded) or
by a flat fan cap.  Surfaces of revolution, capsules and tubes along a polyline are lofts of circles or
ellipses; prisms are lofts of two copies of a 2-D profile.
"""

from __future__ import annotations

import numpy as np

from .mesh_parts import MeshPart, grid_faces, orient_outward, weld_vertices
from .validate import face_normals, smooth_vertex_normals


def frame_from_axis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (u, v, w) with w = ``axis`` normalised (3,); u is as close to +x as w allows."""
    w = np.asarray(axis, dtype=np.float64)
    w = w / np.linalg.norm(w)
    ref = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = ref - w * (ref @ w)
    u /= np.linalg.norm(u)
    return u, np.cross(w, u), w


def _clean(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Faces without repeated indices or zero area."""
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    _, area = face_normals(V, F)
    return F[area > 1e-14]


def loft(rings: np.ndarray, material: int, caps: str = "pole", weld: bool = True) -> MeshPart:
    """A closed surface through ``rings`` (K, N, 3): quads between consecutive rings, ends closed.

    Args:
        rings: (K, N, 3) ring points (each ring a closed loop, same winding for all rings), metres.
        material: material slot of every face.
        caps: ``"pole"`` (the first and last rings are points or are closed by a fan to their centroid,
            sharing the side's vertices) or ``"flat"`` (fan caps with their own vertices: a sharp rim
            and flat shading, for cylinders and prisms).
        weld: merge coincident vertices (pole rings) so normals are smooth across them.
    """
    R = np.asarray(rings, dtype=np.float64)
    K, N = R.shape[:2]
    V = R.reshape(-1, 3)
    F = grid_faces(K, N, wrap_cols=True)
    c = np.arange(N)
    c1 = (c + 1) % N
    caps_out = []
    for end, ring in ((0, 0), (1, K - 1)):
        centre = R[ring].mean(axis=0)
        if np.allclose(R[ring], centre, atol=1e-12):
            continue  # a pole: the ring is one point
        if caps == "flat":
            base = np.concatenate([R[ring], centre[None]])
            tri = np.stack([np.full(N, N), c1, c] if end == 0 else [np.full(N, N), c, c1], 1)
            caps_out.append((base, tri))
        else:
            V = np.concatenate([V, centre[None]])
            idx = len(V) - 1
            r0 = ring * N
            tri = np.stack([np.full(N, idx), r0 + c1, r0 + c] if end == 0 else [np.full(N, idx), r0 + c, r0 + c1], 1)
            F = np.concatenate([F, tri])
    if weld:
        V, F, _ = weld_vertices(V, F, tol=1e-9)
    F = _clean(V, F)
    N_side = smooth_vertex_normals(V, F)
    Vs, Fs, Ns = [V], [F], [N_side]
    off = len(V)
    for base, tri in caps_out:
        tri = _clean(base, tri)
        fn, _ = face_normals(base, tri)
        Vs.append(base)
        Fs.append(tri + off)
        Ns.append(np.broadcast_to(fn.mean(axis=0) / max(np.linalg.norm(fn.mean(axis=0)), 1e-12), base.shape))
        off += len(base)
    V, F, Nn = np.concatenate(Vs), np.concatenate(Fs), np.concatenate(Ns)
    F2 = orient_outward(V, F)
    if F2 is not F:  # flipped: the normals point inwards too
        Nn = -Nn
    return MeshPart(V, F2.astype(np.int64), np.full(len(F2), material, dtype=np.int64), np.ascontiguousarray(Nn))


def ellipse_rings(centres: np.ndarray, u: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray,
                  n_around: int) -> np.ndarray:
    """Rings (K, N, 3): ``centres[k] + a[k] cos t u[k] + b[k] sin t v[k]`` for N angles t.

    ``centres``, ``u``, ``v``: (K, 3) (``u``/``v`` may be (3,) for all rings); ``a``, ``b``: (K,) semi-axes.
    """
    t = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    C = np.asarray(centres, dtype=np.float64)
    U = np.broadcast_to(np.asarray(u, dtype=np.float64), C.shape)
    W = np.broadcast_to(np.asarray(v, dtype=np.float64), C.shape)
    A = np.asarray(a, dtype=np.float64)[:, None, None]
    B = np.asarray(b, dtype=np.float64)[:, None, None]
    return C[:, None] + A * np.cos(t)[None, :, None] * U[:, None] + B * np.sin(t)[None, :, None] * W[:, None]


def revolve(axis_pos: np.ndarray, radius: np.ndarray, origin: np.ndarray, axis: np.ndarray, material: int,
            n_around: int = 16, caps: str = "pole", scale_v: float = 1.0) -> MeshPart:
    """A surface of revolution: profile radii (K,) at positions (K,) along ``axis`` from ``origin``.

    A zero radius at an end makes a pole; otherwise the end is capped (``caps`` as in :func:`loft`).
    ``scale_v`` stretches the cross-section along the frame's v axis (elliptic sections).
    """
    u, v, w = frame_from_axis(axis)
    s = np.asarray(axis_pos, dtype=np.float64)
    r = np.asarray(radius, dtype=np.float64)
    centres = np.asarray(origin, dtype=np.float64) + s[:, None] * w
    return loft(ellipse_rings(centres, u, v, r, r * scale_v, n_around), material, caps=caps)


def ellipsoid(centre: np.ndarray, radii: np.ndarray, material: int, rotation: np.ndarray | None = None,
              n_around: int = 14, n_rings: int = 9, z_floor: float | None = None,
              clamp: np.ndarray | None = None) -> MeshPart:
    """An ellipsoid with semi-axes ``radii`` (3,) along the columns of ``rotation`` (3, 3), at ``centre``.

    ``z_floor``: vertices below this object-frame height are clamped onto it (a flat sole or base).
    ``clamp``: (3,) half-extents in the ellipsoid's own axes the vertices are clamped to (smaller than
    ``radii``: a box with rounded edges, e.g. a backpack).
    """
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    t = np.linspace(0.0, np.pi, n_rings)
    a, b, c = np.asarray(radii, dtype=np.float64)
    rings = ellipse_rings((-c * np.cos(t))[:, None] * np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]),
                          np.array([0.0, 1.0, 0.0]), a * np.sin(t), b * np.sin(t), n_around)
    if clamp is not None:
        lim = np.asarray(clamp, dtype=np.float64)
        rings = np.clip(rings, -lim, lim)
    rings = rings @ R.T + np.asarray(centre, dtype=np.float64)
    if z_floor is not None:
        rings[..., 2] = np.maximum(rings[..., 2], z_floor)
    return loft(rings, material)


def capsule(p0: np.ndarray, p1: np.ndarray, r0: float, r1: float, material: int, n_around: int = 12,
            n_cap: int = 3, flatten: float = 1.0) -> MeshPart:
    """A tapered capsule from ``p0`` (radius ``r0``) to ``p1`` (radius ``r1``), rounded ends.

    ``flatten`` scales the cross-section along the frame's v axis (< 1: an oval limb).
    """
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    d = p1 - p0
    L = float(np.linalg.norm(d))
    if L < 1e-9:
        d, L = np.array([0.0, 0.0, 1.0]), 0.0
    t = np.linspace(0.0, np.pi / 2, n_cap + 1)
    s = np.concatenate([-r0 * np.cos(t), L + r1 * np.sin(t)])
    r = np.concatenate([r0 * np.sin(t), r1 * np.cos(t)])
    return revolve(s, r, p0, d, material, n_around=n_around, scale_v=flatten)


def tube(points: np.ndarray, radius: float | np.ndarray, material: int, n_around: int = 8,
         caps: str = "flat") -> MeshPart:
    """A tube of circular section along the polyline ``points`` (K, 3), closed at both ends.

    Ring frames are parallel-transported along the polyline; interior rings lie in the bisecting plane.
    ``radius`` is a scalar or (K,) per point.
    """
    P = np.asarray(points, dtype=np.float64)
    K = len(P)
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (K,))
    seg = np.diff(P, axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    tang = np.concatenate([seg[:1], seg[:-1] + seg[1:], seg[-1:]]) if K > 2 else np.concatenate([seg, seg])
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    u0, _, _ = frame_from_axis(tang[0])
    U = np.empty((K, 3))
    U[0] = u0
    for k in range(1, K):
        x = U[k - 1] - tang[k] * (U[k - 1] @ tang[k])
        U[k] = x / np.linalg.norm(x)
    Vv = np.cross(tang, U)
    return loft(ellipse_rings(P, U, Vv, r, r, n_around), material, caps=caps, weld=False)


def straight_tubes(p0: np.ndarray, p1: np.ndarray, radius: float, material: int, n_around: int = 4) -> MeshPart:
    """Many thin closed cylinders at once (spokes, wires): from ``p0[i]`` to ``p1[i]`` (S, 3), one part.

    Side normals are radial, cap normals along the axis (no smoothing across the rim).
    """
    A, B = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    S = len(A)
    d = B - A
    w = d / np.linalg.norm(d, axis=1, keepdims=True)
    ref = np.where(np.abs(w[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]))
    u = ref - w * np.einsum("ij,ij->i", ref, w)[:, None]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(w, u)
    t = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    radial = np.cos(t)[None, :, None] * u[:, None] + np.sin(t)[None, :, None] * v[:, None]  # (S, N, 3)
    ring0, ring1 = A[:, None] + radius * radial, B[:, None] + radius * radial
    c = np.arange(n_around)
    c1 = (c + 1) % n_around
    N = n_around
    # per tube vertices: side ring0 (N), side ring1 (N), cap0 ring (N), cap1 ring (N)
    side = np.concatenate([np.stack([c, c1, N + c1], 1), np.stack([c, N + c1, N + c], 1)])
    cap0 = np.stack([np.full(N - 2, 2 * N), 2 * N + np.arange(2, N), 2 * N + np.arange(1, N - 1)], 1)
    cap1 = np.stack([np.full(N - 2, 3 * N), 3 * N + np.arange(1, N - 1), 3 * N + np.arange(2, N)], 1)
    local = np.concatenate([side, cap0, cap1])
    V = np.concatenate([ring0, ring1, ring0, ring1], axis=1)  # (S, 4N, 3)
    Nn = np.concatenate([radial, radial, np.broadcast_to(-w[:, None], ring0.shape),
                         np.broadcast_to(w[:, None], ring0.shape)], axis=1)
    F = (local[None] + (4 * N * np.arange(S))[:, None, None]).reshape(-1, 3)
    V, Nn = V.reshape(-1, 3), Nn.reshape(-1, 3)
    # orient every triangle like its vertex normals (outward)
    fn, _ = face_normals(V, F)
    flip = np.einsum("ij,ij->i", fn, Nn[F].sum(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    return MeshPart(V, F.astype(np.int64), np.full(len(F), material, dtype=np.int64), np.ascontiguousarray(Nn))


def torus(centre: np.ndarray, axis: np.ndarray, R: float, r: float, material: int, n_major: int = 32,
          n_minor: int = 8, scale_axial: float = 1.0) -> MeshPart:
    """A torus of major radius ``R`` and tube radius ``r`` around ``axis`` at ``centre``.

    ``scale_axial`` stretches the tube section along the axis (a wide tyre: > 1).
    """
    u, v, w = frame_from_axis(axis)
    t = np.linspace(0.0, 2 * np.pi, n_major, endpoint=False)
    p = np.linspace(0.0, 2 * np.pi, n_minor, endpoint=False)
    radial = np.cos(t)[:, None, None] * u + np.sin(t)[:, None, None] * v  # (M, 1, 3)
    rad = R + r * np.cos(p)[None, :, None]
    V = (np.asarray(centre, dtype=np.float64) + rad * radial
         + (scale_axial * r * np.sin(p))[None, :, None] * w).reshape(-1, 3)
    F = grid_faces(n_major, n_minor, wrap_cols=True)
    last = (n_major - 1) * n_minor + np.arange(n_minor)
    first = np.arange(n_minor)
    nxt = (np.arange(n_minor) + 1) % n_minor
    F = np.concatenate([F, np.stack([last, last[nxt], first[nxt]], 1), np.stack([last, first[nxt], first], 1)])
    F = orient_outward(V - np.asarray(centre), F)
    return MeshPart(V, F.astype(np.int64), np.full(len(F), material, dtype=np.int64), smooth_vertex_normals(V, F))


def prism(profile: np.ndarray, origin: np.ndarray, u: np.ndarray, v: np.ndarray, w: np.ndarray, length: float,
          material: int, sharp: bool = True) -> MeshPart:
    """A 2-D ``profile`` (N, 2) in the (u, v) plane at ``origin`` extruded by ``length`` along ``w``.

    The profile must be star-shaped about its centroid (the caps are fans).  ``sharp`` duplicates every
    profile point so the side faces shade flat with sharp edges between them.
    """
    Pr = np.asarray(profile, dtype=np.float64)
    if sharp:
        Pr = np.repeat(Pr, 2, axis=0)
    u, v, w = (np.asarray(x, dtype=np.float64) for x in (u, v, w))
    ring = np.asarray(origin, dtype=np.float64) + Pr[:, :1] * u + Pr[:, 1:] * v
    rings = np.stack([ring, ring + length * w])
    return loft(rings, material, caps="flat", weld=False)


def box(lo: np.ndarray, hi: np.ndarray, material: int, rotation: np.ndarray | None = None,
        pivot: np.ndarray | None = None) -> MeshPart:
    """An axis-aligned box ``lo``..``hi`` (3,), optionally rotated by ``rotation`` (3, 3) about ``pivot``."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    prof = np.array([[lo[1], lo[2]], [hi[1], lo[2]], [hi[1], hi[2]], [lo[1], hi[2]]])
    part = prism(prof, np.array([lo[0], 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                 np.array([1.0, 0.0, 0.0]), float(hi[0] - lo[0]), material)
    if rotation is None:
        return part
    Rm = np.asarray(rotation, dtype=np.float64)
    p = np.zeros(3) if pivot is None else np.asarray(pivot, dtype=np.float64)
    return MeshPart((part.vertices - p) @ Rm.T + p, part.faces, part.face_material, part.normals @ Rm.T)


def rot_y(angle: float) -> np.ndarray:
    """Rotation (3, 3) by ``angle`` radians about +y (positive turns +z towards +x)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """Rotation (3, 3) by ``angle`` radians about +z (positive turns +x towards +y)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def transform_part(part: MeshPart, rotation: np.ndarray | None = None, offset: np.ndarray | None = None,
                   scale: float = 1.0) -> MeshPart:
    """``part`` with vertices ``scale * R v + offset`` (normals rotated)."""
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    t = np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64)
    return MeshPart(scale * part.vertices @ R.T + t, part.faces, part.face_material, part.normals @ R.T)


def with_material(part: MeshPart, material: np.ndarray | int) -> MeshPart:
    """``part`` with its face materials replaced (a slot, or (F,) slots)."""
    fm = np.broadcast_to(np.asarray(material, dtype=np.int64), part.face_material.shape).copy()
    return MeshPart(part.vertices, part.faces, fm, part.normals)


__all__ = ["box", "capsule", "ellipse_rings", "ellipsoid", "frame_from_axis", "loft", "prism", "revolve", "rot_y",
           "rot_z", "straight_tubes", "torus", "transform_part", "tube", "with_material"]
