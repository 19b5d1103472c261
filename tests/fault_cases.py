"""Corrupt and malicious inputs, built from the bundled sample scenes and from assets made here.

Each builder writes its inputs under a fresh folder and returns a :class:`FaultCase`: the ``streetaug``
arguments that exercise it and the paths whose state tells the outcome. ``tests/hardening`` asserts the
outcome of every case; ``benchmarks/bench_faults.py`` runs them as separate processes and tabulates exit
code, message, peak memory and what was written (before / after a change).
"""

from __future__ import annotations

import base64
import json
import shutil
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / "examples" / "nuscenes-samples"
VERSION = "v1.0-samples"
FAST = ["--quality", "draft", "--cameras", "CAM_FRONT", "--no-progress"]


@dataclass(frozen=True)
class FaultCase:
    """One bad input: ``argv`` for ``streetaug``; ``out`` the output folder; ``watch`` files that must not change
    or appear (e.g. a private file outside the dataroot, the source dataset)."""

    name: str
    what: str
    argv: list[str]
    out: Path
    watch: dict[str, Path] = field(default_factory=dict)
    concurrent: int = 1  # run this many copies at once
    kill_after_s: float | None = None  # SIGKILL the main process after this long


def batch_argv(root: Path, out: Path) -> list[str]:
    """``streetaug batch`` of a copied dataset on one worker, CAM_FRONT, draft quality."""
    return ["batch", "--dataroot", str(root), "--version", VERSION, "--out", str(out), "--workers", "1", *FAST]


def copy_bundled(root: Path) -> Path:
    """A private copy of the bundled dataset (tables, images, LiDAR, lidarseg, maps; no ground truth)."""
    shutil.copytree(BUNDLED, root, ignore=shutil.ignore_patterns("ground_truth", "README.md"))
    return root


def edit_table(root: Path, table: str, edit: Callable[[list[dict]], None]) -> None:
    path = root / VERSION / f"{table}.json"
    rows = json.loads(path.read_text())
    edit(rows)
    path.write_text(json.dumps(rows))


def first_camera_row(rows: list[dict], channel: str = "CAM_FRONT", index: int = 0) -> dict:
    return [r for r in rows if f"/{channel}/" in r["filename"]][index]


def png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose header claims ``width x height`` with a tiny (truncated) body: costless to make."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = lambda kind, data: struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))
    return path


def png_zeros_streamed(path: Path, width: int, height: int) -> Path:
    """A real, valid black RGB PNG of any size, written row by row (small memory, a few MB on disk)."""
    chunk = lambda kind, data: struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    comp = zlib.compressobj(9)
    row = b"\0" * (1 + 3 * width)
    parts = [comp.compress(row) for _ in range(height)]
    idat = b"".join(parts) + comp.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


def box_gltf(path: Path, image_uri: str | None = None, buffer_uri: str | None = None) -> Path:
    """A 4.4 x 1.8 x 1.5 m box as glTF with an embedded (data URI) buffer, optionally textured by ``image_uri``."""
    v = np.array([[x, y, z] for x in (-0.9, 0.9) for y in (0.0, 1.5) for z in (-2.2, 2.2)], np.float32)
    f = np.array([0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1, 2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4,
                  1, 5, 7, 1, 7, 3], np.uint16)
    uv = np.zeros((8, 2), np.float32)
    blob = v.tobytes() + uv.tobytes() + f.tobytes()
    uri = buffer_uri if buffer_uri is not None else "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "buffers": [{"byteLength": len(blob), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 96},
                        {"buffer": 0, "byteOffset": 96, "byteLength": 64},
                        {"buffer": 0, "byteOffset": 160, "byteLength": 72}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                       "min": v.min(0).tolist(), "max": v.max(0).tolist()},
                      {"bufferView": 1, "componentType": 5126, "count": 8, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 36, "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.1, 0.1, 1.0], "metallicFactor": 0.0,
                                                 "roughnessFactor": 0.5}}],
    }
    if image_uri is not None:
        doc["images"] = [{"uri": image_uri}]
        doc["textures"] = [{"source": 0}]
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    path.write_text(json.dumps(doc))
    return path


# ----------------------------------------------------------------------------- the cases


