"""Where inserted cars differ from real ones: per-region tone statistics of the realism check's crops.

Usage::

    nice python benchmarks/diag_realism_regions.py --tag h4_base --stride 2     # reads /tmp/realism/cache_<tag>

Reuses the crops and the size matching of ``bench_realism.py`` (same cache, same seed, same selection). Per
crop, inside the projected box's hull, rows are split by their height in the box's 2D rectangle
(``t = (v - y0) / (y1 - y0)``): top (t < 0.35: roof and windows), middle (0.35-0.7: doors, bonnet), bottom
(t >= 0.7: sills, tyres, underbody); the ground is the crop outside the hull and other cars' hulls. Per
region: CIELAB L percentiles (5, 50, 95), a and b means, and the "dark channel" (2nd percentile of
min(R, G, B), 0..255: the black level a hazy camera lifts). Also the car's L median minus its ground's (the
exposure match) and the dark channel against distance. Prints medians over the inserted and the real cars and
writes ``benchmarks/results/realism_regions_<tag>.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REGIONS = {"top": (0.0, 0.35), "middle": (0.35, 0.7), "bottom": (0.7, 1.01)}


def _bench():
    spec = importlib.util.spec_from_file_location("bench_realism", ROOT / "benchmarks" / "bench_realism.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def region_stats(crop) -> dict[str, float]:
    """Flat dict of per-region statistics of one :class:`~streetaug.augment.evaluation.realism.CarCrop`."""
    from streetaug.augment.evaluation.realism import srgb_to_lab

    lab = srgb_to_lab(crop.rgb)
    h = crop.rgb.shape[0]
    ys = np.nonzero(crop.car_mask.any(axis=1))[0]
    y0, y1 = ys.min(), ys.max() + 1
    t = ((np.arange(h) - y0) / max(y1 - y0, 1))[:, None] * np.ones(crop.rgb.shape[1])
    dark = crop.rgb.min(axis=2).astype(np.float32)
    masks = {name: crop.car_mask & (t >= lo) & (t < hi) for name, (lo, hi) in REGIONS.items()}
    masks["car"] = crop.car_mask
    masks["ground"] = ~crop.car_mask & ~crop.exclude_mask & np.isfinite(crop.ground_dist_m) \
        & (crop.ground_dist_m < 3.0)
    out = {}
    for name, m in masks.items():
        if m.sum() < 12:
            continue
        L = lab[..., 0][m]
        p5, p50, p95 = np.percentile(L, [5, 50, 95])
        out.update({f"{name}_L5": p5, f"{name}_L50": p50, f"{name}_L95": p95, f"{name}_a": lab[..., 1][m].mean(),
                    f"{name}_b": lab[..., 2][m].mean(), f"{name}_dark2": np.percentile(dark[m], 2)})
    if "ground_L50" in out:
        out["car_minus_ground_L50"] = out["car_L50"] - out["ground_L50"]
        out["car_minus_ground_b"] = out["car_b"] - out["ground_b"]
        out["car_minus_ground_a"] = out["car_a"] - out["ground_a"]
    out["distance_m"] = crop.distance_m
    return {k: float(v) for k, v in out.items()}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tag", required=True)
    p.add_argument("--stride", type=int, default=3)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args_in = p.parse_args(argv)
    bench = _bench()
    from streetaug.augment.evaluation.realism import size_matched

    args = bench.parse_args(["--tag", args_in.tag, "--stride", str(args_in.stride)])
    cache = Path(f"/tmp/realism/cache_{args.tag}")
    all_tokens = bench.keyframe_tokens
    bench.keyframe_tokens = lambda reader, stride: [t for t in all_tokens(reader, stride)  # rendered so far
                                                    if (cache / f"{t}.json").exists()]
    crops, labels, _, _, _ = bench.collect_crops(cache, args)
    heights = np.array([c.box_height_px for c in crops])
    real_idx, ins_idx = np.flatnonzero(labels == 0), np.flatnonzero(labels == 1)
    pick_r, pick_i = size_matched(heights[real_idx], heights[ins_idx], bench.HEIGHT_BINS_PX,
                                  np.random.default_rng(args.seed), args.max_per_class)
    stats = {"real": [region_stats(crops[i]) for i in real_idx[pick_r]],
             "inserted": [region_stats(crops[i]) for i in ins_idx[pick_i]]}
    keys = sorted({k for s in stats["real"] + stats["inserted"] for k in s})
    summary = {}
    print(f"{args.tag}: {len(pick_r)} real vs {len(pick_i)} inserted; medians")
    print(f"  {'statistic':24s} {'inserted':>9s} {'real':>9s}")
    for k in keys:
        a = np.array([s[k] for s in stats["inserted"] if k in s])
        b = np.array([s[k] for s in stats["real"] if k in s])
        summary[k] = {"inserted_median": float(np.median(a)) if a.size else None,
                      "real_median": float(np.median(b)) if b.size else None}
        med_i, med_r = (np.nan if v is None else v for v in summary[k].values())
        print(f"  {k:24s} {med_i:9.2f} {med_r:9.2f}")
    for name in ("real", "inserted"):
        d = np.array([s["distance_m"] for s in stats[name]])
        k = np.array([s.get("car_dark2", np.nan) for s in stats[name]])
        ok = np.isfinite(k)
        slope = np.polyfit(d[ok], k[ok], 1) if ok.sum() > 3 else [np.nan, np.nan]
        summary[f"{name}_dark2_vs_distance"] = {"slope_per_m": float(slope[0]), "at_0m": float(slope[1])}
        print(f"  {name} car dark channel ~ {slope[1]:.1f} + {slope[0]:.2f} / m")
    out = Path(args_in.out) / f"realism_regions_{args.tag}.json"
    out.write_text(json.dumps({"tag": args.tag, "stride": args.stride, "regions": REGIONS, "medians": summary,
                               "per_crop": stats}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
