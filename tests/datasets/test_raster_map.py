"""The semantic-prior raster (nuScenes base release, no map expansion) as the drivable-area source.

Synthetic: PNGs written here with chosen row filters (streamed decode vs Pillow's, exact), rasters of known
geometry (the devkit pixel -> global convention, holes, bottom-left origin, band seams), clear errors.
Real (skips without ``../shared/data/nuscenes-seq``): a copy of scene-0916's tables, raster and one sample's
files WITHOUT the (derived) map expansion: the vectorised raster agrees with the expansion polygons, holds
every ego pose, and placement reports the raster as its drivable source.
"""

from __future__ import annotations

import json
import shutil
import struct
import time
import tracemalloc
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import shapely
from conftest import SHARED_DATA, devkit

from streetaug.datasets.errors import DatasetError
from streetaug.datasets.nuscenes import REQUIRED_TABLES, NuScenesReader
from streetaug.datasets.nuscenes_map import read_drivable_area
from streetaug.datasets.raster_map import (
    MAP_SOURCE_EXPANSION,
    MAP_SOURCE_RASTER,
    global_to_pixel,
    iter_png_bands,
    pixel_to_global,
    png_size,
    read_semantic_prior,
    semantic_prior_row,
)
from streetaug.placement.drivable import drivable_area_for_sample
from streetaug.placement.config import PlacementConfig
from streetaug.placement.place import ObjectBox, place_objects

RES = 0.1
SEQ = SHARED_DATA / "nuscenes-seq"
SEQ_PNG = SEQ / "maps" / "93406b464a165eaba6d9de76ca09f5da.png"
LOCATION = "singapore-queenstown"
# the crop the derived expansion covers (nuscenes-seq/README.md): outside it the expansion is empty
CROP = shapely.box(530.3, 1664.4, 836.1, 1938.2)
needs_seq = pytest.mark.skipif(not SEQ_PNG.is_file(), reason=f"{SEQ} (real scene-0916 with its raster map) not present")


# ---------------------------------------------------------------------- a PNG writer with chosen filters


def _paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


def write_png(path: Path, image: np.ndarray, filters, chunk_bytes: int = 64, depth: int = 8, colour: int = 0) -> Path:
    """8-bit greyscale PNG of ``image`` (H, W) uint8, row i filtered with ``filters[i % len(filters)]``."""
    h, w = image.shape
    img = image.astype(np.int64)
    raw = bytearray()
    for i in range(h):
        f = filters[i % len(filters)]
        x = img[i]
        up = img[i - 1] if i > 0 else np.zeros(w, np.int64)
        left = np.r_[0, x[:-1]]
        upleft = np.r_[0, up[:-1]]
        if f == 0:
            d = x
        elif f == 1:
            d = x - left
        elif f == 2:
            d = x - up
        elif f == 3:
            d = x - (left + up) // 2
        else:
            d = x - np.array([_paeth(a, b, c) for a, b, c in zip(left, up, upleft)])
        raw += bytes([f]) + (d % 256).astype(np.uint8).tobytes()
    data = zlib.compress(bytes(raw), 9)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    out = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, 0))
    for k in range(0, len(data), chunk_bytes):  # many IDAT chunks: the stream crosses chunk borders
        out += chunk(b"IDAT", data[k:k + chunk_bytes])
    path.write_bytes(out + chunk(b"IEND", b""))
    return path


def _decode(path: Path, band_rows: int) -> np.ndarray:
    bands = list(iter_png_bands(path, band_rows))
    assert [r0 for r0, _ in bands] == list(range(0, sum(len(b) for _, b in bands), band_rows))
    return np.concatenate([b for _, b in bands])


def _noise_image(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.uint8)
    img[rng.random((h, w)) < 0.2] = 255
    img[rng.random((h, w)) < 0.05] = rng.integers(1, 255)  # other values decode too
    return img


