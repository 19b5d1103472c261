"""Untrusted asset files: their external references checked before any library opens them.

glTF ``buffers[].uri`` / ``images[].uri`` (also inside a GLB's JSON chunk), OBJ ``mtllib`` and MTL
texture paths that are absolute, carry a URL scheme other than ``data:``, or escape the asset's folder
are refused with :class:`InputError`; so are files larger than :data:`MAX_FILE_BYTES` (200 MB).
"""

from __future__ import annotations

import json
import os
import re
import struct
import urllib.parse
from pathlib import Path

from ..core import InputError

MAX_FILE_BYTES = 200 * 1024 * 1024

_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.\-]*:")


def check_reference(asset_path: Path, ref: str, field: str) -> Path | None:
    """Check one external reference of ``asset_path``; return the local file it names (None for data:).

    Raises:
        InputError: ``ref`` is absolute, has a URL scheme other than ``data:``, or escapes the
            asset's folder (``..``, symlinks).  The message names the file, the field and the URI.
    """
    if not isinstance(ref, str) or not ref:
        raise InputError(f"{asset_path}: {field} must be a non-empty string, got {ref!r}")
    if ref.startswith("data:"):
        return None
    if _SCHEME.match(ref):
        raise InputError(f"{asset_path}: {field} {ref!r} has a URL scheme; only relative paths inside the "
                         f"asset's folder or data: URIs are allowed")
    decoded = urllib.parse.unquote(ref).replace("\\", "/")
    if decoded.startswith("/") or _SCHEME.match(decoded) or os.path.isabs(decoded):
        raise InputError(f"{asset_path}: {field} {ref!r} is an absolute path; only relative paths inside the "
                         f"asset's folder are allowed")
    folder = asset_path.parent.resolve()
    target = (folder / decoded).resolve()
    try:
        target.relative_to(folder)
    except ValueError:
        raise InputError(f"{asset_path}: {field} {ref!r} points outside the asset's folder {folder}") from None
    return target


def read_gltf_json(path: Path) -> dict:
    """The glTF JSON of a ``.gltf`` file or of a ``.glb``'s JSON chunk (no library involved)."""
    data = path.read_bytes()
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise InputError(f"{path}: not a binary glTF file (missing 'glTF' magic)")
        version, total = struct.unpack_from("<II", data, 4)
        chunk_len, chunk_type = struct.unpack_from("<I4s", data, 12)
        if version != 2 or chunk_type != b"JSON" or 20 + chunk_len > len(data) or total > len(data):
            raise InputError(f"{path}: malformed GLB header (version {version}, first chunk {chunk_type!r}); "
                             f"expected glTF 2.0 with a JSON chunk")
        text = data[20:20 + chunk_len]
    else:
        text = data
    try:
        gltf = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"{path}: glTF JSON is not valid ({e})") from None
    if not isinstance(gltf, dict):
        raise InputError(f"{path}: glTF JSON must be an object")
    return gltf


def check_gltf_references(path: Path, gltf: dict) -> None:
    """Refuse unsafe ``buffers[].uri`` / ``images[].uri`` of a glTF document (see :func:`check_reference`)."""
    for key in ("buffers", "images"):
        items = gltf.get(key, [])
        if not isinstance(items, list):
            raise InputError(f"{path}: glTF field {key!r} must be a list")
        for i, item in enumerate(items):
            if isinstance(item, dict) and "uri" in item:
                target = check_reference(path, item["uri"], f"{key}[{i}].uri")
                if target is not None and target.is_file() and target.stat().st_size > MAX_FILE_BYTES:
                    raise InputError(f"{path}: {key}[{i}].uri {item['uri']!r} is larger than 200 MB; refused")


def check_obj_references(path: Path) -> dict[str, dict]:
    """Check the ``mtllib`` files of an OBJ and the texture paths inside them; return parsed MTL materials."""
    materials: dict[str, dict] = {}
    with open(path, "r", errors="replace") as f:
        for line in f:
            if line.startswith("mtllib"):
                for ref in line.split()[1:]:
                    mtl_path = check_reference(path, ref, "mtllib")
                    if mtl_path is not None and mtl_path.is_file():
                        materials.update(parse_mtl(path, mtl_path))
    return materials


_MTL_MAPS = ("map_ka", "map_kd", "map_ks", "map_ns", "map_d", "map_bump", "bump", "disp", "decal", "refl",
             "map_pr", "map_pm", "map_ke", "norm", "map_kn")


def parse_mtl(obj_path: Path, mtl_path: Path) -> dict[str, dict]:
    """Parse an MTL file into {material name: {key: values}}; texture paths are checked."""
    out: dict[str, dict] = {}
    cur: dict | None = None
    with open(mtl_path, "r", errors="replace") as f:
        for line in f:
            tok = line.strip().split()
            if not tok or tok[0].startswith("#"):
                continue
            key = tok[0].lower()
            if key == "newmtl":
                cur = out.setdefault(" ".join(tok[1:]), {})
            elif key in _MTL_MAPS:
                check_reference(obj_path, tok[-1], f"{mtl_path.name}: {tok[0]}")
                if cur is not None:
                    cur[key] = tok[-1]
            elif cur is not None:
                try:
                    cur[key] = [float(t) for t in tok[1:]]
                except ValueError:
                    pass
    return out


__all__ = ["MAX_FILE_BYTES", "check_gltf_references", "check_obj_references", "check_reference", "parse_mtl",
           "read_gltf_json"]
