"""Assets: procedural cars, the mesh loader (incl. untrusted-input checks) and mesh validation."""

from __future__ import annotations

import base64
import dataclasses
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.assets import references
from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.assets.car_body import body_part, sedan_spec, van_spec
from streetaug.augment.assets.car_wheels import wheel
from streetaug.augment.assets.loader import axis_rotation, list_assets, load_asset
from streetaug.augment.assets.mesh_parts import signed_volume
from streetaug.augment.assets.procedural import paint_palette, procedural_car, procedural_car_variants
from streetaug.augment.assets.references import read_gltf_json
from streetaug.augment.assets.select import select_assets
from streetaug.augment.assets.validate import validate_asset, validate_asset_report
from streetaug.augment.core import InputError
from streetaug.augment.core.raycast import RayScene

DATA = (Path(__file__).parents[2] / ".." / "shared" / "data").resolve()
CARS = DATA / "cars"

# body -> target (length, width, height) in metres
TARGETS = {"sedan": (4.6, 1.8, 1.45), "hatchback": (4.1, 1.75, 1.5), "suv": (4.7, 1.9, 1.75), "van": (5.0, 2.0, 1.95)}


def _mat_index(asset: Asset, name: str) -> int:
    names = [m.name for m in asset.materials]
    assert name in names, f"{name} not in {names}"
    return names.index(name)


def _material_centroid(asset: Asset, prefix: str) -> np.ndarray:
    ids = [i for i, m in enumerate(asset.materials) if m.name.startswith(prefix)]
    sel = np.isin(asset.face_material, ids)
    assert sel.any(), f"no faces with material {prefix}*"
    return asset.vertices[asset.faces[sel]].mean(axis=(0, 1))


# ----------------------------------------------------------------------------- procedural cars


@pytest.fixture(scope="module")
def cars() -> dict[str, Asset]:
    return {body: procedural_car(7, body) for body in procedural_car_variants()}


def test_variants_cover_the_body_types():
    assert set(procedural_car_variants()) == set(TARGETS)
    with pytest.raises(ValueError, match="unknown body"):
        procedural_car(0, "tractor")


@pytest.mark.parametrize("body", sorted(TARGETS))
def test_procedural_dimensions_and_frame(cars, body):
    car = cars[body]
    L, W, H = TARGETS[body]
    w, l, h = car.wlh
    assert abs(l - L) <= 0.1 * L and abs(w - W) <= 0.1 * W and abs(h - H) <= 0.1 * H, (body, car.wlh)
    lo, hi = car.vertices.min(axis=0), car.vertices.max(axis=0)
    assert abs(lo[2]) < 1e-3  # tyres touch the ground
    assert np.allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=1e-6)  # centred
    tyre = _mat_index(car, "tyre")
    assert car.vertices[np.unique(car.faces[car.face_material == tyre])][:, 2].min() < 1e-3
    assert car.category == "vehicle.car"
    assert 3000 < len(car.faces) < 20000


@pytest.mark.parametrize("body", sorted(TARGETS))
def test_procedural_materials(cars, body):
    car = cars[body]
    glass = car.materials[_mat_index(car, "glass")]
    assert glass.opacity < 1.0 and glass.roughness <= 0.1
    paint = car.materials[_mat_index(car, "paint")]
    assert paint.clearcoat == 1.0 and 0.25 <= paint.roughness <= 0.5 and paint.metallic == 0.0 and 0.0 <= paint.flake <= 0.7
    for name in ("glass", "tyre", "rim", "trim", "headlight", "taillight"):
        assert (car.face_material == _mat_index(car, name)).sum() > 0, name
    # Lights at the right ends, glass in the upper body.
    assert _material_centroid(car, "headlight")[0] > 0.35 * car.wlh[1]
    assert _material_centroid(car, "taillight")[0] < -0.35 * car.wlh[1]
    assert _material_centroid(car, "glass")[2] > 0.6 * car.wlh[2]


def test_procedural_is_deterministic_and_seeds_differ():
    a, b = procedural_car(3, "sedan"), procedural_car(3, "sedan")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.face_material, b.face_material)
    assert np.array_equal(a.materials[0].base_color, b.materials[0].base_color)
    colours = {tuple(np.round(procedural_car(s, "sedan").materials[0].base_color, 4)) for s in range(6)}
    assert len(colours) >= 5
    assert procedural_car(11).name == procedural_car(11).name  # body choice deterministic too


