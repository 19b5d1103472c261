"""A peak-memory estimate of an insertion, checked before the expensive stages (decode, render).

Calibrated on measured peak RSS of ``streetaug insert --image`` (a 4.4 m box at 15 m, focal length = the
image side, so the object's screen size grows with the image): 1000 x 1000 px -> 420 MB (draft) /
432 MB (default); 3000 x 3000 px -> 922 / 946 MB. That is ~360 MB of code and models plus ~63 bytes per
image pixel (the image, its depth, mask, shadow and float32 HDR buffers). A batch worker with the six
1600 x 900 nuScenes cameras of a sample in memory peaks at ~580 MB, as the estimate says.
"""

from __future__ import annotations

from typing import Iterable

from ..core.limits import ResourceLimits, check_memory_estimate

BASE_BYTES = 360 * 2**20
# Bytes per image pixel by render preset: measured for draft and default (+10 % margin); high (more
# samples per pixel, larger shading buffers) not measured, taken larger.
BYTES_PER_PIXEL = {"draft": 70, "default": 72, "high": 96}


def estimate_peak_bytes(image_sizes: Iterable[tuple[int, int]], quality: str) -> float:
    """Estimated peak memory (bytes) of inserting into images of ``image_sizes`` ((width, height) each) held
    in memory together, with render preset ``quality``."""
    per_pixel = BYTES_PER_PIXEL.get(quality, max(BYTES_PER_PIXEL.values()))
    return BASE_BYTES + per_pixel * sum(int(w) * int(h) for w, h in image_sizes)


def check_insert_memory(image_sizes: Iterable[tuple[int, int]], quality: str, stage: str,
                        limits: ResourceLimits | None = None) -> None:
    """Refuse (``InputError``) before ``stage`` when its estimate is above ``limits.max_memory_mb``."""
    sizes = list(image_sizes)
    check_memory_estimate(estimate_peak_bytes(sizes, quality),
                          f"{stage} ({len(sizes)} image(s) of {', '.join(f'{w} x {h}' for w, h in sizes)} px)",
                          limits or ResourceLimits.from_env())
