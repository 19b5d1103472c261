"""Scale of the lighting where the input camera saw nothing: one-north, L2 from CAM_FRONT alone.

Usage: ``python benchmarks/bench_unseen_bands.py [--level L2]``. For each camera of the one-north keyframe, the
mean LDR value of the rendered view (the map at that camera's centre, EV 0, 320 px) and of the real view in
three horizontal image bands (top = mostly sky, middle = facades, bottom = road). A bias here, not misplaced
detail, is what holds PSNR under si-PSNR. Writes ``benchmarks/results/unseen_bands.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.core import hdr_to_ldr  # noqa: E402
from streetaug.augment.core.io import write_json_atomic  # noqa: E402
from streetaug.augment.lighting.api import estimate_views_lighting  # noqa: E402
from streetaug.augment.lighting.predicted_view import observed_ldr, predicted_radiance  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
BANDS = ("top", "middle", "bottom")


def band_means(ldr: np.ndarray) -> list[float]:
    """Mean value of the image's top, middle and bottom thirds (H, W, 3) in [0, 1]."""
    return [float(b.mean()) for b in np.array_split(ldr, 3, axis=0)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--level", default="L2")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args()
    sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    sl = estimate_views_lighting([sample.cameras["CAM_FRONT"]], sample.location, args.level,
                                 lidar=sample.lidar, boxes=sample.boxes)
    rows = {}
    for cam, view in sample.cameras.items():
        pred = band_means(np.asarray(hdr_to_ldr(predicted_radiance(sl, view))))
        real = band_means(observed_ldr(view))
        rows[cam] = {b: {"pred": p, "real": r} for b, p, r in zip(BANDS, pred, real)}
        print(cam, " ".join(f"{b} {p:.3f}/{r:.3f}" for b, p, r in zip(BANDS, pred, real)), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "unseen_bands.json", {"level": args.level, "source": "CAM_FRONT", "cameras": rows})


if __name__ == "__main__":
    main()
