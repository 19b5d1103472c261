"""Resource limits: refuse, before decoding, inputs that would exhaust memory or time.

An image's size is read from its header (PNG, JPEG, EXR) without decoding it, so a 20000 x 20000 input or a
small glTF with a 13000 x 13000 texture is refused (or, for textures, downscaled while decoding) at once.
Limits come from :class:`ResourceLimits` (defaults below, overridable by ``STREETAUG_MAX_*`` environment
variables and by the CLI's ``--max-*`` options).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, fields, replace
from pathlib import Path

from .errors import InputError

_ENV_PREFIX = "STREETAUG_"


@dataclass(frozen=True)
class ResourceLimits:
    """Upper bounds on inputs (all positive integers).

    Attributes:
        max_image_pixels: camera images, depth maps, env maps (width x height). nuScenes images are 1.44 MP.
        max_texture_side: textures larger than this on either side are downscaled while decoding.
        max_texture_pixels: textures above this many pixels (before downscaling) are refused: decoding them
            alone would take ``4 x`` as many bytes.
        max_triangles: triangles of one asset.
        max_memory_mb: an estimate of a stage's peak memory above this is refused before the stage runs.
    """

    max_image_pixels: int = 64_000_000
    max_texture_side: int = 4096
    max_texture_pixels: int = 100_000_000
    max_triangles: int = 2_000_000
    max_memory_mb: int = 8192

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise InputError(f"resource limit {f.name} must be a positive integer, got {value!r}")

    @classmethod
    def from_env(cls, environ: dict[str, str] | None = None) -> "ResourceLimits":
        """Defaults overridden by ``STREETAUG_MAX_IMAGE_PIXELS`` etc. (the field name in upper case)."""
        environ = os.environ if environ is None else environ
        overrides = {}
        for f in fields(cls):
            key = _ENV_PREFIX + f.name.upper()
            if key in environ:
                try:
                    overrides[f.name] = int(environ[key])
                except ValueError:
                    raise InputError(f"environment variable {key}: expected a positive integer, "
                                     f"got {environ[key]!r}") from None
        return replace(cls(), **overrides)


def _png_size(head: bytes) -> tuple[int, int] | None:
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        return struct.unpack(">II", head[16:24])
    return None


_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
            i += 2
            continue
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if marker in _JPEG_SOF:
            height, width = struct.unpack(">HH", data[i + 5:i + 9])
            return width, height
        i += 2 + length
    return None


def image_size_from_bytes(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG or JPEG header, or None if the format is not recognised."""
    return _png_size(data[:32]) or _jpeg_size(data)


def image_size_from_header(path: str | Path, max_header_bytes: int = 1 << 20) -> tuple[int, int] | None:
    """(width, height) of a PNG, JPEG or EXR file read from its header only, or None if not recognised."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(max_header_bytes)
    size = image_size_from_bytes(head)
    if size is None and head[:4] == b"\x76\x2f\x31\x01":  # OpenEXR magic
        import OpenEXR  # deferred: only EXR inputs need it

        (x0, y0), (x1, y1) = OpenEXR.File(str(path), header_only=True).header()["dataWindow"]
        size = (int(x1) - int(x0) + 1, int(y1) - int(y0) + 1)
    return size


def check_image_pixels(size: tuple[int, int], source: str, limits: ResourceLimits) -> None:
    """Raise unless ``size`` = (width, height) is within ``limits.max_image_pixels``."""
    width, height = size
    if width * height > limits.max_image_pixels:
        raise InputError(f"{source}: the image is {width} x {height} = {width * height / 1e6:.1f} MP, above the "
                         f"limit of {limits.max_image_pixels / 1e6:.1f} MP (raise it with --max-image-pixels or "
                         "STREETAUG_MAX_IMAGE_PIXELS if the machine has the memory)")


def texture_reduction(size: tuple[int, int], source: str, limits: ResourceLimits) -> int:
    """The power-of-two factor (1, 2, 4, 8, ...) a texture of ``size`` is reduced by while decoding.

    Raises:
        InputError: the texture has more than ``limits.max_texture_pixels`` pixels.
    """
    width, height = size
    if width * height > limits.max_texture_pixels:
        raise InputError(f"{source}: texture of {width} x {height} = {width * height / 1e6:.0f} MP is above the "
                         f"limit of {limits.max_texture_pixels / 1e6:.0f} MP (STREETAUG_MAX_TEXTURE_PIXELS); "
                         "downscale it in the asset")
    factor = 1
    while max(width, height) / factor > limits.max_texture_side:
        factor *= 2
    return factor


def check_triangles(n_triangles: int, source: str, limits: ResourceLimits) -> None:
    """Raise unless an asset's triangle count is within ``limits.max_triangles``."""
    if n_triangles > limits.max_triangles:
        raise InputError(f"{source}: {n_triangles} triangles, above the limit of {limits.max_triangles} "
                         "(STREETAUG_MAX_TRIANGLES); decimate the asset")


def check_memory_estimate(estimate_bytes: float, stage: str, limits: ResourceLimits) -> None:
    """Raise before ``stage`` runs when its estimated peak memory is above ``limits.max_memory_mb``."""
    if estimate_bytes > limits.max_memory_mb * 2**20:
        raise InputError(f"{stage}: would need about {estimate_bytes / 2**30:.1f} GiB, above the limit of "
                         f"{limits.max_memory_mb / 1024:.1f} GiB (STREETAUG_MAX_MEMORY_MB)")
