"""Where the single-image sun error comes from, per view, from a ``bench_sky.py --real`` results JSON.

Splits each set's views by whether the sun was reported (seen) and by the combined estimate's cone
(``uncertainty_deg``), comparing the combined (network x cues) error with the network alone; then tries the rule
"keep the network's direction when the combined cone exceeds U", choosing U on the training sets (pano_train,
street_train) only and reporting it on the held-out ones. Prints a table and writes JSON under benchmarks/results/.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TRAIN, HELD_OUT = ("pano_train", "street_train"), ("pano_heldout", "one_north", "street_test")
EXTRA = ("pano_train_sun_in_view", "street_gap", "pano_heldout_sun_in_view")  # in the split stats when present


def split_stats(views: list[dict]) -> dict:
    out = {}
    for name, sel in (("reported", lambda v: v["sun_reported"]), ("not_reported", lambda v: not v["sun_reported"]),
                      ("cone_le_30", lambda v: v["uncertainty_deg"] <= 30), ("cone_gt_30", lambda v: v["uncertainty_deg"] > 30)):
        vs = [v for v in views if sel(v)]
        out[name] = {"n": len(vs),
                     "err_deg_median": float(np.median([v["err_deg"] for v in vs])) if vs else None,
                     "cnn_only_err_deg_median": float(np.median([v["err_deg_cnn_only"] for v in vs])) if vs else None}
    out["reported_with_err_over_30deg"] = int(sum(v["sun_reported"] and v["err_deg"] > 30.0 for v in views))
    return out


def rule_err(views: list[dict], cone_max_deg: float) -> float:
    e = [v["err_deg_cnn_only"] if (v["uncertainty_deg"] > cone_max_deg and not v["sun_reported"]) else v["err_deg"]
         for v in views]
    return float(np.median(e))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--real", type=Path, default=ROOT / "benchmarks" / "results" / "sky_benchmark_real.json")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "sun_error_analysis.json")
    args = ap.parse_args()
    sets = json.load(open(args.real))["after"]
    report: dict = {"source": str(args.real.name), "sets": {}}
    for k in [k for k in TRAIN + HELD_OUT + EXTRA if k in sets]:
        views = sets[k]["views"]
        report["sets"][k] = split_stats(views)
        print(k, json.dumps(report["sets"][k]))
    grid = [float(u) for u in range(20, 95, 5)] + [1e9]
    train_score = {u: float(np.mean([rule_err(sets[k]["views"], u) for k in TRAIN])) for u in grid}
    best = min(grid, key=lambda u: (train_score[u], -u))
    report["rule"] = {"cone_max_deg_grid": grid, "train_mean_of_medians": [train_score[u] for u in grid],
                      "chosen_cone_max_deg": best,
                      "held_out": {k: {"rule_err_deg_median": rule_err(sets[k]["views"], best),
                                       "current_err_deg_median": rule_err(sets[k]["views"], 1e9)} for k in HELD_OUT}}
    print("chosen U on train:", best, "train:", train_score[best], "current:", train_score[1e9])
    for k, r in report["rule"]["held_out"].items():
        print(f"  {k}: rule {r['rule_err_deg_median']:.1f} deg vs current {r['current_err_deg_median']:.1f} deg")
    args.out.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
