"""Byte-offset indexes of large nuScenes table files: find and read rows without parsing the whole table.

A nuScenes table is one JSON array of flat objects (field values: strings, numbers, booleans, null, arrays of
those). One streaming pass (numpy over windows of the file's bytes, memory bounded by the window) finds each
row's byte span and the values of the fields lookups need (``token``; ``sample_token`` for ``sample_data`` and
``sample_annotation``), kept as 64-bit hashes sorted for binary search. A row is read by seeking to its span and
parsing that slice alone; its field is compared with the value asked for, so a hash collision or a stale index
can never return a wrong row.

The index is cached under ``$XDG_CACHE_HOME/streetaug/tables/`` (default ``~/.cache/streetaug/tables``) as an
``.npz`` of plain arrays (no pickles; ``np.load(..., allow_pickle=False)`` reads it), keyed by the file's
absolute path, size and ``mtime_ns`` and :data:`INDEX_FORMAT`; written atomically (temp file + ``os.replace``)
with its arrays 64-byte aligned, so that a later run memory-maps them (milliseconds, whatever the table's
size). A cache folder that cannot be written: the index is kept in memory only (one warning). A stale or
unreadable cache file: rebuilt; one found damaged while used: removed, the lookup fails naming it.

The scan refuses (:class:`UnexpectedLayout`) anything it is not sure to read as ``json.loads`` would: nested
objects, text between rows other than one comma, a looked-up field that is not a plain string (escapes
included) or appears twice in a row, a row without ``token``, a sampled row whose parse disagrees. The caller
then parses the file whole, as for a small table, and reports what that finds.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import struct
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from .errors import DatasetError

INDEX_FORMAT = 2
WINDOW_BYTES = 4 << 20  # bytes scanned at a time (the scan's memory is a few times this; small: in cache)
VERIFIED_ROWS = 64  # rows parsed after a scan to check the index against json.loads
_MAX_VALUE_BYTES = 256  # longest indexed field value (nuScenes tokens: 32)
_SHORT_GAP = 8  # bytes between a key and its value checked in numpy (longer: in Python)

_QUOTE, _BACKSLASH, _COMMA, _COLON, _OPEN, _CLOSE = 0x22, 0x5C, 0x2C, 0x3A, 0x7B, 0x7D
_WHITESPACE = b" \t\n\r"
_IS_SPACE = np.zeros(256, dtype=bool)
_IS_SPACE[list(_WHITESPACE)] = True
_MIX_A, _MIX_B = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9)
_ALIGN_FIELD = 0xD935  # zip extra field id padding a member's data to alignment (as Android's zipalign)
_PAD = _MAX_VALUE_BYTES + 16  # zero bytes after each window: gathers need no bounds checks

log = logging.getLogger(__name__)
_warned: set[str] = set()
_scans = 0


class UnexpectedLayout(Exception):
    """The file is not laid out as the scan reads tables; parse it whole instead."""


def scan_count() -> int:
    """How many table files this process has scanned (index builds; cache hits do not count)."""
    return _scans


def cache_folder() -> Path:
    """``$XDG_CACHE_HOME/streetaug/tables`` (an absolute XDG_CACHE_HOME), else ``~/.cache/streetaug/tables``."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and os.path.isabs(base) else Path.home() / ".cache"
    return root / "streetaug" / "tables"


# ---------------------------------------------------------------------------- hashing


