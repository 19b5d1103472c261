"""Load untrusted mesh files (glTF/GLB, OBJ+MTL, PLY) into :class:`Asset` objects.

Contract (``interfaces.md``): files are in metres with glTF axes (+Y up, the object's front +Z)
unless options say otherwise.  The result is in the object frame of :mod:`.asset` (x front,
y left, z up, metres, origin at the bottom centre of the box).

Safety: before any library sees a file, its external references are checked -- glTF
``buffers[].uri`` / ``images[].uri`` (also inside a GLB's JSON chunk), OBJ ``mtllib`` and MTL
texture paths -- and anything absolute, with a URL scheme other than ``data:``, or escaping the
asset's folder is refused with :class:`InputError`; so are files larger than 200 MB. Then what the file
would cost is read from its headers (:mod:`.budget`): data URIs must be valid base64, textures above
``ResourceLimits.max_texture_pixels`` and assets above ``max_triangles`` are refused, textures above
``max_texture_side`` are reduced before their pixels are converted (limits from ``STREETAUG_MAX_*``).

Materials: glTF PBR factors are read exactly from the file's JSON (baseColorFactor and
emissiveFactor are linear; ``alphaMode: BLEND`` alpha and ``KHR_materials_transmission`` become
opacity; clear coat, IOR / specular and emissive strength are read too: :func:`gltf_extension_factors`),
textures are converted to float32 (base colour sRGB -> linear).  OBJ: Kd (taken as
linear, as Blender writes it), Ns -> roughness, d / Tr -> opacity, Ke -> emission, Pr / Pm when
present.  PLY: vertex or face colours (sRGB) quantised into a few materials, else grey paint.
UVs are stored in the glTF convention (origin top-left, v down).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core import InputError
from ..core.limits import ResourceLimits, check_triangles
from .asset import Asset, Material
from .budget import check_gltf_budget, check_obj_budget, check_ply_budget, reduce_textures
from .categories import category_for_asset
from . import references
from .procedural import srgb_to_linear
from .references import check_gltf_references, check_obj_references, read_gltf_json
from .validate import smooth_vertex_normals, validate_asset

SUPPORTED_SUFFIXES = (".glb", ".gltf", ".obj", ".ply")
_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}
_CACHE_SIZE = 32

#: In-process cache: (resolved path, mtime_ns, size, options) -> Asset.  Bounded (oldest evicted).
asset_cache: dict[tuple, Asset] = {}


# ----------------------------------------------------------------------------- public API


def list_assets(directory: str | Path) -> list[Path]:
    """Asset files (``.glb``, ``.gltf``, ``.obj``, ``.ply``) directly in ``directory``, sorted by name.

    Raises:
        InputError: the folder does not exist or holds no asset file.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory}: asset folder not found")
    files = sorted(p for p in directory.iterdir() if p.is_file() and p.suffix.lower() in SUPPORTED_SUFFIXES)
    if not files:
        raise InputError(f"{directory}: no asset files ({', '.join(SUPPORTED_SUFFIXES)}) in this folder")
    return files


def axis_rotation(front_axis: str = "+z", up_axis: str = "+y") -> np.ndarray:
    """Rotation (3, 3) R_object_from_file: file front -> +x, file up -> +z, left = up x front -> +y.

    Raises:
        InputError: an axis is not one of +x, -x, +y, -y, +z, -z, or front and up are parallel.
    """
    vecs = []
    for name, axis in (("front_axis", front_axis), ("up_axis", up_axis)):
        key = str(axis).strip().lower()
        if key in ("x", "y", "z"):
            key = "+" + key
        if key not in _AXES:
            raise InputError(f"{name}: expected one of {', '.join(_AXES)}, got {axis!r}")
        i, sign = _AXES[key]
        v = np.zeros(3)
        v[i] = sign
        vecs.append(v)
    front, up = vecs
    if abs(front @ up) > 0.5:
        raise InputError(f"front_axis {front_axis!r} and up_axis {up_axis!r} must be perpendicular")
    left = np.cross(up, front)
    return np.stack([front, left, up])