def case_basename_collision(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")

    def edit(rows):
        for i, r in enumerate([r for r in rows if "/CAM_FRONT/" in r["filename"]][:2]):
            src = root / r["filename"]
            dst = root / "samples" / "CAM_FRONT" / f"sub{i}" / "same.jpg"
            dst.parent.mkdir(parents=True, exist_ok=True)
            src.rename(dst)
            r["filename"] = str(dst.relative_to(root))

    edit_table(root, "sample_data", edit)
    out = tmp / "out"
    return FaultCase("basename-collision", "two CAM_FRONT images named same.jpg in sub0/ and sub1/",
                     batch_argv(root, out),
                     out)


def case_filename_escapes_batch(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    private = tmp / "private" / "secret_photo.jpg"
    private.parent.mkdir()
    shutil.copy(root / first_camera_row(json.loads((root / VERSION / "sample_data.json").read_text()))["filename"], private)
    edit_table(root, "sample_data", lambda rows: first_camera_row(rows).update(filename="../private/secret_photo.jpg"))
    out = tmp / "out"
    return FaultCase("filename-escapes-batch", "sample_data.filename = ../private/secret_photo.jpg",
                     batch_argv(root, out),
                     out, watch={"private": private})


def case_filename_absolute_insert(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    rows = json.loads((root / VERSION / "sample_data.json").read_text())
    scene_sample = first_camera_row(rows)["sample_token"]
    edit_table(root, "sample_data", lambda rows: first_camera_row(rows).update(filename="/etc/passwd"))
    out = tmp / "out"
    return FaultCase("filename-absolute-insert", "sample_data.filename = /etc/passwd, insert",
                     ["insert", "--dataroot", str(root), "--version", VERSION, "--scene", "sample-sunny",
                      "--sample", scene_sample, "--camera", "CAM_FRONT", "--quality", "draft", "--out", str(out)], out)


def case_insert_out_is_source(tmp: Path, sub: str = "samples/CAM_FRONT") -> FaultCase:
    root = copy_bundled(tmp / "data")
    out = root / sub
    return FaultCase(f"insert-out-in-source:{sub}", f"insert --out DATAROOT/{sub}",
                     ["insert", "--dataroot", str(root), "--version", VERSION, "--scene", "sample-sunny",
                      "--quality", "draft", "--out", str(out)], out, watch={"source": root})


def case_texture_bomb(tmp: Path, side: int = 13000, real: bool = False) -> FaultCase:
    folder = tmp / "assets"
    folder.mkdir(parents=True)
    (png_zeros_streamed if real else png_header_only)(folder / "paint.png", side, side)
    asset = box_gltf(folder / "car.gltf", image_uri="paint.png")
    out = tmp / "out"
    return FaultCase(f"texture-{side}", f"glTF with a {side} x {side} PNG texture",
                     ["insert", "--scene", "sample-sunny", "--asset", str(asset), "--quality", "draft",
                      "--out", str(out)], out)


def case_huge_image(tmp: Path, side: int = 20000, real: bool = False) -> FaultCase:
    image = (png_zeros_streamed if real else png_header_only)(tmp / "big.png", side, side)
    depth = tmp / "depth.npy"
    np.save(depth, np.full((4, 4), 10.0, np.float32))
    env = tmp / "env.exr"
    from streetaug.augment.core import write_exr

    write_exr(env, np.ones((16, 32, 3), np.float32))
    asset = box_gltf(tmp / "car.gltf")
    out = tmp / "out"
    return FaultCase(f"image-{side}", f"a {side} x {side} input image",
                     ["insert", "--image", str(image), "--intrinsics", f"{side},{side},{side / 2},{side / 2}",
                      "--depth", str(depth), "--envmap", str(env), "--asset", str(asset), "--pose-camera",
                      "0,1.5,15,0", "--out", str(out)], out)


def corrupt_images(root: Path, channel: str | None = "CAM_FRONT", count: int | None = None) -> None:
    rows = json.loads((root / VERSION / "sample_data.json").read_text())
    cams = [r for r in rows if "/CAM_" in r["filename"] and (channel is None or f"/{channel}/" in r["filename"])]
    for r in cams[:count]:
        (root / r["filename"]).write_bytes(b"not a jpeg")


def case_all_images_corrupt(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    corrupt_images(root)
    out = tmp / "out"
    return FaultCase("all-images-corrupt", "every CAM_FRONT image corrupt",
                     batch_argv(root, out),
                     out)


def case_one_camera_corrupt(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    corrupt_images(root, "CAM_BACK", count=1)
    out = tmp / "out"
    return FaultCase("one-camera-corrupt", "one CAM_BACK image corrupt, three cameras",
                     ["batch", "--dataroot", str(root), "--version", VERSION, "--out", str(out), "--workers", "1",
                      "--quality", "draft", "--cameras", "CAM_FRONT,CAM_FRONT_LEFT,CAM_BACK", "--limit", "1",
                      "--no-progress"], out)


def case_broken_asset_in_folder(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    folder = tmp / "assets"
    folder.mkdir()
    box_gltf(folder / "good.gltf")
    (folder / "broken.glb").write_bytes(b"glTF not really")
    out = tmp / "out"
    return FaultCase("assets-one-broken", "--assets folder with one broken .glb",
                     ["batch", "--dataroot", str(root), "--version", VERSION, "--out", str(out), "--workers", "1",
                      "--assets", str(folder), *FAST], out)


def case_option(tmp: Path, name: str, args: list[str]) -> FaultCase:
    out = tmp / "out"
    return FaultCase(f"option:{name}", " ".join(args),
                     ["insert", "--scene", "sample-sunny", "--quality", "draft", *args, "--out", str(out)], out)


def case_duplicate_cameras(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    out = tmp / "out"
    return FaultCase("duplicate-cameras", "--cameras CAM_FRONT,CAM_FRONT --n-objects 1",
                     ["batch", "--dataroot", str(root), "--version", VERSION, "--out", str(out), "--workers", "1",
                      "--quality", "draft", "--cameras", "CAM_FRONT,CAM_FRONT", "--limit", "1", "--no-progress"], out)


def case_concurrent_batches(tmp: Path, copies: int = 2) -> FaultCase:
    root = copy_bundled(tmp / "data")
    out = tmp / "out"
    return FaultCase(f"concurrent-{copies}", f"{copies} batch runs on one --out at once",
                     ["batch", "--dataroot", str(root), "--version", VERSION, "--out", str(out), "--workers", "1",
                      *FAST], out, concurrent=copies)


def case_lidar_nan(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    lidar = sorted((root / "samples" / "LIDAR_TOP").iterdir())[0]
    points = np.fromfile(lidar, np.float32).reshape(-1, 5)
    points[::7, 0] = np.nan
    points.tofile(lidar)
    out = tmp / "out"
    return FaultCase("lidar-nan", "NaN coordinates in a LIDAR_TOP file",
                     batch_argv(root, out),
                     out)


def case_table_field(tmp: Path, name: str, table: str, edit: Callable[[list[dict]], None]) -> FaultCase:
    root = copy_bundled(tmp / "data")
    edit_table(root, table, edit)
    out = tmp / "out"
    return FaultCase(f"table:{name}", name,
                     batch_argv(root, out),
                     out)


def table_cases() -> dict[str, tuple[str, Callable[[list[dict]], None]]]:
    def zero_quat(rows):
        rows[0]["rotation"] = [0, 0, 0, 0]

    def nan_size(rows):
        rows[0]["size"] = [float("nan"), 4.0, 1.5]

    def text_timestamp(rows):
        first_camera_row(rows)["timestamp"] = "yesterday"

    def duplicate_token(rows):
        rows.append(dict(rows[0]))

    def wrong_size(rows):
        first_camera_row(rows).update(width=800, height=450)

    return {"annotation zero quaternion": ("sample_annotation", zero_quat),
            "annotation NaN size": ("sample_annotation", nan_size),
            "non-numeric timestamp": ("sample_data", text_timestamp),
            "duplicated token": ("sample_annotation", duplicate_token),
            "image size differs from table": ("sample_data", wrong_size)}


def case_data_uri(tmp: Path, name: str, uri: str) -> FaultCase:
    asset = box_gltf(tmp / "car.gltf", buffer_uri=uri)
    out = tmp / "out"
    return FaultCase(f"data-uri:{name}", f"buffer uri {uri[:40]}",
                     ["insert", "--scene", "sample-sunny", "--asset", str(asset), "--quality", "draft",
                      "--out", str(out)], out)


def case_deep_map(tmp: Path) -> FaultCase:
    root = copy_bundled(tmp / "data")
    for p in (root / "maps" / "expansion").glob("*.json"):
        p.write_text("[" * 100_000 + "]" * 100_000)
    out = tmp / "out"
    return FaultCase("deep-map-json", "a 100k-deep map expansion JSON",
                     batch_argv(root, out),
                     out)