def test_custom_paint():
    car = procedural_car(0, "hatchback", paint=(0.5, 0.02, 0.02, 0.4))
    paint = car.materials[_mat_index(car, "paint")]
    # the paint's metallic look is its flakes' share of the base coat, not a bare-metal UE4 metallic
    assert np.allclose(paint.base_color, [0.5, 0.02, 0.02]) and paint.flake == 0.4 and paint.metallic == 0.0
    with pytest.raises(ValueError):
        procedural_car(0, "sedan", paint=(2.0, 0.0, 0.0))


def test_palette_is_realistic():
    palette = paint_palette()
    assert len(palette) >= 30
    cols = np.array([c for _, c, _, _ in palette])
    assert cols.min() >= 0 and cols.max() <= 1
    weights = np.array([w for *_, w in palette])
    lum = cols @ np.array([0.2126, 0.7152, 0.0722])
    # White/black/grey dominate real traffic: weight of low-saturation colours > 60 %.
    sat = cols.max(axis=1) - cols.min(axis=1)
    assert weights[sat < 0.06 * np.maximum(cols.max(axis=1), 1e-3) + 0.03].sum() / weights.sum() > 0.6
    assert lum.max() > 0.7 and lum.min() < 0.01


@pytest.mark.parametrize("body", sorted(TARGETS))
def test_silhouette_is_not_a_box(cars, body):
    car = cars[body]
    lo, hi = car.vertices.min(axis=0), car.vertices.max(axis=0)
    scene = RayScene(car.vertices, car.faces)
    # Height field from above: volume under the top surface / box volume.
    xs = np.linspace(lo[0], hi[0], 80)
    ys = np.linspace(lo[1], hi[1], 40)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    origins = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, hi[2] + 1.0)], 1)
    dirs = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    hits = scene.intersect(origins, dirs)
    top = np.where(hits.hit, hi[2] + 1.0 - hits.t, 0.0)
    fill = top.mean() / (hi[2] - lo[2])
    assert 0.4 < fill < 0.85, fill
    # Side silhouette is not a rectangle either (bonnet / boot lower than the roof).
    zs = np.linspace(lo[2], hi[2], 40)
    sx, sz = np.meshgrid(xs, zs, indexing="ij")
    origins = np.stack([sx.ravel(), np.full(sx.size, lo[1] - 5.0), sz.ravel()], 1)
    side = scene.intersect(origins, np.tile([0.0, 1.0, 0.0], (len(origins), 1))).hit.mean()
    assert 0.45 < side < 0.9, side


@pytest.mark.parametrize("body", sorted(TARGETS))
def test_tumblehome_roof_narrower_than_belt(cars, body):
    car = cars[body]
    h = car.wlh[2]
    body_mats = [_mat_index(car, "paint"), _mat_index(car, "glass")]
    body_v = np.unique(car.faces[np.isin(car.face_material, body_mats)])
    V = car.vertices[body_v]

    def width_at(z):
        band = np.abs(V[:, 2] - z) < 0.03
        return np.ptp(V[band, 1])

    assert width_at(0.96 * h) < 0.9 * width_at(0.55 * h)


