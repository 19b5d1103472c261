"""The surface of the object: the asset prepared for ray tracing, and what is at a ray hit.

The bottom of the renderer's chain (surface -> bounce -> shadow -> foreground -> composite): every
later stage traces rays against a :class:`PreparedAsset` and reads its hits with :func:`surface_at_hits`.

* :func:`prepare_asset`: validated mesh, Embree scene, per-face data, material tables; built once per
  asset and kept on the asset itself (:meth:`streetaug.augment.assets.asset.Asset.derived`), so repeated
  insertions of the same asset pay for the BVH only once.
* :func:`surface_at_hits`: a :class:`SurfaceHits` (normals, material, BRDF parameters with textures
  applied) at ray hits, the renderer's G-buffer.

Everything is in the object frame (x front, y left, z up, metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..assets.asset import Asset, Material
from ..core import InputError, luminance
from ..core.raycast import RayScene
from .brdf import BRDFParams, row_norm


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
        retroreflective: (M,) retro-reflective strength per material, or None when no material has any.
        flake: (M,) metallic-flake share of the diffuse lobe per material, or None when no material has any.
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
    retroreflective: np.ndarray | None = None
    flake: np.ndarray | None = None

    @property
    def materials(self) -> tuple[Material, ...]:
        return self.asset.materials

    @property
    def box_corners_object(self) -> np.ndarray:
        """(8, 3) corners of the axis-aligned box of the vertices (object frame)."""
        return box_corners_object(self.asset)


def box_corners_object(asset: Asset) -> np.ndarray:
    """(8, 3) float64 corners of the axis-aligned box of the asset's vertices (object frame, metres)."""
    lo, hi = asset.vertices.min(axis=0), asset.vertices.max(axis=0)
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
    """The :class:`PreparedAsset` of ``asset``, built on the first call and kept on the asset."""
    return asset.derived(f"render.prepared.{backend}", lambda a: _prepare(a, backend))


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
    retro = np.array([float(getattr(m, "retroreflective", 0.0)) for m in mats], dtype=np.float64)
    flake = np.clip(np.array([float(getattr(m, "flake", 0.0)) for m in mats], dtype=np.float64), 0.0, 1.0)
    fm = np.asarray(asset.face_material, dtype=np.int64)[keep]
    base_lum = luminance(base)
    albedo = (1 - metallic) * base_lum + (1 - metallic) * 0.08 * specular + metallic * base_lum
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
        retroreflective=retro if np.any(retro > 0) else None,
        flake=flake if np.any(flake > 0) else None,
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


@dataclass(frozen=True)
class SurfaceHits:
    """What is at N ray hits on the object (object frame): the renderer's G-buffer.

    Attributes:
        normal: (N, 3) float64 unit shading normal (smooth, normal-mapped), on the ray origin's side.
        geometric_normal: (N, 3) float64 unit face normal, turned towards the ray's origin.
        front: (N,) bool, the ray hit the outer side of the face (its stored normal faces the ray's origin).
        material: (N,) int64 material index of the hit face.
        params: (N) BRDF parameters, textures (base colour, metallic-roughness) applied.
        opacity: (N,) float64 material opacity (1 opaque, < 1 glass).
        emission: (N, 3) float64 emitted radiance.
    """

    normal: np.ndarray
    geometric_normal: np.ndarray
    front: np.ndarray
    material: np.ndarray
    params: BRDFParams
    opacity: np.ndarray
    emission: np.ndarray


