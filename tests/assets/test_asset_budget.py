"""What an untrusted asset may cost: data URIs, texture sizes and triangle counts are checked from the file's
headers before the mesh library opens it; large textures are reduced before they are converted."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

import fault_cases as fc
from streetaug.augment.assets import loader
from streetaug.augment.assets.budget import gltf_triangles
from streetaug.augment.core import InputError


@pytest.fixture()
def no_mesh_library(monkeypatch):
    """Fail the test if the mesh library is asked to open the file (the checks must come first)."""
    monkeypatch.setattr(trimesh, "load", lambda path, *a, **k: pytest.fail(f"trimesh opened {path}"))


def glb_with_image(path: Path, image: bytes) -> Path:
    """The fault cases' box as a GLB whose texture is ``image`` in a bufferView of the binary chunk."""
    doc = json.loads(fc.box_gltf(path.with_suffix(".gltf")).read_text())
    blob = base64.b64decode(doc["buffers"][0].pop("uri").split(",", 1)[1])
    offset = len(blob)
    blob += image + b"\0" * (-len(image) % 4)
    doc["buffers"][0]["byteLength"] = len(blob)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": offset, "byteLength": len(image)})
    doc["images"] = [{"bufferView": 3, "mimeType": "image/png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(blob), b"BIN\0") + blob
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path


class TestDataUris:
    @pytest.mark.parametrize("uri, expect", [
        ("data:application/octet-stream;base64,@@@@", "is not valid base64"),
        ("data:application/octet-stream,abc", "is not base64-encoded"),
        ("data:application/octet-stream;base64,AAAA", "byteLength 232 but its data holds 3 bytes"),
    ])
    def test_bad_buffer_uris_name_the_file_and_the_field(self, tmp_path, no_mesh_library, uri, expect):
        asset = fc.box_gltf(tmp_path / "car.gltf", buffer_uri=uri)
        with pytest.raises(InputError) as e:
            loader.load_asset(asset)
        assert str(e.value).startswith(f"{asset}: buffers[0]") and expect in str(e.value)

    def test_a_bad_image_data_uri(self, tmp_path, no_mesh_library):
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri="data:image/png;base64,!!")
        with pytest.raises(InputError, match=r"images\[0\].uri: the payload .* is not valid base64"):
            loader.load_asset(asset)


class TestTextureSizes:
    def test_a_texture_bomb_file_is_refused_from_its_header(self, tmp_path, no_mesh_library):
        fc.png_header_only(tmp_path / "paint.png", 13000, 13000)
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri="paint.png")
        with pytest.raises(InputError, match=r"car.gltf: images\[0\] 'paint.png': texture of 13000 x 13000"):
            loader.load_asset(asset)

    def test_a_texture_bomb_in_a_data_uri(self, tmp_path, no_mesh_library):
        png = fc.png_header_only(tmp_path / "p.png", 20000, 6000).read_bytes()
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri="data:image/png;base64," + base64.b64encode(png).decode())
        with pytest.raises(InputError, match=r"images\[0\]: texture of 20000 x 6000"):
            loader.load_asset(asset)

    def test_a_texture_bomb_in_a_glb_buffer_view(self, tmp_path, no_mesh_library):
        png = fc.png_header_only(tmp_path / "p.png", 12000, 12000).read_bytes()
        with pytest.raises(InputError, match=r"car.glb: images\[0\]: texture of 12000 x 12000"):
            loader.load_asset(glb_with_image(tmp_path / "car.glb", png))

    def test_the_pixel_limit_comes_from_the_environment(self, tmp_path, monkeypatch, no_mesh_library):
        cv2.imwrite(str(tmp_path / "paint.png"), np.zeros((300, 400, 3), np.uint8))
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri="paint.png")
        monkeypatch.setenv("STREETAUG_MAX_TEXTURE_PIXELS", "100000")
        with pytest.raises(InputError, match="400 x 300 .* above the limit"):
            loader.load_asset(asset)

    @pytest.mark.parametrize("suffix, shape, side, expect", [(".png", (3000, 5000), 1024, (375, 625)),
                                                             (".jpg", (1024, 2048), 512, (256, 512))])
    def test_large_textures_are_reduced_to_the_side_limit(self, tmp_path, monkeypatch, suffix, shape, side, expect):
        rng = np.random.default_rng(0)
        cv2.imwrite(str(tmp_path / f"paint{suffix}"), rng.integers(0, 256, (*shape, 3), dtype=np.uint8))
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri=f"paint{suffix}")
        monkeypatch.setenv("STREETAUG_MAX_TEXTURE_SIDE", str(side))
        (texture,) = [m.base_color_texture for m in loader.load_asset(asset, use_cache=False).materials]
        assert texture.shape == (*expect, 3) and texture.dtype == np.float32
        assert 0.0 <= texture.min() and texture.max() <= 1.0

    def test_textures_within_the_limits_load_unchanged(self, tmp_path):
        rgb = np.random.default_rng(1).integers(0, 256, (64, 96, 3), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / "paint.png"), rgb[..., ::-1])
        asset = fc.box_gltf(tmp_path / "car.gltf", image_uri="paint.png")
        (texture,) = [m.base_color_texture for m in loader.load_asset(asset, use_cache=False).materials]
        c = rgb / 255.0
        expect = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        np.testing.assert_allclose(texture, expect, rtol=1e-6, atol=1e-7)

    def test_an_mtl_texture_bomb_is_refused(self, tmp_path, no_mesh_library):
        fc.png_header_only(tmp_path / "big.png", 15000, 15000)
        (tmp_path / "car.mtl").write_text("newmtl paint\nKd 0.5 0.5 0.5\nmap_Kd big.png\n")
        obj = tmp_path / "car.obj"
        obj.write_text("mtllib car.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl paint\nf 1 2 3\n")
        with pytest.raises(InputError, match="car.obj: material 'paint' map_kd 'big.png': texture of 15000 x 15000"):
            loader.load_asset(obj)


class TestTriangles:
    def test_gltf_triangles_come_from_the_accessors(self, tmp_path):
        doc = json.loads(fc.box_gltf(tmp_path / "car.gltf").read_text())
        assert gltf_triangles(doc) == 12
        doc["nodes"].append({"mesh": 0})
        assert gltf_triangles(doc) == 24  # two instances

    @pytest.mark.parametrize("make", ["gltf", "obj", "ply"])
    def test_assets_above_the_triangle_limit_are_refused_before_loading(self, tmp_path, monkeypatch,
                                                                        no_mesh_library, make):
        if make == "gltf":
            asset = fc.box_gltf(tmp_path / "car.gltf")
        elif make == "obj":
            asset = tmp_path / "car.obj"
            asset.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * 12)
        else:
            asset = tmp_path / "car.ply"
            asset.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                              b"property float z\nelement face 12\nproperty list uchar int vertex_indices\n"
                              b"end_header\n")
        monkeypatch.setenv("STREETAUG_MAX_TRIANGLES", "10")
        with pytest.raises(InputError, match=f"{asset.name}: 12 triangles, above the limit of 10"):
            loader.load_asset(asset)