def load_asset(
    path: str | Path,
    front_axis: str = "+z",
    up_axis: str = "+y",
    scale: float | None = None,
    length_m: float | None = None,
    category: str | None = None,
    use_cache: bool = True,
) -> Asset:
    """Load a mesh file as an :class:`Asset` in the object frame (x front, y left, z up, metres).

    Args:
        path: ``.glb``, ``.gltf``, ``.obj`` or ``.ply`` file (untrusted).
        front_axis: the file's axis the object's front points along (``+x`` ... ``-z``); the Kenney
            cars use ``-z``.
        up_axis: the file's up axis (glTF: ``+y``).
        scale: multiply file units by this to get metres (default 1).
        length_m: instead of ``scale``, rescale so the extent along the front axis is this length.
        category: nuScenes category (default: from the file name, see :mod:`streetaug.augment.assets.categories`).
        use_cache: reuse an earlier result for the same file (path, mtime, size) and options.

    Returns:
        The validated asset; origin at the bottom centre (min z = 0, x/y box centre = 0).

    Raises:
        InputError: missing / too large / unsupported / unsafe / broken file, bad options.
    """
    path = Path(path)
    if scale is not None and length_m is not None:
        raise InputError(f"{path}: give either scale or length_m, not both")
    for name, value in (("scale", scale), ("length_m", length_m)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise InputError(f"{path}: {name} must be a positive number, got {value!r}")
    R = axis_rotation(front_axis, up_axis)
    if not path.is_file():
        raise InputError(f"{path}: asset file not found")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise InputError(f"{path}: unsupported asset format {suffix!r}; "
                         f"expected one of {', '.join(SUPPORTED_SUFFIXES)}")
    st = path.stat()
    if st.st_size > references.MAX_FILE_BYTES:
        raise InputError(f"{path}: file is {st.st_size / 2**20:.0f} MB; assets larger than 200 MB are refused")
    limits = ResourceLimits.from_env()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size, str(front_axis), str(up_axis), scale, length_m, category,
           limits)
    if use_cache and key in asset_cache:
        return asset_cache[key]

    try:
        parts = _checked_parts(path, suffix, limits)
    except (OSError, SyntaxError) as e:  # a texture the mesh library opened lazily fails to decode (truncated...)
        raise InputError(f"{path}: could not decode a texture or part ({type(e).__name__}: {e})") from None
    if category is None:
        category = category_for_asset(path)
    check_triangles(sum(len(p.faces) for p in parts), str(path), limits)
    asset = _assemble(path, parts, R, scale, length_m, category)

    if use_cache:
        asset_cache[key] = asset
        while len(asset_cache) > _CACHE_SIZE:
            asset_cache.pop(next(iter(asset_cache)))
    return asset


# ----------------------------------------------------------------------------- format readers

@dataclass(frozen=True)
class FilePart:
    """One mesh of a file with its material, in the file's frame (before the object-frame rotation).

    Attributes:
        vertices: (V, 3) float64; ``faces`` (F, 3) int64; ``normals`` (V, 3) float64 or None (computed later).
        uv: (V, 2) float64 texture coordinates in the glTF convention (v down), or None.
        material: the part's material.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None
    uv: np.ndarray | None
    material: Material


def _checked_parts(path: Path, suffix: str, limits: ResourceLimits) -> list[FilePart]:
    """The file's parts, after its references, data URIs, texture sizes and triangle counts are checked."""
    if suffix in (".gltf", ".glb"):
        gltf = read_gltf_json(path)
        check_gltf_references(path, gltf)
        check_gltf_budget(path, gltf, limits)
        return _load_gltf_parts(path, gltf, limits)
    if suffix == ".obj":
        mtl = check_obj_references(path)
        check_obj_budget(path, mtl, limits)
        return _load_obj_parts(path, mtl, limits)
    check_ply_budget(path, limits)
    return _load_ply_parts(path, limits)


