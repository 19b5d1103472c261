"""Triangle-mesh building blocks of the procedural objects: parts, grids of quads, welding, orientation, boxes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .validate import face_normals


@dataclass(frozen=True)
class MeshPart:
    """One part of a procedural mesh (object frame, metres).

    Attributes:
        vertices: (V, 3) float64 positions.
        faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside.
        face_material: (F,) int64 material slot per face.
        normals: (V, 3) float64 unit smooth-shading normals.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    normals: np.ndarray


def target_wlh(wlh, where: str) -> np.ndarray | None:
    """A generator's target box size (3,) float64 [w, l, h] metres, checked; None stays None (a typical size).

    Raises:
        ValueError: not 3 finite positive numbers (the message starts with ``where``).
    """
    if wlh is None:
        return None
    a = np.asarray(wlh, dtype=np.float64).ravel()
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"{where}: wlh must be 3 finite positive numbers [w, l, h] in metres, got {wlh!r}")
    return a


def merge_parts(parts: list[MeshPart]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parts as one mesh: vertices (V, 3), faces (F, 3) int64 and face materials (F,) int64."""
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    V = np.concatenate([p.vertices for p in parts])
    F = np.concatenate([p.faces + o for p, o in zip(parts, offsets)])
    M = np.concatenate([p.face_material for p in parts])
    return V, F.astype(np.int64), M.astype(np.int64)


def grid_faces(n_rows: int, n_cols: int, wrap_cols: bool) -> np.ndarray:
    """Two triangles per quad of a (n_rows, n_cols) vertex grid (row-major), (F, 3) int64."""
    cols = n_cols if wrap_cols else n_cols - 1
    r, c = np.meshgrid(np.arange(n_rows - 1), np.arange(cols), indexing="ij")
    r, c = r.ravel(), c.ravel()
    c1 = (c + 1) % n_cols
    a, b, cc, d = r * n_cols + c, r * n_cols + c1, (r + 1) * n_cols + c1, (r + 1) * n_cols + c
    return np.concatenate([np.stack([a, b, cc], 1), np.stack([a, cc, d], 1)])


def signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Signed volume of a triangle mesh (positive when its faces wind counter-clockwise seen from outside)."""
    tri = V[F]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def orient_outward(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip all faces if the (closed-ish) surface has negative signed volume."""
    return F if signed_volume(V, F) >= 0 else F[:, ::-1].copy()


def weld_vertices(V: np.ndarray, F: np.ndarray, tol: float = 1e-7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge coincident vertices; drop triangles that became degenerate (returns V, F, kept-face mask)."""
    key = np.round(V / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    F = inverse.reshape(-1)[F]
    ok = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    return V[first], F[ok], ok


def cut_along_levels(V: np.ndarray, F: np.ndarray, N: np.ndarray, levels: np.ndarray, snap: float = 0.05,
                     zero_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cut a triangle mesh along the zero levels of per-vertex functions, so regions they bound have clean outlines.

    Each column of ``levels`` (V, L) is a function on the mesh, linear on every triangle; in turn along each
    column's zero level, every edge whose ends have opposite signs gets one vertex at the crossing (shared by
    the edge's triangles: a closed mesh stays closed) and every crossed triangle becomes three (two when the
    level passes through one of its vertices).  A crossing closer than ``snap`` x the edge's length to an end
    moves onto that end (its value becomes 0), so no slivers are made; so do values within ``zero_tol`` of 0
    (a vertex that lies on a level up to rounding is on it).  Positions do not change; new vertices
    get the linear interpolation of the normals and of every column's values (0 in the column cut).

    Args:
        V, F, N: (V, 3) positions, (F, 3) counter-clockwise faces, (V, 3) unit smooth normals.
        levels: (V, L) float64 values; a face's side of level k is the sign of its vertices' mean value.

    Returns:
        (V', F', N', levels' (V', L), parent (F',) index into ``F`` of the face each new face was cut from).
    """
    V, N, lv = np.asarray(V, np.float64), np.asarray(N, np.float64), np.array(levels, np.float64)
    lv = lv[:, None] if lv.ndim == 1 else lv
    F = np.asarray(F, np.int64)
    parent = np.arange(len(F))
    for k in range(lv.shape[1]):
        lv[np.abs(lv[:, k]) < zero_tol, k] = 0.0
        neg, pos = lv[:, k] < 0.0, lv[:, k] > 0.0
        # Only faces with values of both signs can have a crossed edge (both faces of one have).
        mixed = (neg[F[:, 0]] | neg[F[:, 1]] | neg[F[:, 2]]) & (pos[F[:, 0]] | pos[F[:, 1]] | pos[F[:, 2]])
        if not mixed.any():
            continue
        Fm, pm = F[mixed], parent[mixed]
        edges = np.sort(Fm[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        keys, inv = np.unique(edges[:, 0] * len(V) + edges[:, 1], return_inverse=True)  # 1-D keys: fast
        uniq = np.stack([keys // len(V), keys % len(V)], axis=1)
        inv = inv.reshape(-1, 3)  # face edge j joins its vertices j and j + 1
        fa, fb = lv[uniq[:, 0], k], lv[uniq[:, 1], k]
        cross = fa * fb < 0
        t = np.where(cross, fa / np.where(cross, fa - fb, 1.0), 0.0)
        # Snapping an end to 0 only removes crossings (an edge with a zero end has none); the others keep their t.
        lv[np.concatenate([uniq[cross & (t < snap), 0], uniq[cross & (t > 1.0 - snap), 1]]), k] = 0.0
        cross &= (lv[uniq[:, 0], k] != 0.0) & (lv[uniq[:, 1], k] != 0.0)
        ce = np.flatnonzero(cross)
        a, b, tc = uniq[ce, 0], uniq[ce, 1], t[ce][:, None]
        new_idx = np.full(len(uniq), -1, np.int64)
        new_idx[ce] = len(V) + np.arange(len(ce))
        n_new = N[a] + tc * (N[b] - N[a])
        N = np.concatenate([N, n_new / np.maximum(np.linalg.norm(n_new, axis=1, keepdims=True), 1e-12)])
        V = np.concatenate([V, V[a] + tc * (V[b] - V[a])])
        lv_new = lv[a] + tc * (lv[b] - lv[a])
        lv_new[:, k] = 0.0
        lv = np.concatenate([lv, lv_new])
        m = new_idx[inv]  # (mixed faces, 3) new vertex on each face edge, -1 where not crossed
        n_cross = (m >= 0).sum(axis=1)
        out_F, out_p = [F[~mixed], Fm[n_cross == 0]], [parent[~mixed], pm[n_cross == 0]]
        # Two crossed edges: the vertex between them (i) gets a triangle, the rest of the face a quad.
        two = np.flatnonzero(n_cross == 2)
        i = (np.argmin(m[two] >= 0, axis=1) + 2) % 3  # the edge not crossed is opposite vertex i
        va, vb, vc = Fm[two, i], Fm[two, (i + 1) % 3], Fm[two, (i + 2) % 3]
        m_ab, m_ca = m[two, i], m[two, (i + 2) % 3]
        out_F += [np.stack([va, m_ab, m_ca], 1), np.stack([m_ab, vb, vc], 1), np.stack([m_ab, vc, m_ca], 1)]
        out_p += [pm[two]] * 3
        # One crossed edge (j): the level runs from its crossing through the opposite vertex.
        one = np.flatnonzero(n_cross == 1)
        j = np.argmax(m[one] >= 0, axis=1)
        v0, v1, v2, mj = Fm[one, j], Fm[one, (j + 1) % 3], Fm[one, (j + 2) % 3], m[one, j]
        out_F += [np.stack([v0, mj, v2], 1), np.stack([mj, v1, v2], 1)]
        out_p += [pm[one]] * 2
        F, parent = np.concatenate(out_F), np.concatenate(out_p)
    return V, F, N, lv, parent


def box_mesh(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


__all__ = ["MeshPart", "box_mesh", "cut_along_levels", "grid_faces", "merge_parts", "orient_outward", "signed_volume",
           "target_wlh", "weld_vertices"]
