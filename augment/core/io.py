"""File I/O at the edges: atomic writes, images, EXR, JSON.

Every writer writes to a temporary file in the destination folder and renames it into place,
so a crash never leaves a half-written file and a rerun can trust whatever exists.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

from .errors import InputError, check_shape
from .limits import ResourceLimits, check_image_pixels, image_size_from_header


_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``, else delete it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _write_error(path: Path, e: OSError) -> InputError:
    return InputError(f"{path}: cannot write ({e.strerror or e}, errno {e.errno}); "
                      "free some space or choose another output folder")


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file, fsync, rename); a failed write names the file."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
    except OSError as e:
        raise _write_error(path, e) from None


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON (numpy scalars/arrays converted)."""
    write_bytes_atomic(path, (json.dumps(obj, indent=2, default=_json_default) + "\n").encode())


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def read_json(path: str | Path) -> Any:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except RecursionError:
        raise InputError(f"{path}: JSON nested too deeply to read") from None


def read_image_rgb(path: str | Path, limits: ResourceLimits | None = None) -> np.ndarray:
    """Read an 8-bit image as (H, W, 3) uint8 RGB; clear error if missing, undecodable or too large.

    The size is checked from the header against ``limits`` (default: :meth:`ResourceLimits.from_env`)
    before anything is decoded.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    size = image_size_from_header(path)
    if size is not None:
        check_image_pixels(size, str(path), limits or ResourceLimits.from_env())
    data = np.fromfile(path, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise InputError(f"{path}: cannot decode image (corrupt or not a PNG/JPEG)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def encode_image_rgb(image: np.ndarray, suffix: str, jpeg_quality: int = 95) -> bytes:
    """Encode (H, W, 3) uint8 RGB (or (H, W) gray) as PNG or JPEG bytes by ``suffix``."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if suffix.lower() in (".jpg", ".jpeg") else []
    ok, buf = cv2.imencode(suffix, bgr, params)
    if not ok:
        raise ValueError(f"cannot encode image as {suffix}")
    return buf.tobytes()


def write_image_rgb(path: str | Path, image: np.ndarray, jpeg_quality: int = 95) -> None:
    """Atomically write (H, W, 3) uint8 RGB or (H, W) uint8 gray as PNG/JPEG (by extension)."""
    write_bytes_atomic(path, encode_image_rgb(image, Path(path).suffix, jpeg_quality))


def read_exr(path: str | Path) -> np.ndarray:
    """Read an EXR as float32 (H, W, 3) RGB (or (H, W, 1) for a single channel)."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: EXR file not found")
    size = image_size_from_header(path) if path.stat().st_size >= 4 else None
    if size is not None:
        check_image_pixels(size, str(path), ResourceLimits.from_env())
    try:
        with OpenEXR.File(str(path)) as f:
            channels = {name: np.array(ch.pixels, dtype=np.float32) for name, ch in f.channels().items()}
    except Exception as e:  # OpenEXR raises RuntimeError/OSError with little context
        raise InputError(f"{path}: cannot read EXR ({e})") from None
    if "RGB" in channels:
        return channels["RGB"]
    if "RGBA" in channels:
        return channels["RGBA"][..., :3]
    if all(c in channels for c in ("R", "G", "B")):
        return np.stack([channels[c] for c in "RGB"], axis=-1)
    if len(channels) == 1:
        (only,) = channels.values()
        return only[..., None] if only.ndim == 2 else only
    raise InputError(f"{path}: EXR has channels {sorted(channels)}, expected RGB or a single channel")


def write_exr(path: str | Path, image: np.ndarray) -> None:
    """Atomically write float32 (H, W, 3) as an RGB EXR or (H, W) as a single 'Y' channel."""
    import OpenEXR

    image = np.ascontiguousarray(np.asarray(image, dtype=np.float32))
    if image.ndim == 2:
        channels = {"Y": image}
    else:
        check_shape(image, ("H", "W", 3), "EXR image")
        channels = {"RGB": image}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            with OpenEXR.File(header, channels) as f:
                f.write(str(tmp))
    except OSError as e:
        raise _write_error(path, e) from None
