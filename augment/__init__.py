"""streetaug's augmentation library: physically lit 3D objects inserted into driving images.

Sub-packages, bottom up: ``core`` (conventions, errors, I/O, rays, the one LiDAR depth; a leaf),
``assets`` (meshes and materials), ``lighting`` (the scene's light, one front door), ``render`` (the
renderer), ``scenegen`` (the bundled sample scenes), ``pipeline`` (the stages wired together, with the
per-sample context), ``batch`` (whole datasets), ``evaluation`` (metrics, benchmarks, the Mitsuba
reference) and ``training`` (the learned sky model's training). This package itself holds no code:
import from the sub-packages (``from streetaug.augment.pipeline import insert_into_view``).
"""

__all__: list[str] = []
