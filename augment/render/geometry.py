"""An asset prepared for ray tracing: validated mesh, Embree scene, per-face data, material tables.

Built once per asset and kept in a small LRU cache (:func:`prepare_asset`), so repeated insertions
of the same asset in one process pay for the BVH only once.  Everything is in the object frame
(x front, y left, z up, metres).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..assets.asset import Asset, Material
from ..core import InputError
from ..core.raycast import RayScene

_CACHE: "OrderedDict[int, tuple[Asset, PreparedAsset]]" = OrderedDict()
_CACHE_SIZE = 16


@dataclass(frozen=True)
class PreparedAsset:
    """Ray-tracing view of an :class:`Asset`.

    Attributes:
        asset: the source asset.
        scene: Embree scene of the (non-degenerate) faces, object frame.
        faces: (F, 3) int64 faces kept (zero-area ones dropped).
        face_normal: (F, 3) float64 unit geometric normals (object frame).
        face_material: (F,) int64 material index per kept face.
        face_tangent, face_bitangent: (F, 3) unit dP/du and -dP/dv (glTF uv, v down) or None.
        base_color, emission: (M, 3) float64; metallic, roughness, specular, opacity, clearcoat: (M,).
        mean_albedo: area-weighted mean diffuse-plus-specular albedo (luminance) of the surface.
    """

    asset: Asset
    scene: RayScene
    faces: np.ndarray
    face_normal: np.ndarray
    face_material: np.ndarray
    face_tangent: np.ndarray | None
    face_bitangent: np.ndarray | None
    base_color: np.ndarray
    metallic: np.ndarray
    roughness: np.ndarray
    specular: np.ndarray
    opacity: np.ndarray
    clearcoat: np.ndarray
    emission: np.ndarray
    mean_albedo: float

    @property
    def materials(self) -> tuple[Material, ...]:
        return self.asset.materials

    @property
    def box_corners_object(self) -> np.ndarray:
        """(8, 3) corners of the axis-aligned box of the vertices (object frame)."""
        lo, hi = self.asset.vertices.min(axis=0), self.asset.vertices.max(axis=0)
        ix = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return np.where(ix == 0, lo, hi)


def renderable_faces(asset: Asset) -> np.ndarray:
    """Indices of the faces the renderer can use (a last guard for assets not built by the loader).

    Loaded and procedural assets are already cleaned by :func:`streetaug.augment.assets.validate.validate_asset`.

    Raises:
        InputError: no faces, non-finite vertices or normals, face indices out of range,
            material indices out of range, or every triangle of zero area.
    """
    V, F = asset.vertices, asset.faces
    if len(F) == 0:
        raise InputError(f"asset {asset.name!r}: has no faces; expected a triangle mesh")
    if not np.all(np.isfinite(V)):
        raise InputError(f"asset {asset.name!r}: vertices contain NaN or Inf")
    if not np.all(np.isfinite(asset.vertex_normals)):
        raise InputError(f"asset {asset.name!r}: vertex normals contain NaN or Inf")
    if F.min() < 0 or F.max() >= len(V):
        raise InputError(f"asset {asset.name!r}: face indices must be in [0, {len(V)}), got [{F.min()}, {F.max()}]")
    fm = asset.face_material
    if len(fm) and (fm.min() < 0 or fm.max() >= len(asset.materials)):
        raise InputError(f"asset {asset.name!r}: face_material must index its {len(asset.materials)} materials")
    tri = V[F]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    scale = max(float(np.ptp(V, axis=0).max()), 1e-12)
    keep = np.flatnonzero(area2 > 1e-12 * scale * scale)
    if len(keep) == 0:
        raise InputError(f"asset {asset.name!r}: all {len(F)} triangles have zero area")
    return keep


def prepare_asset(asset: Asset, backend: str = "embree") -> PreparedAsset:
    """The :class:`PreparedAsset` of ``asset`` (cached by identity; at most 16 kept)."""
    key = id(asset)
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is asset and hit[1].scene.backend == backend:
        _CACHE.move_to_end(key)
        return hit[1]
    prepared = _prepare(asset, backend)
    _CACHE[key] = (asset, prepared)
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return prepared


def _prepare(asset: Asset, backend: str) -> PreparedAsset:
    keep = renderable_faces(asset)
    V = np.asarray(asset.vertices, dtype=np.float64)
    F = np.asarray(asset.faces, dtype=np.int64)[keep]
    tri = V[F]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    cr = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    face_normal = cr / np.maximum(2 * area, 1e-30)[:, None]
    tangent = bitangent = None
    if asset.uv is not None and any(m.normal_texture is not None for m in asset.materials):
        uv = np.asarray(asset.uv, dtype=np.float64)[F]
        d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
        det = np.where(np.abs(det) < 1e-20, 1e-20, det)
        dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
        dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
        tangent = dpdu / np.maximum(np.linalg.norm(dpdu, axis=1, keepdims=True), 1e-20)
        bitangent = -dpdv / np.maximum(np.linalg.norm(dpdv, axis=1, keepdims=True), 1e-20)
    mats = asset.materials
    base = np.array([np.asarray(m.base_color, dtype=np.float64)[:3] for m in mats])
    metallic = np.array([m.metallic for m in mats], dtype=np.float64)
    roughness = np.array([m.roughness for m in mats], dtype=np.float64)
    specular = np.array([m.specular for m in mats], dtype=np.float64)
    opacity = np.array([m.opacity for m in mats], dtype=np.float64)
    clearcoat = np.array([m.clearcoat for m in mats], dtype=np.float64)
    emission = np.array([np.asarray(m.emission, dtype=np.float64)[:3] for m in mats])
    fm = np.asarray(asset.face_material, dtype=np.int64)[keep]
    lum = np.array([0.2126, 0.7152, 0.0722])
    albedo = (1 - metallic) * (base @ lum) + (1 - metallic) * 0.08 * specular + metallic * (base @ lum)
    mean_albedo = float((albedo[fm] * area).sum() / max(area.sum(), 1e-30))
    return PreparedAsset(
        asset=asset,
        scene=RayScene(V, F, backend=backend),
        faces=F,
        face_normal=face_normal,
        face_material=fm,
        face_tangent=tangent,
        face_bitangent=bitangent,
        base_color=base,
        metallic=metallic,
        roughness=roughness,
        specular=specular,
        opacity=opacity,
        clearcoat=clearcoat,
        emission=emission,
        mean_albedo=mean_albedo,
    )


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear, wrapping lookup of an (h, w, C) texture at glTF uv (N, 2) (v = 0 at the top row) -> (N, C)."""
    h, w = texture.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0m, x1m = np.mod(x0, w), np.mod(x0 + 1, w)
    y0m, y1m = np.mod(y0, h), np.mod(y0 + 1, h)
    t = texture
    return (t[y0m, x0m] * (1 - fx) + t[y0m, x1m] * fx) * (1 - fy) + (t[y1m, x0m] * (1 - fx) + t[y1m, x1m] * fx) * fy
