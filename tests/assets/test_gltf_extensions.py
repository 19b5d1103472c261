"""User glTF assets keep the PBR extensions the renderer models (issue 20: user assets first-class)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.assets.loader import gltf_extension_factors, load_asset
from streetaug.augment.core import InputError


def _write_triangle_gltf(folder: Path, material: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "tri.bin").write_bytes(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], np.float32).tobytes())
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [material],
        "buffers": [{"byteLength": 36, "uri": "tri.bin"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0.5]}],
    }
    path = folder / "tri.gltf"
    path.write_text(json.dumps(doc))
    return path


def test_defaults_are_the_plain_gltf_material():
    assert gltf_extension_factors({"name": "m"}) == pytest.approx(
        {"transmission": 0.0, "clearcoat": 0.0, "specular": 0.5, "emissive_strength": 1.0})


def test_clearcoat_transmission_ior_and_emissive_strength_reach_the_material(tmp_path):
    material = {"name": "paint", "emissiveFactor": [0.1, 0.0, 0.0],
                "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.1, 0.1, 1.0], "metallicFactor": 0.3,
                                         "roughnessFactor": 0.4},
                "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.8},
                               "KHR_materials_ior": {"ior": 1.6},
                               "KHR_materials_emissive_strength": {"emissiveStrength": 5.0}}}
    paint = load_asset(_write_triangle_gltf(tmp_path / "a", material)).materials[0]
    assert paint.clearcoat == pytest.approx(0.8)
    assert paint.specular == pytest.approx((0.6 / 2.6) ** 2 / 0.08)  # F0 of IOR 1.6
    assert np.allclose(paint.emission, [0.5, 0.0, 0.0])
    assert paint.opacity == 1.0

    glass = {"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1.0],
                                                       "metallicFactor": 0.0, "roughnessFactor": 0.05},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.9},
                            "KHR_materials_specular": {"specularFactor": 0.5}}}
    g = load_asset(_write_triangle_gltf(tmp_path / "b", glass)).materials[0]
    assert g.opacity == pytest.approx(0.1) and g.specular == pytest.approx(0.25)


@pytest.mark.parametrize("ext, message", [
    ({"KHR_materials_clearcoat": {"clearcoatFactor": "shiny"}}, "clearcoatFactor must be a number"),
    ({"KHR_materials_transmission": {"transmissionFactor": 1.5}}, r"transmissionFactor must be in \[0.0, 1.0\]"),
    ({"KHR_materials_specular": {"specularColorFactor": "red"}}, "specularColorFactor must be 3 numbers"),
    ({"KHR_materials_specular": 0.5}, "KHR_materials_specular must be an object"),
])
def test_bad_extension_values_are_refused_by_name(tmp_path, ext, message):
    material = {"name": "bad", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}, "extensions": ext}
    with pytest.raises(InputError, match=message):
        load_asset(_write_triangle_gltf(tmp_path / "c", material), use_cache=False)
