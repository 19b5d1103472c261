"""``augment_log.jsonl``: one :class:`~.row.LogRow` per attempted image, appended by the driver alone.

Crash safety: the lines of one sample are appended in one write and fsync'ed, after its files are in
place. A crash can leave a truncated last line or a sample with only some of its lines; on resume
:func:`compact_log` keeps only the lines of complete samples (whose files are there with the size and
sha256 their row recorded) and drops the rest, so the log never holds two lines for one image.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Callable, Iterable

from ..core import write_bytes_atomic
from .row import LogRow


def read_log(path: Path) -> list[LogRow]:
    """Rows of a log in file order; lines that do not parse (a crash's truncated tail) are ignored."""
    rows = []
    if not path.is_file():
        return rows
    with open(path, "rb") as f:
        for line in f:
            try:
                doc = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                continue
            if isinstance(doc, dict) and "sample_token" in doc and "camera" in doc:
                rows.append(LogRow.from_json(doc))
    return rows


def latest_rows(rows: Iterable[LogRow]) -> dict[tuple[str, str], LogRow]:
    """(sample_token, camera) -> its last row."""
    return {r.key: r for r in rows}


def done_samples(rows: Iterable[LogRow], out_dir: Path, expected: Callable[[str], Iterable[str]]) -> set[str]:
    """Samples whose every expected camera has an ok/skipped row whose files exist."""
    by_sample: dict[str, dict[str, LogRow]] = {}
    for (token, camera), row in latest_rows(rows).items():
        by_sample.setdefault(token, {})[camera] = row
    done = set()
    verified: dict[str, bool] = {}  # a sample's LiDAR sweep is on each of its camera rows: hashed once
    for token, cams in by_sample.items():
        want = list(expected(token))
        if want and all(c in cams and row_complete(cams[c], out_dir, verified) for c in want):
            done.add(token)
    return done


def file_check(path: Path) -> dict[str, int | str]:
    """``{"size": bytes, "sha256": hex}`` of a file (what the log records of each output)."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
            size += len(block)
    return {"size": size, "sha256": digest.hexdigest()}


def file_intact(path: Path, check: dict | None) -> bool:
    """``path`` exists and, when ``check`` is given, has its recorded size and sha256."""
    if not path.is_file():
        return False
    if not check:
        return True  # a log written before checks were recorded: existence only
    if path.stat().st_size != check.get("size"):
        return False
    return file_check(path)["sha256"] == check.get("sha256")


def row_complete(row: LogRow, out_dir: Path, verified: dict[str, bool] | None = None) -> bool:
    """The row's image is done (ok / skipped) and every file it wrote is under ``out_dir`` as written
    (same size and sha256 as logged): a truncated or overwritten output is redone.

    Args:
        verified: file -> result of earlier checks of this resume (filled in here).
    """
    if not row.done:
        return False
    verified = {} if verified is None else verified
    checks = row.file_checks or {}
    for f in row.files:
        if f not in verified:
            verified[f] = file_intact(out_dir / f, checks.get(f))
        if not verified[f]:
            return False
    return True


def compact_log(path: Path, keep: Callable[[LogRow], bool]) -> list[LogRow]:
    """Keep the last row per image of rows with ``keep(row)``; rewrite the file (atomically) if that changes it."""
    raw = path.read_bytes() if path.is_file() else b""
    rows = read_log(path)
    kept = [r for r in latest_rows(rows).values() if keep(r)]
    if len(kept) != len(rows) or (raw and not raw.endswith(b"\n")):
        write_bytes_atomic(path, b"".join(log_line(r) for r in kept))
    return kept


def append_rows(path: Path, rows: list[LogRow]) -> None:
    """Append rows in one write, then fsync."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = b"".join(log_line(r) for r in rows)
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        while data:
            data = data[os.write(fd, data):]
        os.fsync(fd)
    finally:
        os.close(fd)


def write_log(path: Path, rows: list[LogRow]) -> None:
    """Write a whole log (atomically)."""
    write_bytes_atomic(path, b"".join(log_line(r) for r in rows))


def log_line(row: LogRow) -> bytes:
    """One line of the log: the row's JSON with sorted keys."""
    return (json.dumps(row.to_json(), sort_keys=True) + "\n").encode()
