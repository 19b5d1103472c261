"""A peak-memory estimate of an insertion, checked before the expensive stages (decode, render).

Calibrated on measured peak RSS of ``streetaug insert --image`` (a 4.4 m box at 15 m, focal length = the
image side, so the object's screen size grows with the image): 1000 x 1000 px -> 420 MB (draft) /
432 MB (default); 3000 x 3000 px -> 922 / 946 MB. That is ~360 MB of code and models plus ~63 bytes per
image pixel (the image, its depth, mask, shadow and float32 HDR buffers).

A batch worker on the real scene-0916 (six 1600 x 900 cameras per sample, default quality, the sky model
loaded) peaks at 1.29-1.45 GB, above the estimate (0.98 GB): ~370 MB of code, models and maps; ~17 MB per
camera kept until the sample is written (image, depth, mask, shadow); ~66 MB per object already drawn in
the camera being rendered (the renderer's full-frame layers, kept until the camera was done: since then only
its mask and coverage in its pixel box are kept, ``pipeline.objects.RenderedObject``); and the
render of one object, ~0.4-1 kB per camera sample of its pixel box: 564 MB when the object's box straddles
the camera plane and its pixel box is the whole frame (``render.footprint.object_pixel_box``), 300 MB for a
car filling a fifth of the frame. The estimate does not model the last two (they depend on where the
objects are, not on the image size).

Since then (session 8, scene-0916, one worker): the renderer traces an object's pixel box in chunks
(``render.foreground.TRACE_CHUNK_RAYS``), so its memory no longer grows with the box beyond its per-pixel
sums and shade's light-sample batch (~155 MB at ``shade.SHADE_CHUNK_RAYS``): a car at 4.5 m (439k px)
293 MB traced instead of 396. Of the "370 MB of code, models and maps", 116 MB are the imports and ~190-240
MB what a worker holds after a sample once its freed heap is returned (``batch.execute.release_free_heap``,
after each sample); the rest was freed memory the tuned malloc kept. A worker's peak (0.64-0.76 GB) is now
within one sample, in the lighting's level choice (``lighting.multiview.choose_auto``: ~250 MB transient).

Session 10 (issue #19; scene-0916, default, ``benchmarks/bench_batch.py``): with ``choose_auto`` bounded
(``levels.HeightMap.blocked``) the peak was in the render of an object late in a sample: ~300-400 MB live
(the sample's lighting with its seen surfaces ~70 MB, six depth maps 33 MB, the images 25 MB, the cameras
already rendered: image, mask and shadow ratio, ~16 MB each) plus the render's largest batches: the shadow's
sky test (``render.shadow.SHADOW_CHUNK_RAYS`` 1M rays: ~210 MB), shade's environment samples
(``render.shade.SHADE_CHUNK_RAYS`` 300k: ~130 MB) and the composite's nine full-frame layers (69 MB; the veil
in float64 over the object's box, up to ~130 MB for a near object). With 250k / 100k rays, the layers held in
the object's box (``render.composite.ObjectLayers``) and the veil on the object's pixels, no stage of a render
adds more than ~70 MB (tracemalloc): peak RSS 772 -> 660 MB (first 4 keyframes, 1 worker) and 732 -> 640 MB
(8 keyframes, 2 workers). A worker holds ~190-235 MB between samples (RSS after the heap release; ~75-110 MB
of it malloc'd): nothing of a sample stays alive into the next.

Later in session 10 (same scene and bench): the renderer's result (``render.Insertion``, and
the composite's ``Composited``) holds its layers inside the object's / shadow's pixel box (mask, coverage,
depth, ratios, radiance: ~63 MB of full-frame float layers per object before; the full-frame attributes are
now properties building a new array), ``render_objects`` updates the depth, mask union and shadow product
box-locally, the composite's noise is drawn in 64k-pixel row chunks (same random stream; 66 -> 8 MB
tracemalloc peak for a whole-frame box) and the shadow's coarse-to-fine sky grid is interpolated in blocks
(52 -> 6 MB for a whole-frame grid); outputs byte-identical. Peak RSS, first 4 keyframes, 1 worker:
611 -> 592 MB (median of 3 interleaved runs each: 618, 611, 605 -> 592, 591, 602;
``benchmarks/results/batch_seq4_s10_mem2_{before,after}.json``). The whole scene, 2 workers: 671 / 687 MB
(``batch_seq_full_s10_mem2.json``; 692 / 726 before the per-camera results were held in their box, 660 / 669
with them: the peaks move by ~30 MB between runs). The
worker's high-water creep over a scene (fragmentation of the tuned heap?) is not addressed.
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