def value_hashes(values: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(N,) uint64 hashes of N byte strings: ``values`` (N, L) uint8 holding them, zero past ``lengths`` (N,).

    The string's 8-byte words (little-endian, zero padded) mixed in turn (multiply-xorshift), after its length.
    """
    n, width = values.shape
    words = -(-width // 8)
    padded = np.zeros((n, 8 * words), dtype=np.uint8)
    padded[:, :width] = values
    padded = padded.view("<u8")
    lengths = lengths.astype(np.uint64)
    hashes = lengths * _MIX_A + _MIX_B
    with np.errstate(over="ignore"):
        for j in range(words):
            mixed = (hashes ^ padded[:, j]) * _MIX_A
            mixed ^= mixed >> np.uint64(31)
            hashes = np.where(lengths > np.uint64(8 * j), mixed, hashes)
    return hashes


def text_hash(text: str) -> np.uint64:
    """The :func:`value_hashes` hash of ``text`` (UTF-8), as the scan records a field holding it."""
    raw = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    return value_hashes(raw[None, :], np.array([raw.size]))[0]


# ---------------------------------------------------------------------------- the scan


def _gather(window: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """(N, width) bytes of ``window`` from each of ``starts`` (``window`` is followed by _PAD zero bytes)."""
    return np.lib.stride_tricks.as_strided(window, (len(window), width), (1, 1), writeable=False)[starts]


def _words(window: np.ndarray) -> np.ndarray:
    """(len(window),) little-endian uint64: the 8 bytes from each position (``window`` is zero padded)."""
    return np.lib.stride_tricks.as_strided(window, (len(window), 8), (1, 1), writeable=False).view("<u8")[:, 0]


def _equal_bytes(words: np.ndarray, starts: np.ndarray, text: bytes) -> np.ndarray:
    """(N,) bool: the bytes from each of ``starts`` begin with ``text`` (``words``: :func:`_words`)."""
    same = np.ones(len(starts), dtype=bool)
    for at in range(0, len(text), 8):
        part = text[at: at + 8]
        mask = np.uint64((1 << (8 * len(part))) - 1)
        same &= (words[starts + at] & mask) == np.uint64(int.from_bytes(part, "little"))
    return same


def _unescaped_quotes(window: np.ndarray) -> np.ndarray:
    """Positions of the ``"`` that open or close strings (not those after an odd run of backslashes)."""
    quotes = np.flatnonzero(window == _QUOTE)
    maybe = quotes[window[quotes - 1] == _BACKSLASH]  # (a quote at 0 looks at the last byte: checked below)
    if maybe.size == 0:
        return quotes
    escaped = []
    for p in maybe.tolist():
        j = p - 1
        while j >= 0 and window[j] == _BACKSLASH:
            j -= 1
        if p > 0 and (p - 1 - j) % 2:
            escaped.append(p)
    return np.setdiff1d(quotes, np.array(escaped, dtype=quotes.dtype), assume_unique=True)


def _check_gaps(window: np.ndarray, starts: np.ndarray, stops: np.ndarray, separator: int) -> bool:
    """Every ``window[start:stop]`` is whitespace around exactly one ``separator`` byte."""
    length = stops - starts
    if length.size == 0:
        return True
    if np.any(length <= 0):
        return False
    width = int(length[0])
    if width <= 8 and np.all(length == width):  # one layout throughout (e.g. ",\n "): compare 8-byte words
        mask = np.uint64((1 << (8 * width)) - 1)
        words = _words(window)[starts] & mask
        sample = int(words[0]).to_bytes(8, "little")[:width]
        if np.all(words == words[0]):
            return sample.strip(_WHITESPACE) == bytes([separator])
    first = np.cumsum(length) - length  # where each gap begins in the flat list of gap bytes
    flat = window[np.repeat(starts - first, length) + np.arange(int(length.sum()))]
    solid = ~_IS_SPACE[flat]
    return bool(np.all(np.add.reduceat(solid, first) == 1) and np.all(flat[solid] == separator))


def _field_keys(window: np.ndarray, opens: np.ndarray, closes: np.ndarray,
                keys: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The strings that are the keys ``keys`` of fields: (string indices k, ascending; which key each is).

    The field's value is string k + 1.

    Raises:
        UnexpectedLayout: such a field's value is not a string.
    """
    found, which = [], []
    words, length = _words(window), closes - opens - 1
    for n, key in enumerate(keys):
        name = key.encode()
        k = np.flatnonzero(length == len(name))
        k = k[_equal_bytes(words, opens[k] + 1, name)]
        found.append(k)
        which.append(np.full(len(k), n, dtype=np.int64))
    k, which = np.concatenate(found), np.concatenate(which)
    last = k == len(opens) - 1  # no string after it: a key here has a value that is not a string
    nxt = np.where(last, len(window), opens[np.minimum(k + 1, len(opens) - 1)])
    gap = nxt - closes[k] - 1
    if np.all(gap == 2) and np.all(window[closes[k] + 1] == _COLON) and np.all(_IS_SPACE[window[closes[k] + 2]]):
        is_key = np.ones(len(k), dtype=bool)  # '"key": "value"', the usual layout
    else:
        is_key = np.zeros(len(k), dtype=bool)
        short = np.flatnonzero(gap <= _SHORT_GAP)
        seg = _gather(window, closes[k[short]] + 1, _SHORT_GAP)
        solid = (np.arange(_SHORT_GAP) < gap[short, None]) & ~_IS_SPACE[seg]
        colon_first = solid.any(axis=1) & (seg[np.arange(len(seg)), np.argmax(solid, axis=1)] == _COLON)
        if np.any(colon_first & ((solid.sum(axis=1) != 1) | last[short])):
            raise UnexpectedLayout("an indexed field with a value that is not a string")
        is_key[short] = colon_first
        for i in np.flatnonzero(gap > _SHORT_GAP).tolist():
            text = window[closes[k[i]] + 1: nxt[i]].tobytes().lstrip(_WHITESPACE)
            if text.startswith(b":"):
                if text[1:].strip(_WHITESPACE) or last[i]:
                    raise UnexpectedLayout("an indexed field with a value that is not a string")
                is_key[i] = True
    k, which = k[is_key], which[is_key]
    order = np.argsort(k, kind="stable")
    return k[order], which[order]


def _scan_window(window: np.ndarray, first: bool, at_end: bool,
                 keys: tuple[str, ...]) -> tuple[int, np.ndarray, np.ndarray, dict[str, np.ndarray]] | None:
    """Rows wholly inside ``window`` (which starts outside any string: at the file's start or a row's ``}``;
    it is followed by _PAD zero bytes).

    Returns (bytes consumed: the position of the last row's ``}``, row starts, row ends (inclusive), key ->
    (rows,) uint64 value hashes), or None when no row ends in the window (read a larger one).
    """
    quotes = _unescaped_quotes(window)
    braces = np.flatnonzero(window >= _OPEN)  # { | } ~ and bytes >= 128 (UTF-8)
    braces = braces[(window[braces] == _OPEN) | (window[braces] == _CLOSE)]
    braces = braces[(np.searchsorted(quotes, braces) & 1) == 0]  # outside strings
    if not first:
        if braces.size == 0 or braces[0] != 0:
            raise UnexpectedLayout("a window that does not start at a row's end")
        braces = braces[1:]  # window[0]: the previous window's last row end
    ends_at = np.flatnonzero(window[braces] == _CLOSE)
    if ends_at.size == 0:
        if not at_end:
            return None
        braces = braces[:0]
    elif not at_end:
        braces = braces[: ends_at[-1] + 1]
    kinds = window[braces]
    if kinds.size % 2 or np.any(kinds[0::2] != _OPEN) or np.any(kinds[1::2] != _CLOSE):
        raise UnexpectedLayout("rows that are not flat JSON objects")
    starts, ends = braces[0::2], braces[1::2]
    if at_end:
        tail_from = int(ends[-1]) + 1 if ends.size else (0 if first else 1)
        if window[tail_from:].tobytes().strip(_WHITESPACE) != b"]":
            raise UnexpectedLayout("text after the last row other than ']'")
    if ends.size == 0:
        if first:
            raise UnexpectedLayout("no rows")
        return len(window), starts, ends, {key: np.zeros(0, np.uint64) for key in keys}
    if first:
        if window[: starts[0]].tobytes().strip(_WHITESPACE) != b"[":
            raise UnexpectedLayout("text before the first row other than '['")
        gap_starts, gap_stops = ends[:-1] + 1, starts[1:]
    else:
        gap_starts, gap_stops = np.concatenate([[1], ends[:-1] + 1]), starts
    if not _check_gaps(window, gap_starts, gap_stops, _COMMA):
        raise UnexpectedLayout("text between rows other than one comma")

    inside = quotes[: np.searchsorted(quotes, ends[-1])]
    opens, closes = inside[0::2], inside[1::2]
    k, which = _field_keys(window, opens, closes, keys)
    row = np.searchsorted(starts, opens[k], side="right") - 1
    if np.any(row < 0) or np.any(opens[k] > ends[np.maximum(row, 0)]):
        raise UnexpectedLayout("an indexed field outside a row")
    value_start, value_length = opens[k + 1] + 1, closes[k + 1] - opens[k + 1] - 1
    width = int(value_length.max(initial=0))
    if width > _MAX_VALUE_BYTES:
        raise UnexpectedLayout(f"an indexed field longer than {_MAX_VALUE_BYTES} bytes")
    values = _gather(window, value_start, max(width, 1))
    if value_length.min(initial=width) < width:
        values = np.where(np.arange(values.shape[1]) >= value_length[:, None], np.uint8(0), values)
    if np.any(values == _BACKSLASH):
        raise UnexpectedLayout("an indexed field with an escape sequence")
    value_hash = value_hashes(values, value_length)
    hashes: dict[str, np.ndarray] = {}
    for n, key in enumerate(keys):
        mine = which == n
        count = np.bincount(row[mine], minlength=len(starts))
        if np.any(count > 1) or (n == 0 and np.any(count == 0)):
            raise UnexpectedLayout(f"rows with {'no or ' if n == 0 else ''}two fields '{key}'")
        column = np.full(len(starts), text_hash(""), dtype=np.uint64)  # a missing field reads as ""
        column[row[mine]] = value_hash[mine]
        hashes[key] = column
    return int(ends[-1]), starts, ends, hashes


def scan_table(path: Path, keys: tuple[str, ...], window_bytes: int = WINDOW_BYTES) -> dict[str, np.ndarray]:
    """Row spans and field hashes of a table file, in one pass of ``window_bytes`` windows.

    Returns:
        ``offset`` (rows,) int64 byte offset of each row's ``{``; ``length`` (rows,) int64 bytes up to its
        ``}``; per key ``hash_<key>`` (rows,) uint64 (:func:`value_hashes` of the field's raw bytes).

    Raises:
        UnexpectedLayout: the file is not one JSON array of flat objects each with a string ``keys[0]``.
    """
    global _scans
    _scans += 1
    size = os.path.getsize(path)
    offsets, lengths, columns = [], [], {key: [] for key in keys}
    at, first, width = 0, True, window_bytes
    buffer = np.zeros(0, dtype=np.uint8)
    with open(path, "rb") as f:
        while True:
            if len(buffer) < width + _PAD:
                buffer = np.zeros(width + _PAD, dtype=np.uint8)
            f.seek(at)
            got = f.readinto(memoryview(buffer)[:width])
            buffer[got: got + _PAD] = 0
            window = buffer[:got]
            at_end = at + got >= size
            found = _scan_window(window, first, at_end, keys)
            if found is None:
                width *= 2  # a row longer than the window
                continue
            used, starts, ends, hashes = found
            offsets.append(starts + at)
            lengths.append(ends - starts + 1)
            for key in keys:
                columns[key].append(hashes[key])
            if at_end:
                break
            at, first, width = at + used, False, window_bytes
    out = {"offset": np.concatenate(offsets).astype(np.int64), "length": np.concatenate(lengths).astype(np.int64)}
    out.update({f"hash_{key}": np.concatenate(columns[key]) for key in keys})
    return out


# ---------------------------------------------------------------------------- the index


class TableIndex:
    """Rows of one table file by position, ``token`` and other indexed fields, read on demand (and kept).

    Args:
        path: the table file.
        arrays: ``offset``, ``length`` (rows,) int64 and per key ``sorted_<key>`` (rows,) uint64 hashes in
            ascending order with ``order_<key>`` (rows,) the row of each (equal hashes: rows in any order).
        keys: the indexed fields, ``token`` first.
    """

    def __init__(self, path: Path, arrays: dict[str, np.ndarray], keys: tuple[str, ...],
                 cache_file: Path | None = None) -> None:
        self.path, self.keys, self.cache_file = Path(path), keys, cache_file
        self.size = os.path.getsize(self.path)
        self.offset, self.length = arrays["offset"], arrays["length"]
        self._sorted = {key: arrays[f"sorted_{key}"] for key in keys}
        self._order = {key: arrays[f"order_{key}"] for key in keys}
        self._rows: dict[int, dict] = {}

    def __len__(self) -> int:
        return len(self.offset)

    def _candidates(self, key: str, value: str) -> list[int]:
        """Rows whose ``key`` hash equals that of ``value``, ascending."""
        h = text_hash(value)
        sorted_hashes = self._sorted[key]
        lo, hi = np.searchsorted(sorted_hashes, h, side="left"), np.searchsorted(sorted_hashes, h, side="right")
        rows = np.sort(self._order[key][lo:hi])
        if rows.size and (rows[0] < 0 or rows[-1] >= len(self)):
            self._damaged(f"row {int(rows[-1])} of {len(self)}")
        return rows.tolist()

    def _damaged(self, what: str) -> None:
        """DatasetError for a cached index found inconsistent while used (the cache file is removed)."""
        if self.cache_file is not None:
            try:
                os.unlink(self.cache_file)
            except OSError:
                pass
        raise DatasetError(f"{self.cache_file or 'the index'} of table {self.path}: inconsistent ({what}); "
                           "removed: run again to index the table afresh")

    def find(self, token: object) -> int | None:
        """The row number of ``token``, or None."""
        if not isinstance(token, str):
            return None
        for i in self._candidates("token", token):
            if self.row(i).get("token") == token:
                return i
        return None

    def rows_where(self, key: str, value: str) -> list[dict]:
        """The rows whose field ``key`` (an indexed one; missing reads as ``""``) equals ``value``, in file order."""
        candidates = self._candidates(key, value)
        self.read(candidates)
        return [self._rows[i] for i in candidates if self._rows[i].get(key, "") == value]

    def row(self, i: int) -> dict:
        """Row ``i`` of the file (parsed once, then the same dict)."""
        if i not in self._rows:
            self.read([i])
        return self._rows[i]

    def read(self, rows: list[int]) -> None:
        """Parse the rows ``rows`` not read yet (one open of the file, in file order)."""
        todo = sorted(i for i in set(rows) if i not in self._rows)
        if not todo:
            return
        with open(self.path, "rb") as f:
            for i in todo:
                start, length = int(self.offset[i]), int(self.length[i])
                if start < 0 or length <= 0 or start + length > self.size:
                    self._damaged(f"row {i} at bytes {start}-{start + length} of {self.size}")
                f.seek(start)
                data = f.read(length)
                try:
                    row = json.loads(data)
                except (json.JSONDecodeError, UnicodeDecodeError) as e:
                    raise DatasetError(f"{self.path}: table is not valid JSON (row {i}, bytes {start}-"
                                       f"{start + length}: {e})") from None
                except RecursionError:
                    raise DatasetError(f"{self.path}: table JSON nested too deeply to read (row {i})") from None
                if not isinstance(row, dict):
                    raise DatasetError(f"{self.path}: row {i} (bytes {start}-{start + length}) is not an object; "
                                       "the table changed after it was indexed")
                self._rows[i] = row


def _sorted_columns(scan: dict[str, np.ndarray], keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    rows = len(scan["offset"])
    out = {"offset": scan["offset"], "length": scan["length"]}
    order_type = np.int32 if rows < 2**31 else np.int64
    for key in keys:
        order = np.argsort(scan[f"hash_{key}"])  # equal hashes (rare): rows in any order
        out[f"sorted_{key}"] = scan[f"hash_{key}"][order]
        out[f"order_{key}"] = order.astype(order_type)
    return out


def _verify(index: TableIndex, scan: dict[str, np.ndarray]) -> None:
    """Parse up to VERIFIED_ROWS rows spread over the file and compare their fields with the scan's hashes."""
    rows = np.unique(np.linspace(0, len(index) - 1, min(VERIFIED_ROWS, len(index))).astype(np.int64)).tolist()
    try:
        index.read(rows)
    except DatasetError as e:
        raise UnexpectedLayout(str(e)) from None
    for i in rows:
        row = index.row(i)
        for key in index.keys:
            value = row.get(key, "")
            if not isinstance(value, str) or text_hash(value) != scan[f"hash_{key}"][i]:
                raise UnexpectedLayout(f"row {i}: field '{key}' parsed as {value!r}, not as the scan read it")


def _refuse_duplicates(index: TableIndex) -> None:
    """DatasetError naming both rows for the first repeated token (as :func:`.tables.token_index` reports it)."""
    sorted_hashes = index._sorted["token"]
    same = sorted_hashes[1:] == sorted_hashes[:-1]
    if not same.any():
        return
    shared = np.zeros(len(sorted_hashes), dtype=bool)  # rows whose hash another row has too
    shared[1:] |= same
    shared[:-1] |= same
    rows, hashes = np.asarray(index._order["token"])[shared], sorted_hashes[shared]
    by = np.lexsort((rows, hashes))  # by hash, then row
    rows, hashes = rows[by], hashes[by]
    repeat = np.flatnonzero(hashes[1:] == hashes[:-1]) + 1  # not the first row of its hash
    group_start = np.searchsorted(hashes, hashes[repeat], side="left")
    for k in np.argsort(rows[repeat], kind="stable").tolist():  # repeats in row order
        i, earlier = int(rows[repeat[k]]), rows[group_start[k]: repeat[k]].tolist()
        token = index.row(i)["token"]
        matching = [j for j in sorted(earlier) if index.row(j)["token"] == token]
        if matching:
            raise DatasetError(f"{index.path}: token '{token}' appears in rows {matching[0]} and {i}; "
                               "tokens must be unique (the table is corrupt or was concatenated twice)")


def build_index(path: Path, keys: tuple[str, ...], window_bytes: int = WINDOW_BYTES) -> TableIndex:
    """Scan ``path`` (:func:`scan_table`), check it on sampled rows and refuse duplicated tokens.

    Raises:
        UnexpectedLayout: see :func:`scan_table`, or a sampled row disagrees with the scan.
        DatasetError: a token appears twice (naming both rows).
    """
    scan = scan_table(path, keys, window_bytes)
    index = TableIndex(path, _sorted_columns(scan, keys), keys)
    _verify(index, scan)
    _refuse_duplicates(index)
    return index


# ---------------------------------------------------------------------------- the cache


def _cache_file(folder: Path, path: Path, keys: tuple[str, ...]) -> Path:
    digest = hashlib.sha256(f"{INDEX_FORMAT}\0{path}\0{','.join(keys)}".encode()).hexdigest()[:24]
    return folder / f"{path.stem}-{digest}.npz"


def _identity(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    st = os.stat(path)
    return {"format": np.array(INDEX_FORMAT), "size": np.array(st.st_size, np.int64),
            "mtime_ns": np.array(st.st_mtime_ns, np.int64), "path": np.array(str(path)),
            "keys": np.array(",".join(keys))}


def _mapped_npz(file: Path) -> dict[str, np.ndarray]:
    """The arrays of an uncompressed ``.npz`` (as ``np.savez`` writes it), memory-mapped, not read.

    Pages are read when touched (a lookup touches a few), so opening costs milliseconds whatever the table's
    size. Object arrays are refused (no pickles). ``ValueError`` / ``OSError`` on anything else unexpected.
    """
    out = {}
    with zipfile.ZipFile(file) as z, open(file, "rb") as f:
        for info in z.infolist():
            if info.compress_type != zipfile.ZIP_STORED or not info.filename.endswith(".npy"):
                raise ValueError(f"member {info.filename!r} is not a stored .npy")
            f.seek(info.header_offset)
            local = f.read(30)
            if len(local) != 30 or local[:4] != b"PK\x03\x04":
                raise ValueError(f"member {info.filename!r}: no local header")
            name_length, extra_length = struct.unpack("<HH", local[26:30])
            f.seek(info.header_offset + 30 + name_length + extra_length)
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"member {info.filename!r}: .npy version {version}")
            if dtype.hasobject:
                raise ValueError(f"member {info.filename!r} holds Python objects")
            start = f.tell()
            nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
            if start + nbytes > info.header_offset + 30 + name_length + extra_length + info.file_size:
                raise ValueError(f"member {info.filename!r} is shorter than its array")
            name = info.filename[:-4]
            if len(shape) == 1 and nbytes > 0 and start % dtype.alignment == 0:
                out[name] = np.memmap(file, dtype=dtype, mode="r", offset=start, shape=shape,
                                      order="F" if fortran else "C")
            else:
                f.seek(start)
                out[name] = np.frombuffer(f.read(nbytes), dtype=dtype).reshape(shape).copy()
    return out


def _load(file: Path, identity: dict[str, np.ndarray], keys: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """The cached arrays (memory-mapped) when ``file`` holds an index of the same file version, else None.

    Checked here: the file version, the arrays' names, dtypes and lengths, the hashes' order at a few
    places. Each row's span and position are checked when used (:meth:`TableIndex.read`), so a damaged
    cache can fail a lookup (naming the cache file, which is then removed) but never return a wrong row.
    """
    names = ["offset", "length"] + [f"{p}_{k}" for k in keys for p in ("sorted", "order")]
    try:
        z = _mapped_npz(file)
        if any(z[name].shape != value.shape or z[name].item() != value.item() for name, value in identity.items()):
            return None
        arrays = {name: z[name] for name in names}
    except FileNotFoundError:
        return None
    except Exception as e:  # noqa: BLE001 - any unreadable cache file is rebuilt
        log.info("table index cache %s unreadable (%s); rebuilding it", file, e)
        return None
    rows = len(arrays["offset"])
    probe = np.unique(np.linspace(0, max(rows - 2, 0), min(rows, 64)).astype(np.int64))
    if not (rows > 0 and all(a.ndim == 1 and len(a) == rows for a in arrays.values())
            and arrays["offset"].dtype == np.int64 and arrays["length"].dtype == np.int64
            and all(arrays[f"sorted_{k}"].dtype == np.uint64 and arrays[f"order_{k}"].dtype.kind == "i" for k in keys)
            and all(np.all(arrays[f"sorted_{k}"][probe] <= arrays[f"sorted_{k}"][np.minimum(probe + 1, rows - 1)])
                    for k in keys)):
        log.info("table index cache %s inconsistent; rebuilding it", file)
        return None
    return arrays


def _write_aligned_npz(f, arrays: dict[str, np.ndarray]) -> None:
    """An uncompressed ``.npz`` (``np.load`` reads it) whose arrays start at multiples of 64 bytes in the
    file, so that :func:`_mapped_npz` maps them aligned (numpy copies an unaligned array to search it)."""
    with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_STORED) as z:
        for name, array in arrays.items():
            data = io.BytesIO()
            np.lib.format.write_array(data, np.asarray(array, order="C"), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            here = f.tell()  # where this member's local header goes
            pad = -(here + 30 + len(info.filename.encode()) + 4) % 64  # the .npy header is 64-byte padded
            info.extra = struct.pack("<HH", _ALIGN_FIELD, pad) + bytes(pad)
            info.compress_type = zipfile.ZIP_STORED
            z.writestr(info, data.getbuffer())


def _save(file: Path, identity: dict[str, np.ndarray], arrays: dict[str, np.ndarray]) -> bool:
    """Write the index atomically (True); a folder that cannot be written: warn once, False."""
    tmp = None
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=file.parent, prefix=file.stem + ".", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            _write_aligned_npz(f, {**identity, **arrays})
        os.replace(tmp, file)
        tmp = None
        return True
    except OSError as e:
        if str(file.parent) not in _warned:
            _warned.add(str(file.parent))
            log.warning("cannot cache table indexes in %s (%s); indexing in memory for this run", file.parent, e)
        return False
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def open_index(path: Path, keys: tuple[str, ...], cache: Path | None = None) -> TableIndex | None:
    """The index of table file ``path`` over fields ``keys`` (``token`` first), or None to parse it whole.

    From the cache folder ``cache`` (default :func:`cache_folder`) when it holds one for this file's size
    and mtime, else scanned (:func:`build_index`) and cached.

    Raises:
        DatasetError: a token appears twice (naming both rows).
    """
    path = Path(path).absolute()
    identity = _identity(path, keys)
    try:
        folder = cache_folder() if cache is None else Path(cache)
    except RuntimeError:  # no home folder
        folder = None
    file = None if folder is None else _cache_file(folder, path, keys)
    arrays = None if file is None else _load(file, identity, keys)
    if arrays is not None:
        return TableIndex(path, arrays, keys, file)
    try:
        index = build_index(path, keys)
    except UnexpectedLayout as e:
        log.info("%s: not indexed (%s); parsing it whole", path, e)
        return None
    if file is not None and _save(file, identity, {"offset": index.offset, "length": index.length,
                                                   **{f"sorted_{k}": index._sorted[k] for k in keys},
                                                   **{f"order_{k}": index._order[k] for k in keys}}):
        index.cache_file = file
    return index


__all__ = ["INDEX_FORMAT", "TableIndex", "UnexpectedLayout", "build_index", "cache_folder", "open_index",
           "scan_count", "scan_table", "text_hash", "value_hashes"]