def _trimesh_load(path: Path):
    import trimesh  # heavy: deferred until a mesh file is read

    try:
        return trimesh.load(str(path), force="scene", process=False)
    except Exception as e:  # any parser error of a broken file is user input error
        raise InputError(f"{path}: could not read the mesh ({type(e).__name__}: {e})") from None


def _scene_meshes(path: Path, limits: ResourceLimits) -> list[tuple[np.ndarray, Any]]:
    """(T_file_from_mesh (4, 4), trimesh mesh) of every non-empty triangle mesh in the file's scene graph.

    Textures above ``limits.max_texture_side`` are reduced before anything reads their pixels.
    """
    import trimesh  # heavy: deferred until a mesh file is read

    scene = _trimesh_load(path)
    reduce_textures((getattr(getattr(g, "visual", None), "material", None) for g in scene.geometry.values()),
                    path, limits)
    out = []
    for node in scene.graph.nodes_geometry:
        T, geom_name = scene.graph[node]
        geom = scene.geometry[geom_name]
        if isinstance(geom, trimesh.Trimesh) and len(geom.faces) > 0:
            out.append((np.asarray(T, dtype=np.float64), geom))
    return out


def _load_gltf_parts(path: Path, gltf: dict, limits: ResourceLimits) -> list[FilePart]:
    exact = _gltf_materials_by_name(gltf)
    cache: dict[int, Material] = {}  # one Material per material object of this file's scene
    parts = []
    for T, geom in _scene_meshes(path, limits):
        mat_obj = getattr(geom.visual, "material", None)
        if id(mat_obj) not in cache:
            cache[id(mat_obj)] = _material_from_trimesh(mat_obj, exact, len(cache))
        parts.append(_transformed_part(geom, T, cache[id(mat_obj)]))
    return parts


def _gltf_materials_by_name(gltf: dict) -> dict[str, dict]:
    """Material JSON entries keyed by name (names that occur once only)."""
    mats = gltf.get("materials", [])
    names = [m.get("name") for m in mats if isinstance(m, dict)]
    return {m["name"]: m for m in mats if isinstance(m, dict) and m.get("name") and names.count(m["name"]) == 1}


def _transformed_part(geom: Any, T: np.ndarray, material: Material) -> FilePart:
    """A trimesh mesh moved by ``T`` (4, 4) (normals by its inverse transpose), uv flipped to v down."""
    V = np.asarray(geom.vertices, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    F = np.asarray(geom.faces, dtype=np.int64)
    normal_matrix = np.linalg.inv(T[:3, :3]).T
    N = np.asarray(geom.vertex_normals, dtype=np.float64) @ normal_matrix.T
    if np.linalg.det(T[:3, :3]) < 0:  # mirrored node: keep counter-clockwise = outward
        F = F[:, ::-1].copy()
    uv = getattr(geom.visual, "uv", None)
    if uv is not None and len(uv) == len(V):
        uv = np.asarray(uv, dtype=np.float64).copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # trimesh stores OpenGL (v up); assets keep the glTF convention
    else:
        uv = None
    return FilePart(V, F, N, uv, material)


_SRGB_TO_LINEAR_8BIT = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0).astype(np.float32)


def _texture(image, srgb: bool) -> np.ndarray | None:
    """float32 (H, W, 3) in [0, 1] of an 8-bit texture, linear when ``srgb`` (a 256-entry table: no float64 copies)."""
    if image is None:
        return None
    rgb = np.asarray(image.convert("RGB"))
    return _SRGB_TO_LINEAR_8BIT[rgb] if srgb else np.asarray(rgb, dtype=np.float32) / 255.0


# UE4's specular 0.5 is a dielectric reflectance F0 of 4 % (F0 = 0.08 specular): glTF's default (IOR 1.5).
UE4_F0_PER_SPECULAR = 0.08