@pytest.mark.parametrize("body", ["sedan", "van"])
def test_procedural_normals_point_outwards(cars, body):
    car = cars[body]
    tri = car.vertices[car.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    vn = car.vertex_normals[car.faces].mean(axis=1)
    assert (np.einsum("ij,ij->i", fn, vn) > 0).mean() > 0.98
    assert np.allclose(np.linalg.norm(car.vertex_normals, axis=1), 1.0, atol=1e-6)
    # Rays from far outside towards the centre hit front faces (normal against the ray).
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2000, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.1
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = np.array([0.0, 0.0, 0.5 * car.wlh[2]])
    origins = centre + 20.0 * d
    hits = RayScene(car.vertices, car.faces).intersect(origins, -d)
    assert hits.hit.mean() > 0.9
    assert (np.einsum("ij,ij->i", fn[hits.face[hits.hit]], -d[hits.hit]) < 0).mean() > 0.97


def test_select_assets_procedural_and_file(tmp_path):
    a = select_assets(np.random.default_rng(5), 2)
    b = select_assets(np.random.default_rng(5), 2)
    assert len(a) == 2 and [x.name for x in a] == [x.name for x in b]
    path = _write_obj(tmp_path / "box.obj", _CUBE_V, _CUBE_F)
    got = select_assets(np.random.default_rng(0), 3, asset=path, asset_length=2.0)
    assert len(got) == 3 and np.isclose(got[0].wlh[1], 2.0)


# ----------------------------------------------------------------------------- loader: Kenney cars


def _kenney() -> list[Path]:
    if not CARS.is_dir():
        pytest.skip(f"shared car models not found at {CARS}")
    return list_assets(CARS)


def test_list_assets_sorted_and_filtered(tmp_path):
    files = _kenney()
    assert len(files) == 10 and files == sorted(files) and all(f.suffix == ".glb" for f in files)
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="no asset files"):
        list_assets(tmp_path)
    with pytest.raises(InputError, match="not found"):
        list_assets(tmp_path / "missing")


def test_kenney_cars_front_axis_and_length():
    for path in _kenney():
        car = load_asset(path, front_axis="-z", length_m=4.5)
        assert np.isclose(car.wlh[1], 4.5, atol=1e-6), path.name
        lo, hi = car.vertices.min(axis=0), car.vertices.max(axis=0)
        assert abs(lo[2]) < 1e-9 and np.allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=1e-9)
        assert _material_centroid(car, "lightFront")[0] > 0.3 * 4.5, path.name  # headlights at +x
        assert len(car.materials) >= 4 and len(car.faces) > 1000
        assert np.allclose(np.linalg.norm(car.vertex_normals, axis=1), 1.0, atol=1e-6)


def test_kenney_default_axes_put_the_front_backwards_and_scale_option():
    path = _kenney()[0]
    sedan = CARS / "sedan.glb"
    plus_z = load_asset(sedan, front_axis="+z", use_cache=False)
    assert _material_centroid(plus_z, "lightFront")[0] < 0  # the Kenney front is -z, so +z is wrong
    one = load_asset(path, front_axis="-z", scale=1.0)
    two = load_asset(path, front_axis="-z", scale=2.0)
    assert np.allclose(two.wlh, 2 * one.wlh)
    index = json.loads((CARS / "index.json").read_text())["files"][path.stem]
    # File extents: x = width, y = height, z = length (glTF axes).
    assert np.allclose(one.wlh, [index["extent_xyz"][0], index["extent_xyz"][2], index["extent_xyz"][1]], atol=1e-3)


def test_kenney_materials_read_exact_factors():
    sedan = load_asset(CARS / "sedan.glb" if CARS.is_dir() else _kenney()[0], front_axis="-z")
    gltf = read_gltf_json(CARS / "sedan.glb")
    by_name = {m["name"]: m for m in gltf["materials"]}
    for mat in sedan.materials:
        if mat.name in by_name and "baseColorFactor" in by_name[mat.name]["pbrMetallicRoughness"]:
            want = by_name[mat.name]["pbrMetallicRoughness"]["baseColorFactor"][:3]
            assert np.allclose(mat.base_color, want), mat.name


def test_load_cache_returns_same_object():
    path = _kenney()[1]
    assert load_asset(path, front_axis="-z") is load_asset(path, front_axis="-z")
    assert load_asset(path, front_axis="-z") is not load_asset(path, front_axis="-z", length_m=4.0)


# ----------------------------------------------------------------------------- loader: small files

_CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
_CUBE_F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def _write_obj(path: Path, V: np.ndarray, F: np.ndarray, header: str = "", usemtl: str | None = None) -> Path:
    lines = [header] if header else []
    lines += [f"v {x} {y} {z}" for x, y, z in V]
    if usemtl:
        lines.append(f"usemtl {usemtl}")
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    path.write_text("\n".join(lines) + "\n")
    return path


def _triangle_buffer() -> bytes:
    return np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], dtype=np.float32).tobytes()


