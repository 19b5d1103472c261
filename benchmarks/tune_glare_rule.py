"""Choose the "is this clipped region the sun?" rule of ``skynet.predict.glare_is_sun`` on training views only.

A clipped region under a detected sun disc, or under the clear-sky fit's sun, counts as the sun (the disc is
used; the direction moves to the glare's centre and its visibility is floored) only if the sky around it falls
off (``sun_cues.glare_region_features``).  Every view is predicted twice: with every region taken as the sun
(the rule before: ``allow``) and with none (``deny``); a candidate rule (which falloff measure, its threshold,
what to do without enough sky to tell) then picks one outcome per view from its region's features.

Chosen on the training views only: ``pano_train`` (12 level views of v3's training panoramas), ``street_train``
(scene-0916 keyframes 0-23, 6 cameras) and ``pano_train_sun_in_view`` (the same panoramas pitched to hold the
sun in frame: the rule must keep real suns).  Objective: the mean over those views whose outcome the rule can
change of the direction error (capped at 90 deg) plus 30 deg per wrongly reported sun (error > 30 deg) and per
missed one (error <= 15 deg while the other outcome reported it); candidates: the exposure-invariant glow measures
(log ratios of linear radiance), a threshold on a grid, and whether a region without sky around it is the sun;
ties: the candidate with the widest interval of optimal thresholds, and its middle.  Reported on the held-out
views: ``pano_heldout``, ``pano_heldout_sun_in_view``, ``one_north`` and ``street_heldout`` (keyframes 24-40).

Usage: ``python benchmarks/tune_glare_rule.py [--sets a,b] [--views-out F] [--merge F ...] [--out F]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_sky as B  # noqa: E402

from streetaug.augment.core import read_image_rgb  # noqa: E402
from streetaug.augment.lighting.skynet import predict as P  # noqa: E402
from streetaug.augment.training import data as D  # noqa: E402
from streetaug.augment.training import real as R  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TRAIN = ("pano_train", "street_train", "pano_train_sun_in_view")
HELD_OUT = ("pano_heldout", "pano_heldout_sun_in_view", "one_north", "street_heldout")
KEYS = ("glow_log_ratio", "glow_log_ratio_p90", "glow_log_ratio_sky")  # exposure-invariant (LDR differences are not)
GRID = [round(float(x), 3) for x in np.arange(-0.1, 1.61, 0.02)]
WRONG_SUN_PENALTY_DEG = 30.0


def _views(name: str):
    """(id, image, K, up_cam or None (a bare image: level), sun_cam) of one set."""
    seq, one = D.default_hdri_dir().parent / "nuscenes-seq", D.default_hdri_dir().parent / "nuscenes-real"
    if name in ("street_train", "street_heldout"):
        kfs = R.TRAIN_KEYFRAMES if name == "street_train" else R.GAP_KEYFRAMES + R.TEST_KEYFRAMES
        for p in R.street_photos(seq, shadows=False):
            if p.keyframe in kfs:
                yield f"{p.keyframe}/{p.channel}", read_image_rgb(p.image_path), p.K, None, p.sun_dir_cam
    elif name == "one_north":
        for p in R.street_photos(one, sample_tokens=(R.ONE_NORTH_SAMPLE,), shadows=False):
            yield p.channel, read_image_rgb(p.image_path), p.K, None, p.sun_dir_cam
    elif name in ("pano_train", "pano_heldout"):
        suns = R.panorama_sun(B.HDRI)
        for pano in (R.TRAIN_PANORAMAS_V3 if name == "pano_train" else R.HELDOUT_PANORAMAS):
            if suns[pano][0] is None:
                continue
            img = D.load_panoramas(B.HDRI, (pano,))[pano]
            for o, image, K, sun_cam in R.panorama_level_views(img, suns[pano][0], B.VIEW_W, B.VIEW_H, B.VIEW_FOV, 12):
                yield f"{pano}/{o:.0f}", image, K, None, sun_cam
    else:
        names = R.TRAIN_PANORAMAS_V3 if name == "pano_train_sun_in_view" else R.HELDOUT_PANORAMAS
        for pano, o, _, image, K, up_cam, sun_cam in B.sun_in_view_images(names):
            yield f"{pano}/{o:.0f}", image, K, up_cam, sun_cam


def _predict(image, K, up_cam, models, allow: bool):
    saved = P.GLARE_MIN_FALLOFF, P.GLARE_FALLOFF_UNKNOWN_IS_SUN
    P.GLARE_MIN_FALLOFF, P.GLARE_FALLOFF_UNKNOWN_IS_SUN = (-np.inf, True) if allow else (np.inf, False)
    try:
        if up_cam is None:
            return R.bare_image_prediction(image, K, models)
        return P.predict_sky(image, K, up_cam, models=models)
    finally:
        P.GLARE_MIN_FALLOFF, P.GLARE_FALLOFF_UNKNOWN_IS_SUN = saved


def collect(sets: list[str], models) -> dict:
    out = {}
    for name in sets:
        rows = []
        for vid, image, K, up_cam, sun_cam in _views(name):
            a = _predict(image, K, up_cam, models, allow=True)
            cues = B._cue_record(a, sun_cam)
            feats = cues.get("disc_region") or cues.get("region")
            row = {"id": vid, "allow_err_deg": B._angle(a.direction_cam, sun_cam), "allow_reported": bool(a.confident),
                   "features": feats, "from_disc": bool(cues.get("disc")), "cues": cues}
            if feats is not None:
                d = _predict(image, K, up_cam, models, allow=False)
                row.update(deny_err_deg=B._angle(d.direction_cam, sun_cam), deny_reported=bool(d.confident))
            else:
                row.update(deny_err_deg=row["allow_err_deg"], deny_reported=row["allow_reported"])
            rows.append(row)
        out[name] = rows
        n_region = sum(r["features"] is not None for r in rows)
        print(name, len(rows), "views,", n_region, "with a clipped region", flush=True)
    return out


def outcome(row: dict, key: str, threshold: float, unknown_is_sun: bool) -> tuple[float, bool, float, bool]:
    """(error, reported) of the view under the rule, then those of the other outcome."""
    f = None if row["features"] is None else row["features"].get(key)
    sun = unknown_is_sun if f is None or not np.isfinite(f) else f >= threshold
    a, d = (row["allow_err_deg"], row["allow_reported"]), (row["deny_err_deg"], row["deny_reported"])
    return (*a, *d) if sun else (*d, *a)


def cost(rows: list[dict], key: str, threshold: float, unknown_is_sun: bool) -> float:
    c = []
    for r in rows:
        if r["allow_err_deg"] == r["deny_err_deg"] and r["allow_reported"] == r["deny_reported"]:
            continue
        err, rep, alt_err, alt_rep = outcome(r, key, threshold, unknown_is_sun)
        wrong = (rep and err > 30.0) + (not rep and alt_rep and alt_err <= 15.0)
        c.append(min(err, 90.0) + WRONG_SUN_PENALTY_DEG * wrong)
    return float(np.mean(c)) if c else 0.0


def summary(rows: list[dict], key: str, threshold: float, unknown_is_sun: bool) -> dict:
    res = [outcome(r, key, threshold, unknown_is_sun)[:2] for r in rows]
    err = np.array([e for e, _ in res])
    rep = np.array([p for _, p in res])
    return {"n": len(rows), "err_deg_median_all_views": float(np.median(err)),
            "fraction_under_15deg": float(np.mean(err < 15.0)), "sun_reported_fraction": float(rep.mean()),
            "err_deg_median_when_reported": float(np.median(err[rep])) if rep.any() else None,
            "reported_with_err_over_30deg": int(np.sum(rep & (err > 30.0)))}


def choose(views: dict) -> dict:
    train = [r for k in TRAIN for r in views[k]]
    table = {}
    for key in KEYS:
        for unknown in (True, False):
            table[f"{key}|unknown_is_sun={unknown}"] = [cost(train, key, t, unknown) for t in GRID]
    best_cost = min(min(v) for v in table.values())

    def longest_run(name):  # the longest run of optimal thresholds of one candidate
        ok = np.isclose(table[name], best_cost)
        runs, i = [(0, -1)], 0
        while i < len(ok):
            if ok[i]:
                j = i
                while j + 1 < len(ok) and ok[j + 1]:
                    j += 1
                runs.append((i, j))
                i = j + 1
            else:
                i += 1
        return max(runs, key=lambda r: r[1] - r[0])

    # ties: the candidate with the widest optimal interval (the largest margin), its middle
    best_name = max(table, key=lambda n: (np.isclose(min(table[n]), best_cost), np.diff(longest_run(n))[0], n))
    lo, hi = longest_run(best_name)
    key, unknown = best_name.split("|")[0], best_name.endswith("True")
    chosen = {"key": key, "unknown_is_sun": unknown, "threshold": float(np.mean([GRID[lo], GRID[hi]])),
              "optimal_interval": [GRID[lo], GRID[hi]], "train_cost": best_cost}
    return {"grid": GRID, "train_cost": table, "chosen": chosen}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default=",".join(TRAIN + HELD_OUT))
    ap.add_argument("--views-out", type=Path, default=None, help="write the collected views here (and stop)")
    ap.add_argument("--merge", type=Path, nargs="*", default=None, help="views files collected by other runs")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "sun_error_glare_rule_s5.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    views: dict = {}
    for f in args.merge or []:
        views.update(json.loads(Path(f).read_text()))
    todo = [s for s in args.sets.split(",") if s and s not in views]
    if todo:
        views.update(collect(todo, P.get_models()))
    if args.views_out is not None:
        args.views_out.write_text(json.dumps(views))
        return
    rule = choose(views)
    c = rule["chosen"]
    rule["before_rule"] = {k: summary(views[k], c["key"], -np.inf, True) for k in TRAIN + HELD_OUT}
    rule["with_rule"] = {k: summary(views[k], c["key"], c["threshold"], c["unknown_is_sun"]) for k in TRAIN + HELD_OUT}
    rule["note"] = __doc__
    rule["views"] = views
    print("chosen:", c)
    for k in TRAIN + HELD_OUT:
        b, a = rule["before_rule"][k], rule["with_rule"][k]
        print(f"{k:26s} n {a['n']:3d}: median {b['err_deg_median_all_views']:5.1f} -> "
              f"{a['err_deg_median_all_views']:5.1f}, "
              f"reported {b['sun_reported_fraction']:.2f} -> {a['sun_reported_fraction']:.2f}, "
              f"reported with err > 30: {b['reported_with_err_over_30deg']} -> {a['reported_with_err_over_30deg']}")
    args.out.write_text(json.dumps(rule, indent=1))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
