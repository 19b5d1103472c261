"""Paths read from untrusted places (dataset tables, asset files) stay inside their root; outputs stay out of sources.

A table's ``filename`` or an asset's URI is joined to its root and resolved, symlinks included; anything that
lands outside the root is refused with an :class:`InputError` that names where the path came from.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError


def is_inside(path: str | Path, root: str | Path) -> bool:
    """True if ``path`` (resolved, symlinks followed) is ``root`` or lies below it."""
    return Path(path).resolve().is_relative_to(Path(root).resolve())


def resolve_inside(root: str | Path, relative: str, where: str) -> Path:
    """``root / relative``, resolved, refused unless it stays inside ``root``.

    Convention: the path must not be absolute nor climb out with ``..``; after symlinks it must lie inside
    ``root``, or inside the target of a symlinked folder at the top of ``root`` (``samples -> /disk2/samples``,
    a usual way to assemble a dataroot); a link deeper down that leaves those is refused.

    Args:
        root: the folder the path must stay in (a dataroot, an asset folder).
        relative: the path as written in the source (a table's ``filename``, a glTF ``uri``).
        where: where it was read, for the message (e.g. ``"sample_data.json row 12 (token ab12) field 'filename'"``).

    Raises:
        InputError: absolute paths, ``..`` escapes and symlinks leading outside ``root``.
    """
    if not isinstance(relative, str) or not relative.strip():
        raise InputError(f"{where}: expected a relative path inside {root}, got {relative!r}")
    if "\x00" in relative:
        raise InputError(f"{where}: the path {relative!r} contains a NUL byte")
    if Path(relative).is_absolute():
        raise InputError(f"{where}: {relative!r} is an absolute path; paths must be relative to {root}")
    parts = Path(os.path.normpath(relative)).parts
    if parts[0] == "..":
        raise InputError(f"{where}: {relative!r} climbs outside {root} with '..'; paths must stay inside it")
    root_resolved = Path(root).resolve()
    allowed = [root_resolved]
    top = Path(root) / parts[0]
    if len(parts) > 1 and top.is_symlink() and top.is_dir():
        allowed.append(top.resolve())
    path = (root_resolved / relative).resolve()
    if not any(path.is_relative_to(a) for a in allowed):
        raise InputError(f"{where}: {relative!r} resolves to {path}, outside {root_resolved}; "
                         "paths in tables and assets must stay inside their root (symlinks included)")
    return path


def refuse_output_inside(out: str | Path, source_root: str | Path, what: str = "the source dataset") -> None:
    """Raise unless the output folder ``out`` is neither inside ``source_root`` nor contains it.

    Writing into a source (its root, its table folder, ``samples/CAM_FRONT``) would modify the input; an output
    that contains the source would make a later ``rm -r OUT`` delete it.
    """
    out_r, src_r = Path(out).resolve(), Path(source_root).resolve()
    if out_r.is_relative_to(src_r):
        raise InputError(f"--out {out} is inside {what} ({src_r}); write the outputs somewhere else")
    if src_r.is_relative_to(out_r):
        raise InputError(f"--out {out} contains {what} ({src_r}); write the outputs somewhere else")


def refuse_overwriting_inputs(out: str | Path, output_names: list[str], inputs: dict[str, str | Path | None]) -> None:
    """Raise if writing ``out/<name>`` for any of ``output_names`` would replace one of the ``inputs``.

    Args:
        out: the output folder.
        output_names: the files the command writes into it (e.g. ``["image.png", "labels.json"]``).
        inputs: option name -> input path (None entries are ignored), for the message.
    """
    targets = {(Path(out) / name).resolve(): name for name in output_names}
    for option, path in inputs.items():
        if path is not None and Path(path).resolve() in targets:
            raise InputError(f"--out {out} would overwrite the input {option} {path} with its "
                             f"{targets[Path(path).resolve()]}; write the outputs somewhere else")