def _gltf_doc(buffer_uri: str, n_bytes: int = 36, image_uri: str | None = None) -> dict:
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"name": "glassy", "alphaMode": "BLEND",
                       "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.3, 0.4, 0.35],
                                                "metallicFactor": 0.0, "roughnessFactor": 0.05}}],
        "buffers": [{"byteLength": n_bytes, "uri": buffer_uri}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": n_bytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0.5]}],
    }
    if image_uri is not None:
        doc["images"] = [{"uri": image_uri}]
    return doc


def _write_gltf(folder: Path, doc: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "tri.gltf"
    path.write_text(json.dumps(doc))
    return path


def test_tiny_gltf_loads_with_relative_and_data_uris(tmp_path):
    folder = tmp_path / "assets"
    folder.mkdir()
    (folder / "tri.bin").write_bytes(_triangle_buffer())
    asset = load_asset(_write_gltf(folder, _gltf_doc("tri.bin")), front_axis="+z", up_axis="+y")
    assert len(asset.faces) == 1
    glass = asset.materials[0]
    assert np.allclose(glass.base_color, [0.2, 0.3, 0.4]) and np.isclose(glass.opacity, 0.35)
    assert np.isclose(glass.roughness, 0.05) and glass.metallic == 0.0
    # glTF (x, y, z) -> object: front +z -> x, up +y -> z, left = y x z = +x -> y.
    assert np.allclose(asset.wlh, [1.0, 0.5, 1.0])
    data_uri = "data:application/octet-stream;base64," + base64.b64encode(_triangle_buffer()).decode()
    assert len(load_asset(_write_gltf(tmp_path / "inline", _gltf_doc(data_uri))).faces) == 1


@pytest.mark.parametrize("uri", ["../secret.bin", "/etc/passwd", "http://example.com/x.bin",
                                 "file:///etc/passwd", "%2e%2e/secret.bin", "sub/../../secret.bin", "C:/x.bin"])
def test_gltf_buffer_uri_outside_folder_is_refused(tmp_path, uri):
    (tmp_path / "secret.bin").write_bytes(_triangle_buffer())
    path = _write_gltf(tmp_path / "assets", _gltf_doc(uri))
    with pytest.raises(InputError) as err:
        load_asset(path)
    assert str(path) in str(err.value) and uri in str(err.value)


def test_gltf_image_uri_outside_folder_is_refused(tmp_path):
    folder = tmp_path / "assets"
    folder.mkdir()
    (folder / "tri.bin").write_bytes(_triangle_buffer())
    with pytest.raises(InputError, match=r"images\[0\]\.uri"):
        load_asset(_write_gltf(folder, _gltf_doc("tri.bin", image_uri="../../etc/hosts")))


def test_glb_json_chunk_is_checked(tmp_path):
    doc = json.dumps(_gltf_doc("/etc/passwd")).encode()
    doc += b" " * (-len(doc) % 4)
    glb = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(doc)) + struct.pack("<I4s", len(doc), b"JSON") + doc
    path = tmp_path / "evil.glb"
    path.write_bytes(glb)
    with pytest.raises(InputError, match="absolute path"):
        load_asset(path)
    (tmp_path / "junk.glb").write_bytes(b"not a glb at all, sorry")
    with pytest.raises(InputError, match="glTF"):
        load_asset(tmp_path / "junk.glb")


def test_obj_mtllib_and_texture_paths_are_checked(tmp_path):
    with pytest.raises(InputError, match="mtllib"):
        load_asset(_write_obj(tmp_path / "a.obj", _CUBE_V, _CUBE_F, header="mtllib ../evil.mtl"))
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.5 0 0\nmap_Kd /etc/passwd\n")
    with pytest.raises(InputError, match="map_Kd"):
        load_asset(_write_obj(tmp_path / "b.obj", _CUBE_V, _CUBE_F, header="mtllib m.mtl", usemtl="red"))


