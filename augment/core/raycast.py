"""Ray casting against triangle meshes: one interface, an Embree backend and a numpy reference.

Both backends take rays as arrays (N, 3) in the mesh's frame and return a :class:`RayHits`.
Embree (through ``embreex``) holds the GIL: parallelise with processes, and pass large batches.
The numpy backend is brute force (O(N x F)) and exists to test the Embree backend on tiny meshes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import check_shape


@dataclass(frozen=True)
class RayHits:
    """Closest hits of N rays.

    Attributes:
        hit: (N,) bool, whether the ray hit a triangle.
        t: (N,) float64 distance along the (unit) ray direction, inf where no hit.
        face: (N,) int64 index of the hit triangle, -1 where no hit.
        bary: (N, 2) float64 barycentric (u, v) of the hit: p = (1-u-v) v0 + u v1 + v v2.
    """

    hit: np.ndarray
    t: np.ndarray
    face: np.ndarray
    bary: np.ndarray


class RayScene:
    """A static triangle mesh ready for ray queries.

    Args:
        vertices: (V, 3) float vertex positions.
        faces: (F, 3) int vertex indices.
        backend: ``"embree"`` (fast) or ``"numpy"`` (brute-force reference, tiny meshes only).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, backend: str = "embree") -> None:
        check_shape(vertices, ("V", 3), "vertices")
        check_shape(faces, ("F", 3), "faces")
        if len(faces) == 0:
            raise ValueError("cannot build a ray scene from a mesh with no faces")
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.backend = backend
        if backend == "embree":
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh

            self._scene = rtcore_scene.EmbreeScene()
            # The scene keeps a reference; keep one too so the buffers outlive the scene.
            self._mesh = TriangleMesh(
                self._scene, self.vertices.astype(np.float32), self.faces.astype(np.int32)
            )
        elif backend != "numpy":
            raise ValueError(f"unknown ray backend {backend!r}; expected 'embree' or 'numpy'")

    def intersect(self, origins: np.ndarray, directions: np.ndarray, t_min: float = 0.0) -> RayHits:
        """Closest hit along each ray (directions need not be unit; t is in units of |direction|)."""
        origins, directions = _check_rays(origins, directions)
        if self.backend == "numpy":
            return _intersect_numpy(self.vertices, self.faces, origins, directions, t_min)
        start = origins + directions * t_min
        out = self._scene.run(start.astype(np.float32), directions.astype(np.float32), output=1)
        face = out["primID"].astype(np.int64)
        hit = out["geomID"] >= 0
        face[~hit] = -1
        t = np.where(hit, out["tfar"].astype(np.float64) + t_min, np.inf)
        bary = np.stack([out["u"], out["v"]], axis=1).astype(np.float64)
        return RayHits(hit=hit, t=t, face=face, bary=bary)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max: float | np.ndarray = np.inf) -> np.ndarray:
        """(N,) bool: does the ray hit anything with 0 < t < t_max?"""
        origins, directions = _check_rays(origins, directions)
        if self.backend == "numpy" or np.any(np.isfinite(t_max)):
            hits = self.intersect(origins, directions)
            return hits.hit & (hits.t < t_max)
        out = self._scene.run(origins.astype(np.float32), directions.astype(np.float32), query="OCCLUDED")
        return out >= 0

    def hit_points(self, hits: RayHits) -> np.ndarray:
        """World positions (N, 3) of hits (garbage where ``hits.hit`` is False)."""
        tri = self.vertices[self.faces[np.maximum(hits.face, 0)]]  # (N, 3, 3)
        u, v = hits.bary[:, :1], hits.bary[:, 1:]
        return (1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2]


def _check_rays(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    check_shape(origins, ("N", 3), "ray origins")
    check_shape(directions, (len(origins), 3), "ray directions")
    return origins, directions


def _intersect_numpy(
    vertices: np.ndarray, faces: np.ndarray, origins: np.ndarray, directions: np.ndarray, t_min: float
) -> RayHits:
    """Moller-Trumbore against every triangle (reference implementation)."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))  # (F, 3)
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(directions[:, None, :], e2[None])  # (N, F, 3)
    det = np.einsum("fk,nfk->nf", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origins[:, None, :] - v0[None]
        u = np.einsum("nfk,nfk->nf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("nk,nfk->nf", directions, q) * inv
        t = np.einsum("fk,nfk->nf", e2, q) * inv
    ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > t_min)
    t = np.where(ok, t, np.inf)
    face = np.argmin(t, axis=1)
    rows = np.arange(len(origins))
    t_best = t[rows, face]
    hit = np.isfinite(t_best)
    bary = np.stack([u[rows, face], v[rows, face]], axis=1)
    bary[~hit] = 0.0
    return RayHits(hit=hit, t=t_best, face=np.where(hit, face, -1), bary=bary)
