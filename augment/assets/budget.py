"""What an untrusted asset would cost, read before any mesh library decodes it: data URIs, texture sizes, triangles.

* glTF data URIs must be base64 (``data:<type>;base64,<payload>``) with a valid payload at least as long as
  the buffer's ``byteLength``; anything else is refused naming the file and the field (``buffers[0].uri``).
* Every texture's size is read from its header (a file URI, a data URI or a bufferView of the GLB / of a
  buffer) and refused above ``ResourceLimits.max_texture_pixels``; textures above ``max_texture_side`` are
  reduced while decoding (:func:`reduce_textures`: JPEG scaled by the decoder, others box-reduced as soon as
  decoded, before any float conversion or hashing).
* The triangle count comes from the accessor counts (glTF), the face lines (OBJ) or the header (PLY) and is
  refused above ``max_triangles``.

Limits come from :meth:`ResourceLimits.from_env` (the CLI's ``--max-*`` options set the variables).
"""

from __future__ import annotations

import base64
import binascii
import io
import re
import struct
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..core import InputError
from ..core.limits import (ResourceLimits, check_triangles, image_size_from_bytes, image_size_from_header,
                           texture_reduction)
from .references import check_reference

_DATA_URI = re.compile(r"^data:(?P<type>[^,;]*)(?P<params>(;[^,;]*)*?);base64,(?P<payload>.*)$", re.DOTALL)
_EXPECTED = "expected a base64 data URI (data:<type>;base64,<payload>)"
_REDUCIBLE_MODES = ("L", "LA", "RGB", "RGBA")
_TEXTURE_ATTRIBUTES = ("baseColorTexture", "metallicRoughnessTexture", "normalTexture", "emissiveTexture",
                       "occlusionTexture", "image")
