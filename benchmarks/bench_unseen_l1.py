"""L1's unseen directions on the real dev scene: CAM_FRONT's L1 map rendered into the other 5 cameras at t.

Usage: ``python benchmarks/bench_unseen_l1.py [--stride 4] [--out benchmarks/results] [--figure /tmp/x.png]``

The ``monocular others`` row of ``bench_real_lighting.py`` at L1 only, quick: for every ``--stride``-th keyframe
of ``../shared/data/nuscenes-seq`` (scene-0916) that has a t + 3 (as there), the L1 lighting from CAM_FRONT
alone (with the sample's LiDAR and boxes) rendered into CAM_FRONT (``self``: on the image's scale?) and into
the 5 other cameras of the same instant (``others``: what the input camera did not see), PSNR / si-PSNR at
320 px (:mod:`streetaug.augment.evaluation.novel_view`), against the constant-colour baseline (CAM_FRONT's mean
LDR colour everywhere). Per keyframe the mean over the 5 cameras; medians over the held-out keyframes
(t = 4 mod 8, what a prior fitted on t = 0 mod 8 is reported on) and over all. ``--figure``: the real
cameras of one keyframe over their L1 predictions (a picture of real data: write it under /tmp).
``--fit``: the unseen-direction prior's constants (``image_dome.SYMMETRY_WEIGHT``, ``SYMMETRY_BLUR_DEG``,
``GROUND_KEEP``) chosen on a grid by the mean ``others`` PSNR of the t = 0 mod 8 keyframes, reported on the
held-out t = 4 mod 8 ones (and all); writes ``unseen_l1_fit.json``. Writes ``unseen_l1.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from streetaug.augment.core import hdr_to_ldr  # noqa: E402
from streetaug.augment.core.io import write_json_atomic  # noqa: E402
from streetaug.augment.evaluation.novel_view import constant_colour_scores, paper_pairs, real_view, score_lighting  # noqa: E402
from streetaug.augment.lighting import image_dome  # noqa: E402
from streetaug.augment.lighting.api import estimate_views_lighting  # noqa: E402
from streetaug.augment.lighting.predicted_view import predicted_radiance  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()  # one-north: another part of the city
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
SCORES = ("psnr", "si_psnr", "const_psnr", "const_si_psnr")


def l1_front(sample):
    """CAM_FRONT's L1 lighting (LiDAR and boxes as in bench_real_lighting)."""
    return estimate_views_lighting([sample.cameras["CAM_FRONT"]], sample.location, "L1", lidar=sample.lidar,
                                   boxes=sample.boxes)


def scored(sl, target, source_image) -> dict:
    s = score_lighting(sl, target)
    c = constant_colour_scores([source_image], real_view(target))
    return {"psnr": s["psnr"], "si_psnr": s["si_psnr"], "const_psnr": c["psnr"], "const_si_psnr": c["si_psnr"]}


def keyframe_scores(sample) -> dict:
    """{"self", "others" (mean over the other cameras the sample has), "per_camera"} of its CAM_FRONT L1."""
    sl = l1_front(sample)
    img = np.asarray(sample.cameras["CAM_FRONT"].image)
    cams = [c for c in CAMERAS if c in sample.cameras]
    per = {c: scored(sl, sample.cameras[c], img) for c in cams}
    others = {k: float(np.mean([per[c][k] for c in cams[1:]])) for k in SCORES}
    return {"self": per["CAM_FRONT"], "others": others, "per_camera": per}


def medians(rows: dict[int, dict], ts: list[int]) -> dict:
    return {target: {k: float(np.median([rows[t][target][k] for t in ts])) for k in SCORES} | {"n": len(ts)}
            for target in ("self", "others")}


def keyframes(reader, stride: int) -> dict:
    tokens = reader.sample_tokens("scene-0916")
    return {t: tokens[t] for t, _ in paper_pairs(len(tokens))[::stride]}


def evaluate(reader, frames: dict[int, str], samples: dict | None = None) -> dict:
    """Scores per keyframe and their medians (held out: t = 4 mod 8; all)."""
    rows = {}
    for t, tok in frames.items():
        sample = samples[t] if samples is not None else reader.sample(tok)
        rows[t] = keyframe_scores(sample)
    held = [t for t in rows if t % 8 == 4]
    return {"per_keyframe": rows, "held_out": medians(rows, held), "all": medians(rows, list(rows)),
            "train": medians(rows, [t for t in rows if t % 8 == 0])}


FIT_GRID = {"SYMMETRY_WEIGHT": (0.0, 0.25, 0.5, 0.75, 1.0), "SYMMETRY_BLUR_DEG": (8.0, 16.0),
            "GROUND_KEEP": (0.0, 0.25)}


