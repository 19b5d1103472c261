"""The nuScenes base-release map: the ``semantic_prior`` raster of a log, vectorised to drivable-area polygons.

Without the map expansion (``maps/expansion/<location>.json``) a nuScenes release still carries, per
location, one 8-bit greyscale PNG named by the ``map`` table (``<version>/map.json`` rows
``{token, category: "semantic_prior", filename: "maps/<hash>.png", log_tokens: [...]}``): drivable
surface = 255, everything else 0, ``0.1`` m per pixel, covering the whole location.

Convention (the devkit's ``MapMask``, ``nuscenes/utils/map_mask.py``)::

    col = round(x / res)            x = col * res            (x east, metres)
    row = round(H - y / res)        y = (H - row) * res      (y north, metres; H = image height, pixels)

    row 0      +---------------------------+   y = H * res   (top of the image = north)
               |                           |
               |        pixel (row, col) = the square of side res centred on (col * res, (H - row) * res)
    row H - 1  +---------------------------+   y = res
               x = 0                       x = (W - 1) * res

i.e. the origin is at the bottom-left, y up, and pixel *centres* sit on the multiples of ``res``.

The decoded raster of a big location is more than a gigapixel (singapore-queenstown: 32286 x 36871,
1.19 Gpx; ``cv2.imread`` refuses it, Pillow calls it a decompression bomb), so it is never held whole when
avoidable: :func:`iter_png_bands` decodes the PNG as a stream, ``band_rows`` image rows at a time (zlib +
the PNG row filters None / Sub / Up in numpy; files using the Average or Paeth filters are decoded whole
by Pillow instead, its decompression-bomb guard lifted explicitly for this one file after our own size
check). Each band is traced with ``cv2.findContours`` (outer boundaries and holes, through drivable pixel
centres), grown by half a pixel with mitred joins (pixel centres -> pixel edges), all bands are united on
a 1/64-pixel grid (band seams merge exactly), simplified (Douglas-Peucker, topology preserving), parts
and holes smaller than ``min_area_m2`` dropped, and the result cut into overlapping square tiles (so a
spatial index finds the few near a camera). What is kept is only those tiles: :class:`RasterDrivable`.

Accuracy: every pixel centre lands on the right side (before simplification), convex corners are exact;
the 8-connected trace cuts concave pixel corners (< 0.3 px^2 each), and a lone background pixel touching
the outside diagonally is filled. With the default 1-pixel simplification, IoU with the derived expansion
of nuscenes-seq is 0.993 over its crop.

Measured on singapore-queenstown (2 shared cores, band_rows 512): decode ~6-9 s, vectorise ~11-14 s,
peak RSS ~+120 MB over the process (Pillow's whole decode: 1.3 GB); kept: 177 tiles, ~11.4k vertices
(~180 kB of WKB).
"""

from __future__ import annotations

import contextlib
import struct
import threading
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from .errors import DatasetError
from .nuscenes_map import DrivableArea

SEMANTIC_PRIOR = "semantic_prior"
DRIVABLE_VALUE = 255
RESOLUTION_M = 0.1
MAP_SOURCE_EXPANSION = "expansion"
MAP_SOURCE_RASTER = "semantic-prior raster"
# Pixel-count ceiling we accept (the largest nuScenes map is 1.19 Gpx; 4 Gpx = a 6.3 km square at 0.1 m).
MAX_PIXELS = 4_000_000_000

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PIL_LOCK = threading.Lock()


# ---------------------------------------------------------------------- conventions


def pixel_to_global(row: np.ndarray, col: np.ndarray, height_px: int,
                    resolution_m: float = RESOLUTION_M) -> np.ndarray:
    """Global x/y (N, 2), metres, of pixel centres (``row``, ``col``) (N,) of a raster ``height_px`` rows high.

    Convention: x = col * res, y = (height_px - row) * res (devkit ``MapMask``; see the module docstring).
    """
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    return np.stack([col * resolution_m, (height_px - row) * resolution_m], axis=-1)


