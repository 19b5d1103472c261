"""``augment_log.jsonl``: one JSON line per attempted image, appended by the driver alone.

Crash safety: the lines of one sample are appended in one write and fsync'ed, after its files are in
place. A crash can leave a truncated last line or a sample with only some of its lines; on resume
:func:`compact_log` keeps only the lines of complete samples (whose files exist) and drops the rest,
so the log never holds two lines for one image.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable, Iterable

from ..core import write_bytes_atomic

DONE_STATUSES = ("ok", "skipped")


def read_log(path: Path) -> list[dict]:
    """Rows of a log in file order; lines that do not parse (a crash's truncated tail) are ignored."""
    rows = []
    if not path.is_file():
        return rows
    with open(path, "rb") as f:
        for line in f:
            try:
                row = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                continue
            if isinstance(row, dict) and "sample_token" in row and "camera" in row:
                rows.append(row)
    return rows


def latest_rows(rows: Iterable[dict]) -> dict[tuple[str, str], dict]:
    """(sample_token, camera) -> its last row."""
    return {(r["sample_token"], r["camera"]): r for r in rows}


def done_samples(rows: Iterable[dict], out_dir: Path, expected: Callable[[str], Iterable[str]]) -> set[str]:
    """Samples whose every expected camera has an ok/skipped row whose files exist."""
    by_sample: dict[str, dict[str, dict]] = {}
    for (token, camera), row in latest_rows(rows).items():
        by_sample.setdefault(token, {})[camera] = row
    done = set()
    for token, cams in by_sample.items():
        want = list(expected(token))
        if want and all(c in cams and _row_done(cams[c], out_dir) for c in want):
            done.add(token)
    return done


def _row_done(row: dict, out_dir: Path) -> bool:
    return row.get("status") in DONE_STATUSES and all((out_dir / f).is_file() for f in row.get("files", []))


def compact_log(path: Path, keep: Callable[[dict], bool]) -> list[dict]:
    """Keep the last row per image of rows with ``keep(row)``; rewrite the file (atomically) if that changes it."""
    raw = path.read_bytes() if path.is_file() else b""
    rows = read_log(path)
    kept = [r for r in latest_rows(rows).values() if keep(r)]
    if len(kept) != len(rows) or (raw and not raw.endswith(b"\n")):
        write_bytes_atomic(path, b"".join(_line(r) for r in kept))
    return kept


def append_rows(path: Path, rows: list[dict]) -> None:
    """Append rows in one write, then fsync."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = b"".join(_line(r) for r in rows)
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        while data:
            data = data[os.write(fd, data):]
        os.fsync(fd)
    finally:
        os.close(fd)


def write_log(path: Path, rows: list[dict]) -> None:
    write_bytes_atomic(path, b"".join(_line(r) for r in rows))


def _line(row: dict) -> bytes:
    return (json.dumps(row, sort_keys=True) + "\n").encode()