def test_obj_mtl_material(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl tinted\nKd 0.5 0.1 0.1\nKs 0.5 0.5 0.5\nNs 200\nd 0.4\n")
    asset = load_asset(_write_obj(tmp_path / "c.obj", _CUBE_V, _CUBE_F, header="mtllib m.mtl", usemtl="tinted"),
                       front_axis="+x", up_axis="+z")
    mat = asset.materials[0]
    assert mat.name == "tinted" and np.allclose(mat.base_color, [0.5, 0.1, 0.1]) and np.isclose(mat.opacity, 0.4)
    assert 0.2 < mat.roughness < 0.4  # Ns 200 is glossy
    assert len(asset.faces) == 12 and np.allclose(asset.wlh, 1.0)
    # Cube normals point away from its centre.
    centre = asset.vertices.mean(axis=0)
    tri = asset.vertices[asset.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", fn, tri.mean(axis=1) - centre) > 0).all()


def test_ply_vertex_colours(tmp_path):
    header = ["ply", "format ascii 1.0", "element vertex 8", "property float x", "property float y",
              "property float z", "property uchar red", "property uchar green", "property uchar blue",
              "element face 12", "property list uchar int vertex_indices", "end_header"]
    cols = ["255 0 0" if v[2] == 0 else "0 0 255" for v in _CUBE_V]
    body = [f"{x} {y} {z} {c}" for (x, y, z), c in zip(_CUBE_V, cols)] + [f"3 {a} {b} {c}" for a, b, c in _CUBE_F]
    path = tmp_path / "cube.ply"
    path.write_text("\n".join(header + body) + "\n")
    asset = load_asset(path, up_axis="+z", front_axis="+x")
    colours = np.array([m.base_color for m in asset.materials])
    assert len(asset.faces) == 12 and len(colours) >= 2
    assert np.isclose(colours[:, 0].max(), 1.0) and np.isclose(colours[:, 2].max(), 1.0)
    plain = tmp_path / "plain.ply"
    plain.write_text("\n".join(header[:6] + header[9:]) + "\n" + "\n".join(
        [f"{x} {y} {z}" for x, y, z in _CUBE_V] + [f"3 {a} {b} {c}" for a, b, c in _CUBE_F]) + "\n")
    assert load_asset(plain, up_axis="+z", front_axis="+x").materials[0].name == "paint"


def test_obj_without_faces_is_refused(tmp_path):
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(InputError, match="no faces") as err:
        load_asset(path)
    assert "points.obj" in str(err.value)


def test_obj_with_nan_vertices_is_refused(tmp_path):
    V = _CUBE_V.copy()
    V[3, 1] = np.nan
    with pytest.raises(InputError, match="NaN") as err:
        load_asset(_write_obj(tmp_path / "nan.obj", V, _CUBE_F))
    assert "nan.obj" in str(err.value)


def test_loader_option_errors(tmp_path):
    path = _write_obj(tmp_path / "cube.obj", _CUBE_V, _CUBE_F)
    with pytest.raises(InputError, match="either scale or length_m"):
        load_asset(path, scale=2.0, length_m=4.0)
    with pytest.raises(InputError, match="front_axis"):
        load_asset(path, front_axis="forward")
    with pytest.raises(InputError, match="perpendicular"):
        load_asset(path, front_axis="+y", up_axis="-y")
    with pytest.raises(InputError, match="length_m"):
        load_asset(path, length_m=-1.0)
    with pytest.raises(InputError, match="not found"):
        load_asset(tmp_path / "missing.glb")
    (tmp_path / "x.stl").write_text("solid x\nendsolid x\n")
    with pytest.raises(InputError, match="unsupported"):
        load_asset(tmp_path / "x.stl")


def test_large_files_are_refused(tmp_path, monkeypatch):
    path = _write_obj(tmp_path / "cube.obj", _CUBE_V, _CUBE_F)
    monkeypatch.setattr(references, "MAX_FILE_BYTES", 10)
    with pytest.raises(InputError, match="200 MB"):
        load_asset(path, use_cache=False)


def test_axis_rotation_is_proper():
    for front in ("+x", "-x", "+y", "-y", "+z", "-z"):
        for up in ("+x", "-x", "+y", "-y", "+z", "-z"):
            if front[1] == up[1]:
                continue
            R = axis_rotation(front, up)
            assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    R = axis_rotation("-z", "+y")  # Kenney: file -z -> +x, +y -> +z, file +x (vehicle right) -> -y
    assert np.allclose(R @ [0, 0, -1], [1, 0, 0]) and np.allclose(R @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(R @ [1, 0, 0], [0, -1, 0])


# ----------------------------------------------------------------------------- validation


def _asset(V, F, name="probe", normals=None) -> Asset:
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    return Asset(name=name, vertices=V, faces=F, face_material=np.zeros(len(F), dtype=np.int64),
                 materials=(Material("m", base_color=np.ones(3)),),
                 vertex_normals=np.zeros_like(V) if normals is None else normals)


def test_validate_drops_zero_area_triangles_and_repairs_normals():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0]], dtype=float)
    F = [[0, 1, 2], [0, 1, 3], [1, 1, 2], [0, 3, 4]]  # 1 good, 1 repeated index, 2 collinear
    cleaned, report = validate_asset_report(_asset(V, F))
    assert report.dropped_degenerate == 3 and len(cleaned.faces) == 1
    assert np.array_equal(cleaned.faces[0], [0, 1, 2])
    assert np.allclose(cleaned.vertex_normals[:3], [0, 0, 1])  # zero normals recomputed
    assert report.repaired_normals == 5
    assert np.isfinite(cleaned.vertex_normals).all()