def gltf_extension_factors(material_json: dict) -> dict[str, float]:
    """The PBR extensions of one glTF material entry that the renderer models, as factors.

    Read: ``KHR_materials_transmission`` (transmissionFactor -> ``transmission``, the renderer's glass is
    ``opacity = 1 - transmission``), ``KHR_materials_clearcoat`` (clearcoatFactor -> ``clearcoat``),
    ``KHR_materials_ior`` and ``KHR_materials_specular`` (the dielectric reflectance
    F0 = ((ior - 1) / (ior + 1))^2 x specularFactor x mean(specularColorFactor) -> UE4 ``specular`` = F0 / 0.08)
    and ``KHR_materials_emissive_strength`` (multiplies emissiveFactor).  Missing extensions give the
    glTF defaults (0, 0, IOR 1.5 -> specular 0.5, strength 1).  Their textures are not read (factors only).
    A value of the wrong type or range raises :class:`InputError` naming the extension and field.
    """
    ext = material_json.get("extensions", {}) if isinstance(material_json, dict) else {}
    if not isinstance(ext, dict):
        raise InputError(f"material {material_json.get('name')!r}: 'extensions' must be an object")

    def entry(name: str) -> dict:
        value = ext.get(name, {})
        if not isinstance(value, dict):
            raise InputError(f"material {material_json.get('name')!r}: {name} must be an object, got {value!r}")
        return value

    def factor(name: str, field_name: str, default: float, lo: float, hi: float) -> float:
        value = entry(name).get(field_name, default)
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise InputError(f"material {material_json.get('name')!r}: {name}.{field_name} must be a number, "
                             f"got {value!r}") from None
        if not (lo <= value <= hi):
            raise InputError(f"material {material_json.get('name')!r}: {name}.{field_name} must be in "
                             f"[{lo}, {hi}], got {value}")
        return value

    ior = factor("KHR_materials_ior", "ior", 1.5, 1.0, 10.0)
    spec_factor = factor("KHR_materials_specular", "specularFactor", 1.0, 0.0, 1.0)
    spec_colour = entry("KHR_materials_specular").get("specularColorFactor", [1.0, 1.0, 1.0])
    try:
        spec_colour_mean = float(np.mean(np.asarray(spec_colour, dtype=np.float64)[:3]))
    except (TypeError, ValueError):
        raise InputError(f"material {material_json.get('name')!r}: KHR_materials_specular.specularColorFactor "
                         f"must be 3 numbers, got {spec_colour!r}") from None
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 * spec_factor * spec_colour_mean
    return {
        "transmission": factor("KHR_materials_transmission", "transmissionFactor", 0.0, 0.0, 1.0),
        "clearcoat": factor("KHR_materials_clearcoat", "clearcoatFactor", 0.0, 0.0, 1.0),
        "specular": float(np.clip(f0 / UE4_F0_PER_SPECULAR, 0.0, 1.0)),
        "emissive_strength": factor("KHR_materials_emissive_strength", "emissiveStrength", 1.0, 0.0, 1e6),
    }


