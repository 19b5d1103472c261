"""Low-poly mesh primitives of the generated streets (street frame: x along the road, y left, z up, metres).

Each returns ``(vertices (V, 3) float64, triangles (F, 3) int)`` with outward counter-clockwise winding.
"""

from __future__ import annotations

import numpy as np

Mesh = tuple[np.ndarray, np.ndarray]  # (vertices (V, 3), triangles (F, 3))


def quad(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, p3: np.ndarray) -> Mesh:
    """A planar quad (counter-clockwise seen from its front side) as 4 vertices and 2 triangles."""
    return np.array([p0, p1, p2, p3], dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]])


def frustum(bottom_xy: np.ndarray, top_xy: np.ndarray, z0: float, z1: float, with_bottom: bool = False) -> Mesh:
    """A closed solid between two horizontal quads (each (4, 2), counter-clockwise seen from above).

    Returns vertices (8, 3) and triangles (10 or 12, 3) with outward counter-clockwise winding.
    """
    v = np.concatenate(
        [np.c_[bottom_xy, np.full(4, z0)], np.c_[top_xy, np.full(4, z1)]], axis=0
    )
    tris = [[4, 5, 6], [4, 6, 7]]  # top
    for i in range(4):
        j = (i + 1) % 4
        tris += [[i, j, 4 + j], [i, 4 + j, 4 + i]]
    if with_bottom:
        tris += [[0, 2, 1], [0, 3, 2]]
    return v, np.array(tris)


def rect_xy(cx: float, cy: float, length: float, width: float, yaw: float) -> np.ndarray:
    """Corners (4, 2) of a rectangle centred at (cx, cy), length along the yaw direction, CCW."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2, width / 2]
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def box_solid(cx: float, cy: float, length: float, width: float, z0: float, z1: float, yaw: float = 0.0,
              with_bottom: bool = False) -> Mesh:
    """A box standing on z0 (up to z1), centred at (cx, cy), length along ``yaw`` (see :func:`frustum`)."""
    r = rect_xy(cx, cy, length, width, yaw)
    return frustum(r, r, z0, z1, with_bottom)


def prism(cx: float, cy: float, radius: float, z0: float, z1: float, n: int = 8) -> Mesh:
    """Vertical n-gon cylinder, open at the bottom."""
    a = 2 * np.pi * np.arange(n) / n
    ring = np.c_[cx + radius * np.cos(a), cy + radius * np.sin(a)]
    v = np.concatenate([np.c_[ring, np.full(n, z0)], np.c_[ring, np.full(n, z1)], [[cx, cy, z1]]])
    tris = []
    for i in range(n):
        j = (i + 1) % n
        tris += [[i, j, n + j], [i, n + j, n + i], [n + i, n + j, 2 * n]]
    return v, np.array(tris)


def wheel_cylinder(cx: float, cy: float, cz: float, radius: float, width: float, n: int = 10) -> Mesh:
    """Cylinder with its axis along y (a wheel), closed at both ends."""
    a = 2 * np.pi * np.arange(n) / n
    xz = np.c_[cx + radius * np.cos(a), cz + radius * np.sin(a)]
    left = np.c_[xz[:, 0], np.full(n, cy + width / 2), xz[:, 1]]
    right = np.c_[xz[:, 0], np.full(n, cy - width / 2), xz[:, 1]]
    v = np.concatenate([left, right, [[cx, cy + width / 2, cz], [cx, cy - width / 2, cz]]])
    tris = []
    for i in range(n):
        j = (i + 1) % n
        tris += [[i, n + i, n + j], [i, n + j, j], [2 * n, j, i], [2 * n + 1, n + i, n + j]]
    return v, np.array(tris)


def icosphere(center: np.ndarray, radius: float, rng: np.random.Generator, subdiv: int = 1,
              jitter: float = 0.15) -> Mesh:
    """A lumpy low-poly sphere (tree crown): icosahedron subdivided ``subdiv`` times, radii jittered."""
    t = (1 + 5**0.5) / 2
    v = np.array(
        [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64
    )
    f = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    )
    for _ in range(subdiv):
        verts = list(v)
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                cache[key] = len(verts)
                verts.append((verts[a] + verts[b]) / 2)
            return cache[key]

        nf = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        v, f = np.array(verts), np.array(nf)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    v = v * (radius * (1 + jitter * rng.uniform(-1, 1, len(v))))[:, None]
    v[:, 2] *= 0.85
    return v + center, f


__all__ = ["Mesh", "box_solid", "frustum", "icosphere", "prism", "quad", "rect_xy", "wheel_cylinder"]