class TestDecode:
    @pytest.mark.parametrize("filters", [[0], [1], [2], [0, 1, 2, 1], [1, 2, 2, 0]])
    @pytest.mark.parametrize("band_rows", [1, 3, 64])
    def test_streamed_rows_match_the_image(self, tmp_path, filters, band_rows):
        img = _noise_image(23, 37, seed=len(filters) * 7 + band_rows)
        path = write_png(tmp_path / "m.png", img, filters)
        assert png_size(path) == (37, 23)
        np.testing.assert_array_equal(_decode(path, band_rows), img)

    @pytest.mark.parametrize("filters", [[3], [4], [1, 1, 4, 2, 3]])
    def test_average_and_paeth_fall_back_to_pillow_past_its_bomb_guard(self, tmp_path, filters, monkeypatch):
        from PIL import Image

        monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 10)  # Pillow would refuse this 851-px image as a bomb
        img = _noise_image(23, 37, seed=3)
        path = write_png(tmp_path / "m.png", img, filters)
        np.testing.assert_array_equal(_decode(path, 2), img)  # [1, 1, 4, ...]: 2 rows streamed, then Pillow
        assert Image.MAX_IMAGE_PIXELS == 10  # the guard is lifted for that one file only
        with pytest.raises(Image.DecompressionBombError):
            Image.open(path)

    def test_png_written_by_opencv(self, tmp_path):
        img = _noise_image(40, 33, seed=5)
        path = tmp_path / "cv.png"
        assert cv2.imwrite(str(path), img)
        np.testing.assert_array_equal(_decode(path, 7), img)

    def test_errors_name_the_file_and_what_was_expected(self, tmp_path):
        with pytest.raises(DatasetError, match=r"nope\.png: semantic-prior raster not found"):
            png_size(tmp_path / "nope.png")
        (tmp_path / "text.png").write_text("not a png")
        with pytest.raises(DatasetError, match=r"text\.png: not a PNG file"):
            png_size(tmp_path / "text.png")
        cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((4, 5, 3), np.uint8))
        with pytest.raises(DatasetError, match=r"rgb\.png: expected an 8-bit greyscale PNG .*colour type 2"):
            png_size(tmp_path / "rgb.png")
        cv2.imwrite(str(tmp_path / "deep.png"), np.zeros((4, 5), np.uint16))
        with pytest.raises(DatasetError, match=r"deep\.png: expected an 8-bit greyscale PNG \(bit depth 8.*got bit depth 16"):
            png_size(tmp_path / "deep.png")
        img = _noise_image(50, 40, seed=1)
        good = write_png(tmp_path / "good.png", img, [1]).read_bytes()
        (tmp_path / "cut.png").write_bytes(good[: len(good) // 2])
        with pytest.raises(DatasetError, match=r"cut\.png: PNG ends .* of 50 rows"):
            _decode(tmp_path / "cut.png", 8)
        bad = bytearray(good)
        bad[60:70] = b"\xff" * 10  # inside the first IDAT's zlib stream
        (tmp_path / "bad.png").write_bytes(bytes(bad))
        with pytest.raises(DatasetError, match=r"bad\.png: (corrupt PNG image data|row \d+ has PNG filter type)"):
            _decode(tmp_path / "bad.png", 8)


# ---------------------------------------------------------------------- convention and vectorising


class TestConvention:
    def test_pixel_centres_devkit_map_mask(self):
        H = 50
        # devkit MapMask: pixel = (round(x / res), round(H - y / res)); row 0 is the top (north) edge
        np.testing.assert_allclose(pixel_to_global([0, H - 1, 10], [0, 0, 7], H), [[0.0, 5.0], [0.0, 0.1], [0.7, 4.0]])
        rng = np.random.default_rng(0)
        row, col = rng.integers(0, H, 100), rng.integers(0, 80, 100)
        xy = pixel_to_global(row, col, H) + rng.uniform(-0.049, 0.049, (100, 2))  # anywhere inside the pixel
        r2, c2 = global_to_pixel(xy, H)
        np.testing.assert_array_equal(r2, row)
        np.testing.assert_array_equal(c2, col)


def _raster(tmp_path: Path, img: np.ndarray, **kw):
    return read_semantic_prior(write_png(tmp_path / "m.png", img, [1, 2]), RES, **kw)


def _union(r):
    return shapely.union_all(r.area.geometries)


class TestVectorise:
    H, W = 60, 80

    def test_rectangle_with_a_hole_lands_on_its_pixel_edges(self, tmp_path):
        img = np.zeros((self.H, self.W), np.uint8)
        img[40:55, 10:70] = 255  # rows 40..54 = near the bottom of the image = small y
        img[45:50, 30:50] = 0  # a hole of 20 x 5 px = 2 m x 0.5 m
        r = _raster(tmp_path, img, band_rows=7, simplify_px=0.0, min_area_m2=0.5, tile_m=2.5, overlap_m=0.3)
        u = _union(r)
        # pixel (row, col) spans x (col -+ 0.5) res, y (H - row -+ 0.5) res
        outer = shapely.box((10 - 0.5) * RES, (self.H - 54 - 0.5) * RES, (69 + 0.5) * RES, (self.H - 40 + 0.5) * RES)
        hole = shapely.box((30 - 0.5) * RES, (self.H - 49 - 0.5) * RES, (49 + 0.5) * RES, (self.H - 45 + 0.5) * RES)
        expected = outer.difference(hole)
        # exact but at concave pixel corners, which the 8-connected trace cuts: < 0.3 px2 each (4 in the hole)
        assert u.symmetric_difference(expected).area < 4 * 0.3 * RES ** 2, u.symmetric_difference(expected).area
        np.testing.assert_allclose(u.bounds, outer.bounds, atol=1e-9)  # convex corners: exact
        np.testing.assert_allclose(u.interiors[0].bounds, hole.bounds, atol=0.35 * RES)
        # every pixel centre on the right side
        rows, cols = np.mgrid[0:self.H, 0:self.W]
        xy = pixel_to_global(rows.ravel(), cols.ravel(), self.H)
        np.testing.assert_array_equal(shapely.contains_xy(u, xy[:, 0], xy[:, 1]), img.ravel() == 255)
        assert isinstance(u, shapely.Polygon) and len(u.interiors) == 1  # band seams (every 7 rows) merged
        assert r.drivable_pixels == int((img == 255).sum())
        assert r.raster_area_m2 == pytest.approx(expected.area)
        assert len(r.area.geometries) > 1  # tiles, for the spatial index
        # a footprint straddling band seams and tile borders is wholly drivable
        assert r.area.contains_xy(pixel_to_global([42, 52, 47], [12, 68, 25], self.H)).all()
        assert not r.area.contains_xy(pixel_to_global([47, 39, 56], [40, 20, 20], self.H)).any()
        # boxes left and right of the hole, across every band seam (rows 42, 49) and a tile border (x 2.5, 5.0)
        assert shapely.contains(u, shapely.box(1.0, 0.6, 2.9, 2.0)) and shapely.contains(u, shapely.box(5.0, 0.6, 6.9, 2.0))
        assert r.area.near(np.array([3.95, 1.3]), 0.4).area == pytest.approx(0.8 * 0.8 - 0.8 * 0.5)

    def test_agrees_with_the_devkit_map_mask(self, tmp_path):
        devkit()  # skips (or fails under make test) without the devkit
        from nuscenes.utils.map_mask import MapMask

        img = np.zeros((self.H, self.W), np.uint8)
        img[40:55, 10:70] = 255
        img[45:50, 30:50] = 0
        img[3:20, 60:75] = 255
        path = write_png(tmp_path / "dk.png", img, [1])
        u = _union(read_semantic_prior(path, RES, band_rows=9, simplify_px=0.0, min_area_m2=0.5))
        rng = np.random.default_rng(2)
        xy = rng.uniform([-0.2, -0.2], [self.W * RES + 0.2, self.H * RES + 0.2], (20000, 2))
        frac = np.abs(xy / RES - np.round(xy / RES) - 0.0)  # offset from pixel centres, pixels
        off_edges = (np.abs(frac - 0.5) > 0.02).all(axis=1)  # devkit rounding at exact edges is arbitrary
        corners = np.array(shapely.box((30 - 0.5) * RES, (self.H - 49 - 0.5) * RES, (49 + 0.5) * RES,
                                       (self.H - 45 + 0.5) * RES).exterior.coords[:4])
        off_corners = np.linalg.norm(xy[:, None] - corners[None], axis=2).min(axis=1) > 0.6 * RES
        keep = off_edges & off_corners
        theirs = MapMask(str(path), resolution=RES).is_on_mask(xy[keep, 0], xy[keep, 1])
        ours = shapely.contains_xy(u, xy[keep, 0], xy[keep, 1])
        assert keep.sum() > 15000 and theirs.any()
        np.testing.assert_array_equal(ours, theirs)

    def test_bottom_left_origin(self, tmp_path):
        img = np.zeros((self.H, self.W), np.uint8)
        img[-3:, :4] = 255  # the bottom-left corner of the image
        u = _union(_raster(tmp_path, img, simplify_px=0.0, min_area_m2=0.01))
        np.testing.assert_allclose(u.bounds, [-0.05, 0.05, 0.35, 0.35], atol=1e-9)

    def test_small_parts_and_holes_dropped(self, tmp_path):
        img = np.zeros((self.H, self.W), np.uint8)
        img[5:45, 5:45] = 255
        img[20:22, 20:22] = 0  # 0.04 m2 hole: filled
        img[50:52, 60:62] = 255  # 0.04 m2 island: dropped
        u = _union(_raster(tmp_path, img, min_area_m2=1.0))
        assert isinstance(u, shapely.Polygon) and len(u.interiors) == 0
        assert u.area == pytest.approx(16.0, abs=1e-6)

    @pytest.mark.parametrize("simplify_px, min_agree", [(0.0, 0.999), (1.0, 0.98)])
    def test_irregular_blobs_agree_with_the_pixels(self, tmp_path, simplify_px, min_agree):
        rng = np.random.default_rng(1)
        field = cv2.GaussianBlur(rng.random((120, 150)), (0, 0), 4)
        img = np.where(field > np.median(field), 255, 0).astype(np.uint8)
        img[rng.random(img.shape) < 0.01] = 255  # lone pixels, diagonal neighbours
        u = _union(_raster(tmp_path, img, band_rows=16, simplify_px=simplify_px, min_area_m2=0.0, tile_m=4.0,
                           overlap_m=0.5))
        rows, cols = np.mgrid[0:120, 0:150]
        xy = pixel_to_global(rows.ravel(), cols.ravel(), 120)
        inside = shapely.contains_xy(u, xy[:, 0], xy[:, 1])
        agree = np.mean(inside == (img.ravel() == 255))
        # pixel centres: all but single background pixels touching the outside diagonally (filled); simplified
        # by 1 px (0.1 m) the staircase moves
        assert agree >= min_agree, agree
        assert u.area == pytest.approx((img == 255).sum() * RES ** 2, rel=0.05)

    def test_empty_raster(self, tmp_path):
        r = _raster(tmp_path, np.zeros((10, 12), np.uint8))
        assert r.area.geometries == [] and r.drivable_pixels == 0
        assert not r.area.contains_xy(np.array([[0.5, 0.5]])).any()


# ---------------------------------------------------------------------- the map table and the reader


class TestMapTable:
    ROWS = [{"token": "m1", "category": "semantic_prior", "filename": "maps/a.png", "log_tokens": ["l1", "l2"]},
            {"token": "m2", "category": "prior_probability", "filename": "maps/b.png", "log_tokens": ["l3"]}]

    def test_row_of_a_log(self):
        assert semantic_prior_row(self.ROWS, "l2", "v/map.json")["token"] == "m1"

    def test_errors(self):
        with pytest.raises(DatasetError, match=r"v/map\.json: no map row lists log 'l9' in its 'log_tokens'"):
            semantic_prior_row(self.ROWS, "l9", "v/map.json")
        with pytest.raises(DatasetError, match=r"v/map\.json row 1 \(token m2\) field 'category': expected "
                                               r"'semantic_prior'.*got 'prior_probability'"):
            semantic_prior_row(self.ROWS, "l3", "v/map.json")
        rows = self.ROWS + [{"token": "m3", "category": "semantic_prior", "filename": "maps/c.png", "log_tokens": ["l1"]}]
        with pytest.raises(DatasetError, match=r"rows \[0, 2\] all list log 'l1' but name different files"):
            semantic_prior_row(rows, "l1", "v/map.json")
        with pytest.raises(DatasetError, match=r"field 'filename': expected the path of the raster PNG"):
            semantic_prior_row([{"token": "m", "category": "semantic_prior", "log_tokens": ["l"]}], "l", "v/map.json")


def _mini_root(root: Path, map_rows: list[dict], location: str = "town") -> Path:
    version = root / "v1.0-test"
    version.mkdir(parents=True)
    for t in REQUIRED_TABLES:
        (version / f"{t}.json").write_text("[]")
    (version / "log.json").write_text(json.dumps([{"token": "log0", "location": location, "logfile": "l",
                                                   "vehicle": "v", "date_captured": "2020-01-01"}]))
    (version / "map.json").write_text(json.dumps(map_rows))
    return root


class TestReaderFallback:
    def test_raster_when_there_is_no_expansion(self, tmp_path):
        img = np.zeros((30, 40), np.uint8)
        img[10:25, 5:35] = 255
        root = _mini_root(tmp_path / "d", [{"token": "m", "category": "semantic_prior", "filename": "maps/m.png",
                                            "log_tokens": ["log0"]}])
        (root / "maps").mkdir()
        write_png(root / "maps" / "m.png", img, [1])
        reader = NuScenesReader(root, "v1.0-test")
        assert reader.map_source("town") == MAP_SOURCE_RASTER
        assert reader.map_sources == {"town": MAP_SOURCE_RASTER}
        assert reader.lanes("town") is None
        area = reader.drivable_area("town", "log0")
        assert shapely.union_all(area.geometries).area == pytest.approx(15 * 30 * RES ** 2)
        assert reader.raster_map("town").drivable_pixels == 15 * 30
        # the map expansion, when present, wins
        other = _mini_root(tmp_path / "e", [{"token": "m", "category": "semantic_prior", "filename": "maps/m.png",
                                             "log_tokens": ["log0"]}])
        shutil.copytree(root / "maps", other / "maps")
        (other / "maps" / "expansion").mkdir()
        nodes = [{"token": f"n{i}", "x": x, "y": y} for i, (x, y) in enumerate([(0, 0), (1, 0), (1, 1)])]
        (other / "maps" / "expansion" / "town.json").write_text(json.dumps({
            "node": nodes, "polygon": [{"token": "p", "exterior_node_tokens": ["n0", "n1", "n2"], "holes": []}],
            "drivable_area": [{"token": "d", "polygon_tokens": ["p"]}]}))
        r2 = NuScenesReader(other, "v1.0-test")
        assert r2.map_source("town") == MAP_SOURCE_EXPANSION and r2.raster_map("town") is None
        assert shapely.union_all(r2.drivable_area("town").geometries).area == pytest.approx(0.5)

    def test_no_file_named_is_no_map(self, tmp_path):
        root = _mini_root(tmp_path / "d", [{"token": "m", "category": "semantic_prior", "filename": "",
                                            "log_tokens": ["log0"]}])
        reader = NuScenesReader(root, "v1.0-test")
        assert reader.drivable_area("town") is None and reader.map_source("town") is None

    @pytest.mark.parametrize("case", ["missing", "category", "no-row", "not-png"])
    def test_errors_name_the_table_field_or_file(self, tmp_path, case):
        row = {"token": "m", "category": "semantic_prior", "filename": "maps/m.png", "log_tokens": ["log0"]}
        if case == "category":
            row["category"] = "lidar_prior"
        if case == "no-row":
            row["log_tokens"] = ["another-log"]
        root = _mini_root(tmp_path / "d", [row])
        if case == "not-png":
            (root / "maps").mkdir()
            (root / "maps" / "m.png").write_bytes(b"GIF89a" + b"\0" * 40)
        expected = {"missing": r"maps/m\.png: semantic-prior raster not found \(v1\.0-test/map\.json row 0 "
                               r"\(token m\) field 'filename'\); install maps/expansion/town\.json",
                    "category": r"map\.json row 0 \(token m\) field 'category': expected 'semantic_prior'",
                    "no-row": r"map\.json: no map row lists log 'log0'",
                    "not-png": r"maps/m\.png: not a PNG file"}[case]
        reader = NuScenesReader(root, "v1.0-test")
        with pytest.raises(DatasetError, match=expected):
            reader.drivable_area("town")
        with pytest.raises(DatasetError, match=expected):  # remembered: every sample of the location fails alike
            reader.map_source("town")
        assert NuScenesReader(root, "v1.0-test", with_map=False).with_map is False


# ---------------------------------------------------------------------- the real raster (scene-0916)


def _copy_dataroot(dst: Path, n_samples: int) -> tuple[Path, list[str]]:
    """Tables + raster + the keyframe files of the first ``n_samples`` samples; NO map expansion (copies)."""
    shutil.copytree(SEQ / "v1.0-mini", dst / "v1.0-mini")
    (dst / "maps").mkdir(parents=True)
    shutil.copy2(SEQ_PNG, dst / "maps" / SEQ_PNG.name)
    reader = NuScenesReader(dst, "v1.0-mini")
    tokens = reader.sample_tokens()[:n_samples]
    for t in tokens:
        for sd in reader.sample_data_rows(t):
            (dst / sd["filename"]).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(SEQ / sd["filename"], dst / sd["filename"])
    return dst, tokens


@pytest.fixture(scope="module")
def base_release(tmp_path_factory):
    """(reader without expansion, sample tokens with files, seconds and peak traced MB of the first map read)."""
    if not SEQ_PNG.is_file():
        pytest.skip(f"{SEQ} (real scene-0916 with its raster map) not present")
    root, tokens = _copy_dataroot(tmp_path_factory.mktemp("base-release"), 1)
    assert not (root / "maps" / "expansion").exists()
    reader = NuScenesReader(root, "v1.0-mini")
    tracemalloc.start()
    t0 = time.perf_counter()
    source = reader.map_source(LOCATION)
    seconds = time.perf_counter() - t0
    peak_mb = tracemalloc.get_traced_memory()[1] / 2 ** 20
    tracemalloc.stop()
    assert source == MAP_SOURCE_RASTER
    return reader, tokens, seconds, peak_mb


@needs_seq
class TestRealRaster:
    def test_agrees_with_the_derived_expansion(self, base_release):
        reader, _, seconds, peak_mb = base_release
        raster = shapely.union_all(reader.drivable_area(LOCATION).geometries)
        expansion = shapely.union_all(read_drivable_area(SEQ / "maps" / "expansion" / f"{LOCATION}.json"))
        a, b = raster.intersection(CROP), expansion.intersection(CROP)
        iou = a.intersection(b).area / a.union(b).area
        info = reader.raster_map(LOCATION)
        print(f"\nraster {info.width_px} x {info.height_px}: decode {info.decode_s:.1f} s, vectorise "
              f"{info.vectorise_s:.1f} s (map read {seconds:.1f} s, peak traced {peak_mb:.0f} MB), "
              f"{info.n_vertices} vertices in {len(info.area.geometries)} tiles; IoU with the expansion over "
              f"the crop {iou:.4f} ({a.area:.0f} vs {b.area:.0f} m2)")
        assert (info.width_px, info.height_px) == (32286, 36871)
        assert iou > 0.985, iou
        # the raster's own area (pixels) and the polygons' agree within 1 %
        assert raster.area == pytest.approx(info.raster_area_m2, rel=0.01)
        assert peak_mb < 600, peak_mb  # streamed: never the 1.2 GB raster whole
        assert info.n_vertices < 100_000  # what a worker keeps is small

    def test_every_ego_pose_is_on_it(self, base_release):
        reader = base_release[0]
        xy = np.array([p["translation"][:2] for p in reader.table("ego_pose")])
        on = reader.drivable_area(LOCATION).contains_xy(xy)
        assert len(xy) == 492 and on.all(), f"{(~on).sum()} of {len(xy)} ego poses off the raster's drivable area"

    def test_sample_and_placement_report_the_raster(self, base_release):
        reader, tokens, _, _ = base_release
        sample = reader.sample(tokens[0])
        assert sample.map_source == MAP_SOURCE_RASTER and sample.lanes is None
        view = sample.cameras["CAM_FRONT"]
        cfg = PlacementConfig()
        area, reason = drivable_area_for_sample(sample, view, cfg)
        assert reason is None and (area.source, area.confidence) == ("map-raster", "high")
        objects = [ObjectBox(np.array([1.9, 4.5, 1.6]), "vehicle.car") for _ in range(3)]
        res = place_objects(sample, view, objects, np.random.default_rng(0), cfg)
        assert res.placements, res.reason
        assert {p.drivable_source for p in res.placements} == {"map-raster"}
        assert {p.drivable_confidence for p in res.placements} == {"high"}
        # the same sample with the (derived) expansion: same camera, same seed
        full = NuScenesReader(SEQ, "v1.0-mini").sample(tokens[0])
        assert full.map_source == MAP_SOURCE_EXPANSION
        res_exp = place_objects(full, full.cameras["CAM_FRONT"], objects, np.random.default_rng(0), cfg)
        assert {p.drivable_source for p in res_exp.placements} == {"map"}
        print(f"\nCAM_FRONT of {tokens[0]}: {len(res.placements)} of 3 placed with the raster, "
              f"{len(res_exp.placements)} of 3 with the expansion")