def test_validate_errors_name_the_asset():
    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    with pytest.raises(InputError, match="'empty'.*no faces"):
        validate_asset(_asset(tri, np.zeros((0, 3)), name="empty"))
    with pytest.raises(InputError, match="'nan'.*NaN"):
        validate_asset(_asset([[0, 0, 0], [1, np.nan, 0], [0, 1, 0]], [[0, 1, 2]], name="nan"))
    with pytest.raises(InputError, match="'oob'.*face indices"):
        validate_asset(_asset(tri, [[0, 1, 5]], name="oob"))
    with pytest.raises(InputError, match="'flat'.*zero area"):
        validate_asset(_asset([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], name="flat"))
    bad_mat = _asset(tri, [[0, 1, 2]], name="mat")
    bad_mat = dataclasses.replace(bad_mat, face_material=np.array([3]))
    with pytest.raises(InputError, match="'mat'.*face_material"):
        validate_asset(bad_mat)


def test_gltf_texture_is_linearised_and_uv_keeps_gltf_convention(tmp_path):
    import cv2

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], np.float32)
    uv = np.array([[0.1, 0.2], [0.9, 0.2], [0.1, 0.7]], np.float32)
    buf = pos.tobytes() + uv.tobytes()
    tex = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [128, 128, 128]]], np.uint8)  # RGB, row 0 = top
    png = cv2.imencode(".png", tex[..., ::-1])[1].tobytes()
    doc = _gltf_doc("data:application/octet-stream;base64," + base64.b64encode(buf).decode(), n_bytes=len(buf),
                    image_uri="data:image/png;base64," + base64.b64encode(png).decode())
    doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 1
    doc["bufferViews"] = [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                          {"buffer": 0, "byteOffset": 36, "byteLength": 24}]
    doc["accessors"].append({"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"})
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [{"name": "tex", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                                 "metallicFactor": 0.0}}]
    asset = load_asset(_write_gltf(tmp_path, doc))
    texture = asset.materials[0].base_color_texture
    assert texture is not None and texture.dtype == np.float32 and texture.shape == (2, 2, 3)
    assert np.allclose(texture[0, 0], [1, 0, 0]) and np.allclose(texture[1, 0], [0, 0, 1])
    assert np.allclose(texture[1, 1], ((128 / 255 + 0.055) / 1.055) ** 2.4, atol=1e-4)  # sRGB -> linear
    assert np.allclose(np.sort(asset.uv[:, 1]), np.sort(uv[:, 1]), atol=1e-6)  # v down, as in the file
    assert asset.materials[0].metallic == 0.0 and np.allclose(asset.materials[0].base_color, 1.0)


def test_procedural_body_and_tyres_are_closed_surfaces():
    for spec in (sedan_spec(), van_spec()):
        part = body_part(spec)
        tyre = wheel(np.array([0.0, 0.8, 0.3]), 1.0, 0.3, 0.2)[0]
        for F in (part.faces, tyre.faces):
            edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
            _, counts = np.unique(edges, axis=0, return_counts=True)
            assert (counts == 2).all()  # every edge shared by exactly two triangles: watertight
        assert signed_volume(part.vertices, part.faces) > 0.5 * spec.length * spec.width * spec.height * 0.5