def fit(reader, frames: dict[int, str]) -> dict:
    """Every grid point of ``FIT_GRID`` scored; the best by the train keyframes' mean others PSNR."""
    samples = {t: reader.sample(tok) for t, tok in frames.items()}
    names = list(FIT_GRID)
    points = [dict(zip(names, map(float, p))) for p in np.array(np.meshgrid(*FIT_GRID.values(), indexing="ij")).reshape(len(names), -1).T]
    points = [p for p in points if p["SYMMETRY_WEIGHT"] > 0 or p["SYMMETRY_BLUR_DEG"] == FIT_GRID["SYMMETRY_BLUR_DEG"][0]]
    before = {n: getattr(image_dome, n) for n in names}
    rows = []
    for p in points:
        for n, v in p.items():
            setattr(image_dome, n, float(v))
        res = evaluate(reader, frames, samples)
        train = float(np.mean([res["per_keyframe"][t]["others"]["psnr"] for t in res["per_keyframe"] if t % 8 == 0]))
        rows.append({"params": {n: float(v) for n, v in p.items()}, "train_mean_psnr": train,
                     "held_out": res["held_out"], "all": res["all"], "train": res["train"]})
        h, a = res["held_out"]["others"], res["all"]["others"]
        print(f"{p}: train mean {train:.2f}; held-out {h['psnr']:.2f}/{h['si_psnr']:.2f}, all {a['psnr']:.2f}/"
              f"{a['si_psnr']:.2f} (const {a['const_psnr']:.2f}/{a['const_si_psnr']:.2f}); self {res['all']['self']['psnr']:.2f}",
              flush=True)
    for n, v in before.items():
        setattr(image_dome, n, v)
    best = max(rows, key=lambda r: r["train_mean_psnr"])
    print(f"chosen (train): {best['params']}")
    return {"grid": {k: list(v) for k, v in FIT_GRID.items()}, "rows": rows, "chosen": best["params"],
            "chosen_held_out": best["held_out"], "chosen_all": best["all"]}


def figure(sample, path: Path, width: int = 320) -> None:
    """Real cameras (top) over CAM_FRONT's L1 prediction for each (bottom)."""
    sl = l1_front(sample)
    cols = []
    for c in ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_RIGHT", "CAM_BACK", "CAM_BACK_LEFT"):
        v = sample.cameras[c]
        pred = hdr_to_ldr(predicted_radiance(sl, v, width))
        real = real_view(v, width)
        cols.append(np.concatenate([real, pred], axis=0))
    h = min(col.shape[0] for col in cols)
    panel = np.concatenate([col[:h] for col in cols], axis=1)
    cv2.imwrite(str(path), cv2.cvtColor((np.clip(panel, 0, 1) * 255).astype(np.uint8), cv2.COLOR_RGB2BGR))
    env = sl.per_view["CAM_FRONT"].light_cam.envmap
    cv2.imwrite(str(path.with_name(path.stem + "_map.png")),
                cv2.cvtColor((hdr_to_ldr(env) * 255).astype(np.uint8), cv2.COLOR_RGB2BGR))


def print_row(name: str, res: dict) -> None:
    for split in ("held_out", "all"):
        m = res[split]
        print(f"{name} {split} (n={m['others']['n']}): others L1 {m['others']['psnr']:.2f}/{m['others']['si_psnr']:.2f} "
              f"const {m['others']['const_psnr']:.2f}/{m['others']['const_si_psnr']:.2f}; self "
              f"{m['self']['psnr']:.2f}/{m['self']['si_psnr']:.2f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stride", type=int, default=4)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    ap.add_argument("--figure", type=Path, default=None, help="PNG path (under /tmp) of keyframe --figure-t")
    ap.add_argument("--figure-t", type=int, default=12)
    ap.add_argument("--fit", action="store_true", help="choose the prior's constants by keyframe split")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if not SEQ.exists():
        raise SystemExit(f"{SEQ} not found")
    reader = NuScenesReader(SEQ, "v1.0-mini")
    frames = keyframes(reader, args.stride)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.fit:
        write_json_atomic(args.out / "unseen_l1_fit.json", fit(reader, frames))
        return
    if args.figure is not None:
        figure(reader.sample(reader.sample_tokens("scene-0916")[args.figure_t]), args.figure)
    t0 = time.perf_counter()
    res = evaluate(reader, frames)
    print_row("L1", res)
    if REAL.exists():  # the one-north keyframe (not used by --fit)
        one = keyframe_scores(NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE))
        res["one_north"] = one
        o, sf = one["others"], one["self"]
        print(f"one-north: others L1 {o['psnr']:.2f}/{o['si_psnr']:.2f} const {o['const_psnr']:.2f}/"
              f"{o['const_si_psnr']:.2f}; self {sf['psnr']:.2f}/{sf['si_psnr']:.2f}", flush=True)
    res["seconds"] = time.perf_counter() - t0
    res["stride"] = args.stride
    res["prior"] = {n: getattr(image_dome, n) for n in FIT_GRID} | {"UNSEEN_KEEP": image_dome.UNSEEN_KEEP}
    write_json_atomic(args.out / "unseen_l1.json", res)
    print(f"wrote {args.out / 'unseen_l1.json'} ({res['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
