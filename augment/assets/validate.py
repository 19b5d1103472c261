"""Mesh checks for assets: reject broken meshes with a clear error, repair what is safe to repair.

:func:`validate_asset` is called by the loader and by the procedural generator.  It raises
:class:`~streetaug.augment.core.InputError` (naming the asset) for meshes that cannot be rendered and
returns a cleaned copy otherwise: zero-area / repeated-index triangles dropped, missing or zero
vertex normals recomputed.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from ..core import InputError
from .asset import Asset

log = logging.getLogger(__name__)

# A triangle counts as degenerate when twice its area is below this fraction of (mesh size)^2.
_AREA_EPS_REL = 1e-12


@dataclass(frozen=True)
class ValidationReport:
    """What :func:`validate_asset` changed.

    Attributes:
        dropped_degenerate: number of zero-area or repeated-index triangles removed.
        repaired_normals: number of vertex normals recomputed (missing, zero or non-finite).
    """

    dropped_degenerate: int = 0
    repaired_normals: int = 0


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit geometric normals (F, 3) float64 and areas (F,) of triangles (counter-clockwise = outward)."""
    tri = np.asarray(vertices, dtype=np.float64)[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(norm, 1e-300)[:, None], 0.5 * norm


def smooth_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted smooth normals (V, 3) float64 of a triangle mesh; unreferenced vertices get +z.

    Args:
        vertices: (V, 3) positions.
        faces: (F, 3) int vertex indices.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    tri = V[F]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    acc = np.zeros_like(V)
    for k in range(3):
        np.add.at(acc, F[:, k], cross)
    return _normalise_or(acc, np.array([0.0, 0.0, 1.0]))


def _normalise_or(vectors: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=1, keepdims=True)
    ok = np.isfinite(norm) & (norm > 1e-20)
    return np.where(ok, vectors / np.where(ok, norm, 1.0), fallback)


def validate_asset_report(asset: Asset) -> tuple[Asset, ValidationReport]:
    """Validate ``asset``; return the cleaned asset and a :class:`ValidationReport`.

    Raises:
        InputError: no faces, NaN/Inf vertices, face or material indices out of range, no
            materials, a bad uv array, or no triangle of non-zero area.  Messages name the asset.
    """
    name = asset.name
    V = np.asarray(asset.vertices, dtype=np.float64)
    F = np.asarray(asset.faces)
    if len(V) == 0 or len(F) == 0:
        raise InputError(f"asset {name!r}: has no faces ({len(V)} vertices, {len(F)} faces); expected a triangle mesh")
    if not np.issubdtype(F.dtype, np.integer):
        raise InputError(f"asset {name!r}: faces must be integer vertex indices, got dtype {F.dtype}")
    F = F.astype(np.int64)
    bad = ~np.isfinite(V).all(axis=1)
    if bad.any():
        raise InputError(f"asset {name!r}: {int(bad.sum())} of {len(V)} vertices contain NaN or Inf")
    if F.min() < 0 or F.max() >= len(V):
        raise InputError(f"asset {name!r}: face indices must be in [0, {len(V)}), got [{F.min()}, {F.max()}]")
    if len(asset.materials) == 0:
        raise InputError(f"asset {name!r}: has no materials; expected at least one")
    fm = np.asarray(asset.face_material).astype(np.int64)
    if fm.min() < 0 or fm.max() >= len(asset.materials):
        raise InputError(f"asset {name!r}: face_material must index its {len(asset.materials)} materials, "
                         f"got [{fm.min()}, {fm.max()}]")
    uv = asset.uv
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (len(V), 2) or not np.isfinite(uv).all():
            raise InputError(f"asset {name!r}: uv must be a finite ({len(V)}, 2) array, got shape {uv.shape}")

    # Degenerate triangles: repeated indices or (relative) zero area.
    _, area = face_normals(V, F)
    size = max(float(np.ptp(V, axis=0).max()), 1e-12)
    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    keep = ~repeated & (2.0 * area > _AREA_EPS_REL * size * size)
    n_drop = int((~keep).sum())
    if not keep.any():
        raise InputError(f"asset {name!r}: all {len(F)} triangles have zero area")
    if n_drop:
        log.info("asset %r: dropped %d degenerate (zero-area) triangles of %d", name, n_drop, len(F))
    F, fm = F[keep], fm[keep]

    # Normals: recompute where missing, zero or non-finite.
    N = np.asarray(asset.vertex_normals, dtype=np.float64)
    smooth = smooth_vertex_normals(V, F)
    if N.shape != V.shape:
        N, n_fix = smooth, len(V)
    else:
        norm = np.linalg.norm(N, axis=1)
        bad_n = ~np.isfinite(norm) | (norm < 1e-8)
        n_fix = int(bad_n.sum())
        N = np.where(bad_n[:, None], smooth, N / np.where(bad_n, 1.0, norm)[:, None])

    cleaned = dataclasses.replace(asset, vertices=V, faces=F, face_material=fm, vertex_normals=N, uv=uv)
    return cleaned, ValidationReport(dropped_degenerate=n_drop, repaired_normals=n_fix)


def validate_asset(asset: Asset) -> Asset:
    """Validate ``asset`` and return a cleaned copy (see :func:`validate_asset_report`).

    Raises:
        InputError: the mesh cannot be rendered (message names the asset).
    """
    return validate_asset_report(asset)[0]