def global_to_pixel(xy_global: np.ndarray, height_px: int,
                    resolution_m: float = RESOLUTION_M) -> tuple[np.ndarray, np.ndarray]:
    """(row (N,), col (N,)) int64 of the pixels holding global x/y points (N, 2) (devkit rounding)."""
    xy = np.asarray(xy_global, dtype=np.float64).reshape(-1, 2)
    col = np.round(xy[:, 0] / resolution_m).astype(np.int64)
    row = np.round(height_px - xy[:, 1] / resolution_m).astype(np.int64)
    return row, col


# ---------------------------------------------------------------------- the map table


def semantic_prior_row(map_rows: list[dict], log_token: str, table_path: str) -> dict:
    """The ``map`` row whose ``log_tokens`` list ``log_token``, checked to be a semantic-prior raster.

    Raises:
        DatasetError: no row lists the log, several do with different files, or the row's ``category``
            is not ``semantic_prior`` (each names the table, the row and the field).
    """
    hits = [(i, r) for i, r in enumerate(map_rows)
            if isinstance(r, dict) and log_token in (r.get("log_tokens") or [])]
    if not hits:
        raise DatasetError(f"{table_path}: no map row lists log {log_token!r} in its 'log_tokens' "
                           f"({len(map_rows)} map rows); every log needs the map of its location")
    files = {r.get("filename") for _, r in hits}
    if len(files) > 1:
        raise DatasetError(f"{table_path}: rows {[i for i, _ in hits]} all list log {log_token!r} but name "
                           f"different files {sorted(map(str, files))}; one map per log expected")
    i, row = hits[0]
    category = row.get("category")
    if category != SEMANTIC_PRIOR:
        raise DatasetError(f"{table_path} row {i} (token {row.get('token')}) field 'category': expected "
                           f"{SEMANTIC_PRIOR!r} (the drivable-surface raster), got {category!r}")
    if not isinstance(row.get("filename"), str):
        raise DatasetError(f"{table_path} row {i} (token {row.get('token')}) field 'filename': expected the "
                           f"path of the raster PNG (e.g. 'maps/<hash>.png'), got {row.get('filename')!r}")
    return row


# ---------------------------------------------------------------------- PNG decoding


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an 8-bit greyscale, non-interlaced PNG, read from its header.

    Raises:
        DatasetError: not a PNG, or not 8-bit greyscale non-interlaced (names the file and what it is).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: semantic-prior raster not found")
    with open(path, "rb") as f:
        head = f.read(33)
    if len(head) < 33 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise DatasetError(f"{path}: not a PNG file (no PNG signature and IHDR header); the semantic-prior "
                           "raster must be the PNG of the nuScenes release")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", head[16:29])
    if depth != 8 or colour != 0:
        raise DatasetError(f"{path}: expected an 8-bit greyscale PNG (bit depth 8, colour type 0), got bit "
                           f"depth {depth}, colour type {colour}")
    if interlace != 0:
        raise DatasetError(f"{path}: interlaced (Adam7) PNG; the semantic-prior raster is expected non-interlaced")
    if width == 0 or height == 0 or width * height > MAX_PIXELS:
        raise DatasetError(f"{path}: raster of {width} x {height} pixels; expected 1 .. {MAX_PIXELS} pixels")
    return width, height


class _NeedsWholeDecode(Exception):
    """A row uses the Average or Paeth filter (sequential per pixel): decode the file whole instead."""


