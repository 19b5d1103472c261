"""Fit the prior for what no camera saw (``lighting.fill.UNSEEN_KEEP``) on the real dev scene, by keyframe split.

Usage: ``python benchmarks/fit_unseen_prior.py [--out benchmarks/results]``

What no camera saw (other directions than the input camera's) is predicted by the model (sky model, shaded
unseen surfaces, the street prior, the seen elevation bands) and then shrunk towards the seen mean colour in
log space, keeping ``keep`` of the model (:func:`streetaug.augment.lighting.fill.shrink_unseen`; L1's unseen ground
and its street symmetry have their own constants, fitted by ``bench_unseen_l1.py --fit``). Score: the
lighting built from CAM_FRONT alone (with LiDAR, boxes) rendered into the 5 other cameras of the same instant
(:mod:`streetaug.augment.evaluation.novel_view`), mean PSNR, at L1 and L2 (the default level's usual choice).
Keyframes of ``../shared/data/nuscenes-seq`` with t = 0 mod 8 choose ``keep`` (train); t = 4 mod 8 report it
(held out; neighbouring keyframes 0.5 s apart look alike, so the two sets are 2 s apart). Writes
``unseen_prior.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from streetaug.augment.core.io import write_json_atomic  # noqa: E402
from streetaug.augment.evaluation.novel_view import constant_colour_scores, real_view, score_lighting  # noqa: E402
from streetaug.augment.lighting import build, image_dome, skydome  # noqa: E402
from streetaug.augment.lighting.api import estimate_views_lighting  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
OTHERS = ("CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
KEEPS = (1.0, 0.5, 0.25, 0.0)


def set_keep(keep: float) -> None:
    """Every builder's default ``keep`` (the L1 map, the sky dome, the unseen surfaces) set to ``keep``."""
    image_dome.image_corrected_envmap.__defaults__ = (keep,)
    skydome.build_sky_dome.__defaults__ = (12.0, None, keep)
    build.build_volume.__defaults__ = (0.15, keep)


def others_psnr(sample, level: str) -> float:
    src = sample.cameras["CAM_FRONT"]
    sl = estimate_views_lighting([src], sample.location, level, lidar=sample.lidar, boxes=sample.boxes)
    return float(np.mean([score_lighting(sl, sample.cameras[c])["psnr"] for c in OTHERS]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args()
    torch.set_num_threads(1)
    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens("scene-0916")
    split = {"train": [t for t in range(len(tokens)) if t % 8 == 0], "test": [t for t in range(len(tokens)) if t % 8 == 4]}
    samples = {t: reader.sample(tokens[t]) for ts in split.values() for t in ts}
    const = {t: float(np.mean([constant_colour_scores([s.cameras["CAM_FRONT"].image], real_view(s.cameras[c]))["psnr"]
                               for c in OTHERS])) for t, s in samples.items()}
    out: dict = {"split": split, "keeps": KEEPS, "levels": {}}
    for level in ("L1", "L2"):
        rows = {}
        for keep in KEEPS:
            set_keep(keep)
            rows[keep] = {t: others_psnr(s, level) for t, s in samples.items()}
            print(f"{level} keep {keep}: train {np.mean([rows[keep][t] for t in split['train']]):.2f}, "
                  f"test {np.mean([rows[keep][t] for t in split['test']]):.2f} dB", flush=True)
        out["levels"][level] = {str(k): v for k, v in rows.items()}
    train_mean = {k: np.mean([out["levels"][lv][str(k)][t] for lv in out["levels"] for t in split["train"]]) for k in KEEPS}
    best = max(KEEPS, key=lambda k: train_mean[k])
    test = {lv: {"keep_1": float(np.mean([out["levels"][lv]["1.0"][t] for t in split["test"]])),
                 "chosen": float(np.mean([out["levels"][lv][str(best)][t] for t in split["test"]])),
                 "constant_colour": float(np.mean([const[t] for t in split["test"]]))} for lv in out["levels"]}
    out |= {"chosen_keep": best, "train_mean_psnr": {str(k): float(v) for k, v in train_mean.items()},
            "test": test, "constant_colour": const}
    print(f"chosen keep {best} (train); held-out other cameras: " + ", ".join(
        f"{lv} {v['keep_1']:.2f} -> {v['chosen']:.2f} dB (constant colour {v['constant_colour']:.2f})"
        for lv, v in test.items()))
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "unseen_prior.json", out)


if __name__ == "__main__":
    main()