_TRIANGLES_PER_INDEX = {4: lambda n: n // 3, 5: lambda n: max(n - 2, 0), 6: lambda n: max(n - 2, 0)}


def decode_data_uri(asset_path: Path, uri: str, field: str) -> bytes:
    """The bytes of a glTF data URI; refused (naming the file and ``field``) unless it is valid base64."""
    match = _DATA_URI.match(uri)
    if match is None:
        raise InputError(f"{asset_path}: {field} {_short(uri)} is not base64-encoded; {_EXPECTED}")
    try:
        return base64.b64decode(match["payload"].strip(), validate=True)
    except (binascii.Error, ValueError) as e:
        raise InputError(f"{asset_path}: {field}: the payload of {_short(uri)} is not valid base64 ({e}); "
                         f"{_EXPECTED}") from None


def glb_binary_chunk(data: bytes) -> bytes | None:
    """The BIN chunk of a GLB file (the bytes of its buffer without ``uri``), or None when it has none."""
    (json_len,) = struct.unpack_from("<I", data, 12)
    start = 20 + json_len
    if start + 8 > len(data):
        return None
    length, kind = struct.unpack_from("<I4s", data, start)
    return data[start + 8:start + 8 + length] if kind == b"BIN\x00" else None


def gltf_buffers(path: Path, gltf: dict, glb_bin: bytes | None, needed: set[int]) -> list[bytes | None]:
    """The bytes of ``buffers[i]``: every data URI decoded and checked, files read only when ``i`` is ``needed``.

    None for a file that is absent or not needed.
    """
    out: list[bytes | None] = []
    for i, buf in enumerate(_items(path, gltf, "buffers")):
        field = f"buffers[{i}].uri"
        uri = buf.get("uri")
        if uri is None:
            data = glb_bin
        elif uri.startswith("data:"):
            data = decode_data_uri(path, uri, field)
        else:
            target = check_reference(path, uri, field)
            data = target.read_bytes() if i in needed and target is not None and target.is_file() else None
        length = buf.get("byteLength")
        if data is not None and isinstance(length, int) and len(data) < length:
            raise InputError(f"{path}: buffers[{i}] has byteLength {length} but its data holds {len(data)} bytes")
        out.append(data)
    return out


def _image_bytes(path: Path, gltf: dict, image: dict, i: int, buffers: list[bytes | None]) -> bytes | None:
    """The encoded bytes of ``images[i]`` (only the header of a file is read)."""
    if "bufferView" in image:
        views = gltf.get("bufferViews", [])
        j = image["bufferView"]
        if not isinstance(j, int) or not 0 <= j < len(views) or not isinstance(views[j], dict):
            raise InputError(f"{path}: images[{i}].bufferView {j!r} is not one of the {len(views)} bufferViews")
        view = views[j]
        b = view.get("buffer")
        data = buffers[b] if isinstance(b, int) and 0 <= b < len(buffers) else None
        if data is None:
            return None
        offset = int(view.get("byteOffset", 0))
        return data[offset:offset + int(view.get("byteLength", 0))]
    uri = image.get("uri")
    if isinstance(uri, str) and uri.startswith("data:"):
        return decode_data_uri(path, uri, f"images[{i}].uri")
    return None


def check_gltf_budget(path: Path, gltf: dict, limits: ResourceLimits) -> None:
    """Refuse a glTF / GLB whose data URIs are not base64, whose textures or triangles exceed ``limits``."""
    glb_bin = glb_binary_chunk(path.read_bytes()) if path.suffix.lower() == ".glb" else None
    views = gltf.get("bufferViews", [])
    needed = {views[image["bufferView"]].get("buffer") for image in _items(path, gltf, "images")
              if isinstance(image.get("bufferView"), int) and 0 <= image["bufferView"] < len(views)
              and isinstance(views[image["bufferView"]], dict)}
    buffers = gltf_buffers(path, gltf, glb_bin, needed)
    for i, image in enumerate(_items(path, gltf, "images")):
        name = f"{path}: images[{i}]" + (f" {image['uri']!r}" if isinstance(image.get("uri"), str)
                                         and not image["uri"].startswith("data:") else "")
        uri = image.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:"):
            target = check_reference(path, uri, f"images[{i}].uri")
            size = image_size_from_header(target) if target is not None and target.is_file() else None
            if size is None and target is not None and target.is_file():
                size = _size_by_pillow(target.read_bytes())
        else:
            data = _image_bytes(path, gltf, image, i, buffers)
            size = None if data is None else (image_size_from_bytes(data) or _size_by_pillow(data))
        if size is not None:
            texture_reduction(size, name, limits)
    check_triangles(gltf_triangles(gltf), str(path), limits)


def gltf_triangles(gltf: dict) -> int:
    """Triangles the file's nodes instantiate, from the accessor counts (nothing decoded)."""
    accessors = gltf.get("accessors", [])
    meshes = gltf.get("meshes", [])

    def count(i: Any) -> int:
        ok = isinstance(i, int) and 0 <= i < len(accessors) and isinstance(accessors[i], dict)
        return int(accessors[i].get("count", 0)) if ok else 0

    def mesh_triangles(m: Any) -> int:
        if not isinstance(m, int) or not 0 <= m < len(meshes) or not isinstance(meshes[m], dict):
            return 0
        total = 0
        for prim in meshes[m].get("primitives", []):
            if not isinstance(prim, dict):
                continue
            per = _TRIANGLES_PER_INDEX.get(prim.get("mode", 4))
            if per is not None:
                n = count(prim["indices"]) if "indices" in prim else count(prim.get("attributes", {}).get("POSITION"))
                total += per(n)
        return total

    nodes = [n for n in gltf.get("nodes", []) if isinstance(n, dict) and "mesh" in n]
    if nodes:
        return sum(mesh_triangles(n["mesh"]) for n in nodes)
    return sum(mesh_triangles(m) for m in range(len(meshes)))


def check_obj_budget(path: Path, mtl: dict[str, dict], limits: ResourceLimits) -> None:
    """Refuse an OBJ whose face count or MTL textures exceed ``limits`` (sizes from the texture headers)."""
    data = path.read_bytes()
    faces = data.count(b"\nf ") + data.count(b"\nf\t") + int(data[:2] in (b"f ", b"f\t"))
    check_triangles(faces, str(path), limits)
    for material, entry in mtl.items():
        for key, ref in entry.items():
            if not isinstance(ref, str):
                continue
            target = check_reference(path, ref, f"material {material!r}: {key}")
            if target is not None and target.is_file():
                size = image_size_from_header(target) or _size_by_pillow(target.read_bytes())
                if size is not None:
                    texture_reduction(size, f"{path}: material {material!r} {key} {ref!r}", limits)


def check_ply_budget(path: Path, limits: ResourceLimits) -> None:
    """Refuse a PLY whose header declares more faces than ``limits.max_triangles``."""
    with open(path, "rb") as f:
        header = f.read(64 * 1024).split(b"end_header", 1)[0]
    for line in header.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == b"element" and parts[1] == b"face" and parts[2].isdigit():
            check_triangles(int(parts[2]), str(path), limits)


def reduce_textures(materials: Iterable[Any], path: Path, limits: ResourceLimits) -> None:
    """Replace, in the mesh library's materials, every texture above ``limits.max_texture_side`` by its reduction.

    Done right after the file is parsed (its images are opened lazily, nothing decoded yet) and before
    anything reads or hashes their pixels, so a large texture is decoded once, at 8 bits, and dropped.
    """
    reduced: dict[int, Any] = {}
    for mat in materials:
        for attr in _TEXTURE_ATTRIBUTES:
            image = getattr(mat, attr, None)
            if image is None or not hasattr(image, "reduce"):
                continue
            if id(image) not in reduced:
                name = getattr(mat, "name", None) or "material"
                reduced[id(image)] = reduced_image(image, f"{path}: {name} {attr}", limits)
            if reduced[id(image)] is not image:
                setattr(mat, attr, reduced[id(image)])


def reduced_image(image: Any, source: str, limits: ResourceLimits) -> Any:
    """A (lazily opened) PIL image reduced by :func:`texture_reduction`'s factor; ``image`` itself if 1.

    A JPEG is decoded at the reduced size (the decoder's DCT scaling); other formats are box-reduced right
    after decoding, before any conversion.
    """
    factor = texture_reduction(image.size, source, limits)
    if factor == 1:
        return image
    width, height = image.size
    image.draft("RGB", (max(1, width // factor), max(1, height // factor)))  # JPEG: reduced while decoding
    if image.mode not in _REDUCIBLE_MODES:
        image = image.convert("RGBA" if "transparency" in image.info else "RGB")
    rest = max(1, round(image.size[0] / max(1, width // factor)))
    return image.reduce(rest) if rest > 1 else image


def _size_by_pillow(data: bytes) -> tuple[int, int] | None:
    """(width, height) from the header of any format Pillow reads (opening is lazy: nothing is decoded)."""
    import PIL.Image  # deferred: only textures in formats the core's header reader does not know need it

    try:
        with PIL.Image.open(io.BytesIO(data)) as im:
            return im.size
    except Exception:  # noqa: BLE001 - not an image Pillow knows: the mesh library cannot decode it either
        return None


def _items(path: Path, gltf: dict, key: str) -> list[dict]:
    items = gltf.get(key, [])
    if not isinstance(items, list):
        raise InputError(f"{path}: glTF field {key!r} must be a list")
    return [item if isinstance(item, dict) else {} for item in items]


def _short(uri: str) -> str:
    return repr(uri if len(uri) <= 60 else uri[:57] + "...")


__all__ = ["check_gltf_budget", "check_obj_budget", "check_ply_budget", "decode_data_uri", "glb_binary_chunk",
           "gltf_buffers", "gltf_triangles", "reduce_textures", "reduced_image"]