def _stream_bands(path: Path, width: int, height: int, band_rows: int) -> Iterator[tuple[int, np.ndarray]]:
    stride = width + 1
    inflate = zlib.decompressobj()
    pending = bytearray()
    prior = np.zeros(width, dtype=np.uint8)
    row0 = 0
    with open(path, "rb") as f:
        f.seek(8)
        while row0 < height:
            head = f.read(8)
            if len(head) < 8:
                raise DatasetError(f"{path}: PNG ends after {row0} of {height} rows (truncated file)")
            length, kind = struct.unpack(">I4s", head)
            chunk = f.read(length)
            f.seek(4, 1)  # CRC
            if len(chunk) < length:
                raise DatasetError(f"{path}: PNG ends inside a {kind!r} chunk after {row0} of {height} rows")
            if kind == b"IEND":
                raise DatasetError(f"{path}: PNG image data ends after {row0} of {height} rows")
            if kind != b"IDAT":
                continue
            try:
                pending += inflate.decompress(chunk)
            except zlib.error as e:
                raise DatasetError(f"{path}: corrupt PNG image data after {row0} rows ({e})") from None
            while row0 < height and (len(pending) >= band_rows * stride or
                                     (len(pending) >= stride and row0 + len(pending) // stride >= height)):
                n = min(len(pending) // stride, band_rows, height - row0)
                raw = np.frombuffer(pending, dtype=np.uint8, count=n * stride).reshape(n, stride)
                band = _unfilter(raw, prior, path, row0)
                del raw  # releases the buffer export so that pending can shrink
                del pending[:n * stride]
                prior = band[-1]
                yield row0, band
                row0 += n


def _unfilter(raw: np.ndarray, prior: np.ndarray, path: Path, row0: int) -> np.ndarray:
    """Undo the PNG row filters of raw rows (n, 1 + W) (bytes per pixel 1); ``prior``: the row above (W,)."""
    kinds = raw[:, 0]
    if np.any(kinds > 4):
        bad = int(np.argmax(kinds > 4))
        raise DatasetError(f"{path}: row {row0 + bad} has PNG filter type {int(kinds[bad])}; expected 0..4")
    if np.any(kinds >= 3):
        raise _NeedsWholeDecode
    out = np.empty((len(raw), raw.shape[1] - 1), dtype=np.uint8)
    none = kinds == 0
    if none.any():
        out[none] = raw[none, 1:]
    sub = kinds == 1
    if sub.all():
        out[:] = _undo_sub(raw[:, 1:])
    elif sub.any():
        out[sub] = _undo_sub(raw[sub, 1:])
    for i in np.flatnonzero(kinds == 2):  # Up: needs the decoded row above
        out[i] = raw[i, 1:] + (out[i - 1] if i > 0 else prior)  # uint8 wraps: the filter's modulo 256
    return out


def _nonzero_bytes(buffer: np.ndarray) -> np.ndarray:
    """Sorted flat indices of the non-zero bytes of a 1-D uint8 array (fast when they are few)."""
    n = len(buffer)
    pad = (-n) % 8
    words = np.concatenate([buffer, np.zeros(pad, np.uint8)]) if pad else buffer
    hot = np.flatnonzero(words.view(np.uint64))  # 8 bytes per test
    if len(hot) == 0:
        return hot
    candidates = (hot[:, None] * 8 + np.arange(8)).reshape(-1)
    return candidates[words[candidates] != 0]


def _undo_sub(deltas: np.ndarray) -> np.ndarray:
    """Rows (k, W) uint8 of the PNG Sub filter decoded: each row's running sum modulo 256.

    Map rows are long runs of one value, so the few non-zero deltas are summed per row and the runs
    expanded with ``np.repeat`` (several times faster than a dense ``cumsum`` over a gigapixel).
    """
    k, width = deltas.shape
    deltas = np.ascontiguousarray(deltas).reshape(-1)
    flat = _nonzero_bytes(deltas)
    rr = flat // width
    running = np.cumsum(deltas[flat], dtype=np.int64)
    first = np.searchsorted(rr, np.arange(k))  # index of each row's first non-zero delta
    before = np.concatenate([[0], running])[first]  # running sum before each row starts
    values = (running - before[rr]) % 256
    # runs: each row starts at value 0, then changes at every non-zero delta
    starts = np.concatenate([np.arange(k) * width, flat])
    vals = np.concatenate([np.zeros(k, dtype=np.int64), values])
    order = np.argsort(starts, kind="stable")  # a row start sorts before a change at column 0
    starts, vals = starts[order], vals[order]
    lengths = np.diff(np.append(starts, k * width))
    return np.repeat(vals.astype(np.uint8), lengths).reshape(k, width)


@contextlib.contextmanager
def _pillow_bomb_guard_lifted():
    """Pillow refuses images above 2 x ``MAX_IMAGE_PIXELS`` (89 Mpx) as decompression bombs, on opening and on
    cropping; our own ceiling (``MAX_PIXELS``, checked by :func:`png_size`) replaces it for the raster only."""
    from PIL import Image

    with _PIL_LOCK:
        saved = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = saved


def _whole_with_pillow(path: Path, width: int, height: int):
    """The image decoded whole by Pillow (a loaded ``PIL.Image`` of mode L), for filters we do not stream."""
    from PIL import Image

    with _pillow_bomb_guard_lifted():
        try:
            im = Image.open(path)
            im.load()
        except (OSError, SyntaxError, ValueError) as e:
            raise DatasetError(f"{path}: cannot decode the PNG ({type(e).__name__}: {e})") from None
    if im.mode != "L" or im.size != (width, height):
        raise DatasetError(f"{path}: decoded as {im.mode} {im.size[0]} x {im.size[1]}; expected "
                           f"8-bit greyscale (L) {width} x {height}")
    return im


def iter_png_bands(path: str | Path, band_rows: int = 512) -> Iterator[tuple[int, np.ndarray]]:
    """Decode an 8-bit greyscale PNG ``band_rows`` rows at a time: yields (first row, band (n, W) uint8).

    Streams (memory ~ a few bands) when the file uses only the None / Sub / Up row filters (the nuScenes
    rasters use Sub); otherwise decodes the whole image with Pillow (memory ~ the image: 1.2 GB for
    singapore-queenstown) and yields its bands. (``cv2.imread`` refuses images above 2^30 pixels.)

    Raises:
        DatasetError: missing, not an 8-bit greyscale PNG, truncated or corrupt (names the file).
    """
    path = Path(path)
    width, height = png_size(path)
    try:
        yielded = 0
        for row0, band in _stream_bands(path, width, height, band_rows):
            yield row0, band
            yielded = row0 + len(band)
        return
    except _NeedsWholeDecode:
        pass
    image = _whole_with_pillow(path, width, height)
    try:
        for row0 in range(yielded, height, band_rows):
            with _pillow_bomb_guard_lifted():
                band = np.asarray(image.crop((0, row0, width, min(row0 + band_rows, height))), dtype=np.uint8)
            yield row0, band
    finally:
        image.close()


# ---------------------------------------------------------------------- vectorising


def _band_polygons(mask: np.ndarray, row0: int) -> list:
    """Pixel-edge polygons (pixel units: x = col, y = row) of the True pixels of a band (n, W) bool."""
    contours, hierarchy = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return []
    hierarchy = hierarchy[0]
    offset = np.array([0.0, float(row0)])
    out = []
    for i, c in enumerate(contours):
        if hierarchy[i, 3] != -1:
            continue  # a hole: taken with its outer contour
        ring = c[:, 0, :].astype(np.float64) + offset
        holes, j = [], hierarchy[i, 2]
        while j != -1:
            h = contours[j][:, 0, :].astype(np.float64) + offset
            if len(h) >= 3:
                holes.append(h)
            j = hierarchy[j, 0]
        poly = Polygon(ring, holes) if len(ring) >= 3 else None
        if poly is not None and poly.is_valid and poly.area > 0:
            grown = poly.buffer(0.5, join_style="mitre", mitre_limit=2.0)
        else:  # a line or a point of pixel centres, or rings touching themselves
            base = shapely.LineString(ring) if len(ring) >= 2 else shapely.Point(ring[0])
            grown = base.buffer(0.5, cap_style="square", join_style="mitre", mitre_limit=2.0)
            if poly is not None and not poly.is_valid:
                grown = shapely.union(grown, shapely.make_valid(poly).buffer(0.5, join_style="mitre",
                                                                             mitre_limit=2.0))
        out.append(grown)
    return out


def _drop_small(geometry, min_area_px: float) -> list[Polygon]:
    parts = getattr(geometry, "geoms", [geometry])
    kept = []
    for p in parts:
        if not isinstance(p, Polygon) or p.area < min_area_px:
            continue
        holes = [h for h in p.interiors if Polygon(h).area >= min_area_px]
        kept.append(Polygon(p.exterior, holes))
    return kept


def _tiles(polygons: list[Polygon], tile_m: float, overlap_m: float) -> list:
    """The polygons cut into squares of side ``tile_m`` grown by ``overlap_m`` (pieces overlap: no seams)."""
    if not polygons:
        return []
    area = MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]
    x0, y0, x1, y1 = area.bounds
    shapely.prepare(area)
    pieces = []
    for tx in np.arange(np.floor(x0 / tile_m) * tile_m, x1, tile_m):
        for ty in np.arange(np.floor(y0 / tile_m) * tile_m, y1, tile_m):
            window = shapely.box(tx - overlap_m, ty - overlap_m, tx + tile_m + overlap_m, ty + tile_m + overlap_m)
            if not area.intersects(window):
                continue
            piece = shapely.intersection(area, window)
            piece = _polygonal(piece)
            if not piece.is_empty and piece.area > 0:
                pieces.append(piece)
    return pieces


def _polygonal(geometry):
    if isinstance(geometry, (Polygon, MultiPolygon)):
        return geometry
    parts = [g for g in getattr(geometry, "geoms", []) if isinstance(g, (Polygon, MultiPolygon))]
    return shapely.union_all(parts) if parts else Polygon()


@dataclass(frozen=True)
class RasterDrivable:
    """The drivable area of one semantic-prior raster, vectorised.

    Attributes:
        area: the polygons (global x/y, metres) as overlapping tiles with a spatial index
            (``area.geometries``; their union is the drivable area).
        path: the raster file.
        width_px, height_px: raster size, pixels.
        resolution_m: metres per pixel.
        drivable_pixels: pixels == 255 in the raster (their area = drivable_pixels * resolution_m**2).
        n_vertices: coordinates kept in all tiles.
        decode_s, vectorise_s: wall time spent decoding the PNG and tracing / uniting / tiling, seconds.
    """

    area: DrivableArea
    path: str
    width_px: int
    height_px: int
    resolution_m: float
    drivable_pixels: int
    n_vertices: int
    decode_s: float
    vectorise_s: float

    @property
    def raster_area_m2(self) -> float:
        return self.drivable_pixels * self.resolution_m ** 2


def read_semantic_prior(path: str | Path, resolution_m: float = RESOLUTION_M, *, band_rows: int = 512,
                        simplify_px: float = 1.0, min_area_m2: float = 1.0, tile_m: float = 100.0,
                        overlap_m: float = 2.0) -> RasterDrivable:
    """Vectorise the drivable surface (pixels == 255) of a semantic-prior PNG into global x/y polygons.

    Args:
        path: the PNG (8-bit greyscale).
        resolution_m: metres per pixel (0.1 for nuScenes v1.0).
        band_rows: rows decoded and traced at a time (memory ~ band_rows x width bytes, x ~6 while tracing).
        simplify_px: Douglas-Peucker tolerance, pixels (topology preserving); 0 keeps the pixel staircase.
        min_area_m2: drivable parts and holes smaller than this are dropped.
        tile_m, overlap_m: tile side and overlap of the kept pieces, metres.

    Raises:
        DatasetError: the file is missing, not an 8-bit greyscale PNG, truncated or corrupt.
    """
    path = Path(path)
    width, height = png_size(path)
    t0 = time.perf_counter()
    decode_s = 0.0
    parts: list = []
    n_drivable = 0
    t_band = time.perf_counter()
    for row0, band in iter_png_bands(path, band_rows):
        decode_s += time.perf_counter() - t_band
        mask = band == DRIVABLE_VALUE
        n_drivable += int(np.count_nonzero(mask))
        if n_drivable:
            parts.extend(_band_polygons(mask, row0))
        del band, mask
        t_band = time.perf_counter()
    decode_s += time.perf_counter() - t_band
    # pixel units (x = col, y = row): the grown rings sit on half-integers, exact on a 1/64 grid
    united = shapely.union_all(parts, grid_size=1.0 / 64) if parts else Polygon()
    del parts
    if simplify_px > 0:
        united = shapely.simplify(united, simplify_px, preserve_topology=True)
    polygons = _drop_small(united, min_area_m2 / resolution_m ** 2)
    polygons = [shapely.transform(p, lambda c: np.c_[c[:, 0] * resolution_m, (height - c[:, 1]) * resolution_m])
                for p in polygons]
    polygons = [p if p.is_valid else _polygonal(shapely.make_valid(p)) for p in polygons]
    pieces = _tiles(polygons, tile_m, overlap_m)
    area = DrivableArea(pieces, shapely.STRtree(pieces))
    n_vertices = int(sum(shapely.get_num_coordinates(p) for p in pieces))
    return RasterDrivable(area, str(path), width, height, resolution_m, n_drivable, n_vertices, decode_s,
                          time.perf_counter() - t0 - decode_s)
