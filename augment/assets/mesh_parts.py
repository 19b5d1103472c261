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


__all__ = ["MeshPart", "box_mesh", "grid_faces", "merge_parts", "orient_outward", "signed_volume", "target_wlh",
           "weld_vertices"]
