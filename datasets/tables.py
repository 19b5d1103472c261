"""Reading nuScenes tables as untrusted input: rows indexed by token (duplicates refused), fields checked by kind.

Every message names the table file, the row (index and token) and the field, what was expected and what came,
e.g. ``v1.0-mini/sample_data.json row 4 (token 40a3...) field 'timestamp': expected an integer ...``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .errors import DatasetError


def read_table_rows(path: Path) -> list[dict]:
    """The rows of a table file: a JSON list of objects, each with a ``token``."""
    try:
        rows = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: table is not valid JSON ({e})") from None
    except RecursionError:
        raise DatasetError(f"{path}: table JSON nested too deeply to read") from None
    if not isinstance(rows, list) or not all(isinstance(r, dict) and "token" in r for r in rows):
        raise DatasetError(f"{path}: expected a JSON list of rows, each with a 'token'")
    return rows


def token_index(rows: list[dict], table_file: str) -> dict[str, int]:
    """Token -> position of its row in ``rows``.

    Raises:
        DatasetError: a token appears twice (naming both rows); the last row would silently win otherwise.
    """
    index: dict[str, int] = {}
    for i, row in enumerate(rows):
        token = row["token"]
        if not isinstance(token, str):
            raise DatasetError(f"{table_file} row {i}: field 'token' must be a string, got {token!r}")
        first = index.setdefault(token, i)
        if first != i:
            raise DatasetError(f"{table_file}: token '{token}' appears in rows {first} and {i}; "
                               "tokens must be unique (the table is corrupt or was concatenated twice)")
    return index


def row_where(table_file: str, row_number: int | None, token: Any, field: str | None) -> str:
    """``"<table_file> row 4 (token ab12) field 'filename'"`` (row number / field left out when None)."""
    row = f" row {row_number}" if row_number is not None else ""
    return f"{table_file}{row} (token {token})" + (f" field '{field}'" if field is not None else "")


def integer_field(value: Any, where: str) -> int:
    """A whole number (e.g. a timestamp in microseconds) from a table field, as ``int()`` reads it."""
    if isinstance(value, bool):
        raise DatasetError(f"{where}: expected an integer, got {value!r}")
    try:
        if isinstance(value, float) and not value.is_integer():
            raise ValueError
        return int(value)
    except (TypeError, ValueError, OverflowError):
        raise DatasetError(f"{where}: expected an integer (a timestamp in microseconds), got {value!r}") from None


def vector_field(value: Any, length: int, where: str, what: str) -> np.ndarray:
    """(length,) float64 of finite numbers from a table field."""
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (length,) or not np.all(np.isfinite(v)):
        raise DatasetError(f"{where}: expected {what} ({length} finite numbers), got {_shown(value)}")
    return v


def size_field(value: Any, where: str) -> np.ndarray:
    """(3,) box size [w, l, h] in metres, every side finite and positive."""
    v = vector_field(value, 3, where, "the box size [w, l, h] in metres")
    if np.any(v <= 0):
        raise DatasetError(f"{where}: expected a positive box size [w, l, h] in metres, got {_shown(value)}")
    return v


def rotation_field(value: Any, where: str) -> np.ndarray:
    """(4,) unit quaternion [w, x, y, z] from a table field (normalised; zero or non-finite refused)."""
    q = vector_field(value, 4, where, "a rotation quaternion [w, x, y, z]")
    norm = float(np.linalg.norm(q))
    if not norm > 1e-6:
        raise DatasetError(f"{where}: expected a non-zero rotation quaternion [w, x, y, z], got {_shown(value)}")
    return q / norm


def _shown(value: Any) -> str:
    text = repr(value)
    if isinstance(value, list) and any(isinstance(v, float) and not math.isfinite(v) for v in value):
        text = "[" + ", ".join(str(v) for v in value) + "]"
    return text if len(text) <= 80 else text[:77] + "..."


__all__ = ["integer_field", "read_table_rows", "rotation_field", "row_where", "size_field", "token_index",
           "vector_field"]