def _material_from_trimesh(mat, exact: dict[str, dict], index: int) -> Material:
    """Material of a trimesh visual: exact glTF factors when the JSON has them, else trimesh's."""
    from trimesh.visual.material import PBRMaterial, SimpleMaterial  # heavy: deferred until a mesh file is read

    name = getattr(mat, "name", None) or f"material{index}"
    if isinstance(mat, PBRMaterial):
        j = exact.get(name, {})
        pbr = j.get("pbrMetallicRoughness", {})
        if "baseColorFactor" in pbr:
            rgba = np.asarray(pbr["baseColorFactor"], dtype=np.float64)
        elif mat.baseColorFactor is not None:
            rgba = np.asarray(mat.baseColorFactor, dtype=np.float64) / 255.0
        else:
            rgba = np.ones(4)
        metallic = pbr.get("metallicFactor", mat.metallicFactor if mat.metallicFactor is not None else 1.0)
        roughness = pbr.get("roughnessFactor", mat.roughnessFactor if mat.roughnessFactor is not None else 1.0)
        emission = np.asarray(j.get("emissiveFactor", mat.emissiveFactor if mat.emissiveFactor is not None
                                    else np.zeros(3)), dtype=np.float64)
        alpha_mode = j.get("alphaMode", mat.alphaMode or "OPAQUE")
        opacity = float(rgba[3]) if len(rgba) > 3 and alpha_mode == "BLEND" else 1.0
        ext = gltf_extension_factors(j)
        opacity = min(opacity, 1.0 - ext["transmission"])
        return Material(
            name=name, base_color=np.clip(rgba[:3], 0, 1), metallic=float(np.clip(metallic, 0, 1)),
            roughness=float(np.clip(roughness, 0.02, 1)), opacity=float(np.clip(opacity, 0.02, 1)),
            emission=np.clip(emission[:3], 0, None) * ext["emissive_strength"],
            specular=ext["specular"], clearcoat=ext["clearcoat"],
            base_color_texture=_texture(mat.baseColorTexture, srgb=True),
            metallic_roughness_texture=_texture(mat.metallicRoughnessTexture, srgb=False),
            normal_texture=_texture(mat.normalTexture, srgb=False),
        )
    if isinstance(mat, SimpleMaterial):
        diffuse = np.asarray(mat.diffuse, dtype=np.float64)[:3] / 255.0
        return Material(name=name, base_color=diffuse, roughness=0.5,
                        base_color_texture=_texture(getattr(mat, "image", None), srgb=True))
    return _grey_paint(name)


def _grey_paint(name: str = "paint") -> Material:
    return Material(name=name, base_color=np.array([0.30, 0.30, 0.30]), metallic=0.0, roughness=0.4, clearcoat=1.0)


def _load_obj_parts(path: Path, mtl: dict[str, dict], limits: ResourceLimits) -> list[FilePart]:
    cache: dict[str, Material] = {}
    parts = []
    for T, geom in _scene_meshes(path, limits):
        mat_obj = getattr(geom.visual, "material", None)
        name = getattr(mat_obj, "name", None) or "default"
        if name not in cache:
            cache[name] = _material_from_mtl(name, mtl.get(name), mat_obj)
        parts.append(_transformed_part(geom, T, cache[name]))
    return parts


def _material_from_mtl(name: str, entry: dict | None, mat_obj) -> Material:
    """UE4 material from MTL values: Kd base colour, Ns -> roughness, d/Tr opacity, Ke emission, Pr/Pm."""
    if entry is None:
        return _material_from_trimesh(mat_obj, {}, 0) if mat_obj is not None else _grey_paint(name)
    kd = np.asarray(entry.get("kd", [0.6, 0.6, 0.6])[:3], dtype=np.float64)
    if len(kd) == 1:
        kd = np.repeat(kd, 3)
    if "pr" in entry:
        roughness = entry["pr"][0]
    else:
        ns = entry.get("ns", [50.0])[0]
        roughness = (2.0 / (max(ns, 0.0) + 2.0)) ** 0.25  # Blinn-Phong exponent -> GGX alpha -> roughness
    if "d" in entry:
        opacity = entry["d"][0]
    elif "tr" in entry:
        opacity = 1.0 - entry["tr"][0]
    else:
        opacity = 1.0
    metallic = entry.get("pm", [0.0])[0]
    ke = np.asarray(entry.get("ke", [0.0, 0.0, 0.0])[:3], dtype=np.float64)
    texture = _texture(getattr(mat_obj, "image", None), srgb=True) if "map_kd" in entry else None
    return Material(name=name, base_color=np.clip(kd, 0, 1), metallic=float(np.clip(metallic, 0, 1)),
                    roughness=float(np.clip(roughness, 0.02, 1)), opacity=float(np.clip(opacity, 0.02, 1)),
                    emission=np.clip(ke, 0, None), base_color_texture=texture)