def surface_at_hits(prep: PreparedAsset, face: np.ndarray, bary: np.ndarray, dirs: np.ndarray) -> SurfaceHits:
    """The surface at ray hits (object frame), textures (base colour, metallic-roughness, normal map) applied.

    Args:
        prep: the prepared asset the rays hit.
        face: (N,) int64 index into ``prep.faces``.
        bary: (N, 2) float64 barycentrics (u, v) of the hits (weights of the face's 2nd and 3rd vertex).
        dirs: (N, 3) float64 unit ray directions.
    """
    asset = prep.asset
    f = prep.faces[face]
    u, v = bary[:, :1], bary[:, 1:]
    w0 = 1.0 - u - v
    vn = asset.vertex_normals
    n_s = w0 * vn[f[:, 0]] + u * vn[f[:, 1]] + v * vn[f[:, 2]]
    n_g = prep.face_normal[face]
    front = np.einsum("ij,ij->i", dirs, n_g) < 0.0
    n_g = np.where(front[:, None], n_g, -n_g)
    # Smooth normal on the viewer's side of the geometry.
    n_s = np.where((np.einsum("ij,ij->i", n_s, n_g) < 0.0)[:, None], -n_s, n_s)
    n_s /= np.maximum(row_norm(n_s)[:, None], 1e-12)
    bad = ~np.isfinite(n_s).all(axis=1) | (row_norm(n_s) < 0.5)
    n_s[bad] = n_g[bad]
    mid = prep.face_material[face]
    base = prep.base_color[mid].copy()
    metallic = prep.metallic[mid].copy()
    rough = prep.roughness[mid].copy()
    if asset.uv is not None:
        uvs = asset.uv[f]
        uv = w0 * uvs[:, 0] + u * uvs[:, 1] + v * uvs[:, 2]
        _apply_textures(prep, face, mid, uv, n_s, base, metallic, rough)
    # Keep the shading normal within the viewer's hemisphere (avoids black rims on smoothed meshes).
    view = -dirs
    nv = np.einsum("ij,ij->i", n_s, view)
    fix = nv < 0.02
    if np.any(fix):
        n_s[fix] += view[fix] * (0.02 - nv[fix])[:, None]
        n_s[fix] /= row_norm(n_s[fix])[:, None]
    retro = None if prep.retroreflective is None else prep.retroreflective[mid]
    flake = None if prep.flake is None else prep.flake[mid]
    params = BRDFParams(base, np.clip(metallic, 0, 1), np.clip(rough, 0, 1), prep.specular[mid], prep.clearcoat[mid],
                        retro, flake)
    return SurfaceHits(n_s, n_g, front, mid, params, prep.opacity[mid], prep.emission[mid])


def _apply_textures(prep: PreparedAsset, face: np.ndarray, mid: np.ndarray, uv: np.ndarray, n_s: np.ndarray,
                    base: np.ndarray, metallic: np.ndarray, rough: np.ndarray) -> None:
    """Multiply the hits' material values by their textures at ``uv`` (N, 2) and normal-map ``n_s``, in place."""
    for m_index, mat in enumerate(prep.asset.materials):
        sel = np.flatnonzero(mid == m_index)
        if len(sel) == 0:
            continue
        if mat.base_color_texture is not None:
            base[sel] *= sample_texture(mat.base_color_texture, uv[sel])[:, :3]
        if mat.metallic_roughness_texture is not None:
            mr = sample_texture(mat.metallic_roughness_texture, uv[sel])
            rough[sel] *= mr[:, 1]
            metallic[sel] *= mr[:, 2]
        if mat.normal_texture is not None and prep.face_tangent is not None:
            t_n = sample_texture(mat.normal_texture, uv[sel]) * 2.0 - 1.0
            T = prep.face_tangent[face[sel]]
            B = prep.face_bitangent[face[sel]]
            ns = n_s[sel]
            T = T - np.einsum("ij,ij->i", T, ns)[:, None] * ns
            T /= np.maximum(row_norm(T)[:, None], 1e-12)
            B = B - np.einsum("ij,ij->i", B, ns)[:, None] * ns - np.einsum("ij,ij->i", B, T)[:, None] * T
            B /= np.maximum(row_norm(B)[:, None], 1e-12)
            nm = t_n[:, :1] * T + t_n[:, 1:2] * B + t_n[:, 2:3] * ns
            nm /= np.maximum(row_norm(nm)[:, None], 1e-12)
            n_s[sel] = np.where(np.isfinite(nm).all(axis=1, keepdims=True), nm, ns)