def _load_ply_parts(path: Path, limits: ResourceLimits) -> list[FilePart]:
    import trimesh  # heavy: deferred until a mesh file is read

    parts = []
    for T, geom in _scene_meshes(path, limits):
        kind = getattr(geom.visual, "kind", None)
        if kind in ("vertex", "face"):
            if kind == "vertex":
                vc = np.asarray(geom.visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
                face_srgb = vc[np.asarray(geom.faces)].mean(axis=1)
            else:
                face_srgb = np.asarray(geom.visual.face_colors, dtype=np.float64)[:, :3] / 255.0
            # Quantise to at most ~64 colours, one material each.
            for levels in (32, 16, 8, 4):
                q = np.round(face_srgb * (levels - 1)).astype(np.int64)
                uniq, inverse = np.unique(q, axis=0, return_inverse=True)
                if len(uniq) <= 64:
                    break
            inverse = inverse.reshape(-1)
            for k, code in enumerate(uniq):
                sel = inverse == k
                color = srgb_to_linear(face_srgb[sel].mean(axis=0))
                sub = trimesh.Trimesh(geom.vertices, np.asarray(geom.faces)[sel], process=False)
                mat = Material(name=f"color{k}", base_color=color, roughness=0.5)
                moved = _transformed_part(sub, T, mat)
                parts.append(FilePart(moved.vertices, moved.faces, None, None, mat))
        else:
            parts.append(_transformed_part(geom, T, _grey_paint()))
    return parts


# ----------------------------------------------------------------------------- assembly


def _assemble(path: Path, parts: list[FilePart], R: np.ndarray, scale: float | None, length_m: float | None,
              category: str) -> Asset:
    """Merge parts, rotate into the object frame, scale, recentre (bottom centre) and validate."""
    if not parts:
        raise InputError(f"{path}: the file has no faces; expected a triangle mesh")
    materials: list[Material] = []
    mat_index: dict[int, int] = {}
    V_list, F_list, N_list, uv_list, fm_list = [], [], [], [], []
    offset = 0
    any_uv = any(p.uv is not None for p in parts)
    for part in parts:
        V, F, N, uv, mat = part.vertices, part.faces, part.normals, part.uv, part.material
        if id(mat) not in mat_index:
            mat_index[id(mat)] = len(materials)
            materials.append(mat)
        if N is None or N.shape != V.shape or not np.isfinite(N).all():
            N = smooth_vertex_normals(V, F) if len(F) and np.isfinite(V).all() else np.zeros_like(V)
        V_list.append(V)
        F_list.append(F + offset)
        N_list.append(N)
        uv_list.append(uv if uv is not None else np.zeros((len(V), 2)))
        fm_list.append(np.full(len(F), mat_index[id(mat)], dtype=np.int64))
        offset += len(V)
    V = np.concatenate(V_list) @ R.T
    N = np.concatenate(N_list) @ R.T
    F = np.concatenate(F_list)
    if not np.isfinite(V).all():
        bad = int((~np.isfinite(V).all(axis=1)).sum())
        raise InputError(f"{path}: {bad} vertices contain NaN or Inf")
    # Only vertices used by faces define the box.
    used = np.unique(F)
    if len(used) == 0 or used.max() >= len(V):
        raise InputError(f"{path}: face indices out of range")
    lo, hi = V[used].min(axis=0), V[used].max(axis=0)
    if length_m is not None:
        length = hi[0] - lo[0]
        if length <= 0:
            raise InputError(f"{path}: zero extent along the front axis; cannot rescale to length_m")
        s = length_m / length
    else:
        s = 1.0 if scale is None else float(scale)
    V = (V - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) * s
    asset = Asset(
        name=path.name, vertices=V, faces=F, face_material=np.concatenate(fm_list), materials=tuple(materials),
        vertex_normals=N, uv=np.concatenate(uv_list) if any_uv else None, category=category,
    )
    try:
        return validate_asset(asset)
    except InputError as e:
        raise InputError(f"{path}: {e}") from None
