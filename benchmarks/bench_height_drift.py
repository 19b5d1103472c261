"""Parked objects through a scene: the global frame's height drift, measured on the real dev scene.

Usage: ``nice python benchmarks/bench_height_drift.py [--seeds 0-5] [--out benchmarks/results]``

nuScenes ego poses have z = 0 in every keyframe, so a static point's global height drifts through a scene
(:mod:`streetaug.placement.height_drift`). Two measures on ``../shared/data/nuscenes-seq`` (scene-0916):

* **leave one out**: every static annotated object seen in >= 10 keyframes; its bottom height in each keyframe
  predicted from the keyframe where the ego passes closest, (a) constant, (b) plus the drift measured by the
  *other* static objects; |error| statistics (m);
* **parked tracks** (``plan_tracks``, 3 tracks per seed, as ``streetaug batch --tracks 3``): per keyframe, the
  track's height minus the median bottom of that keyframe's annotated vehicles within 8 m (where there are
  >= 2), its spread (max - min over the track's keyframes; a parked car on one level should show none), for the
  planned heights and for the same track held at its reference keyframe's height (the previous behaviour).

Skipped (exit 0) without the shared data. Writes ``height_drift.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
RADIUS_M, MIN_VEHICLES = 8.0, 2


def _stats(e: np.ndarray) -> dict:
    a = np.abs(np.asarray(e, np.float64))
    return {"n": int(len(a)), "median_m": round(float(np.median(a)), 3), "p90_m": round(float(np.percentile(a, 90)), 3),
            "max_m": round(float(a.max()), 3), "share_over_0.3m": round(float((a > 0.3).mean()), 3)}


def leave_one_out(samples, bottoms) -> dict:
    from streetaug.placement.height_drift import held_out_errors_m

    ego_xy = np.array([s.cameras["CAM_FRONT"].T_global_from_ego[:2, 3] for s in samples])
    constant, drifted = held_out_errors_m(bottoms, ego_xy)
    return {"constant": _stats(constant), "with_drift": _stats(drifted)}


def parked_tracks(samples, scene_token: str, seeds: list[int]) -> dict:
    from streetaug.augment.batch.config import BatchConfig
    from streetaug.augment.batch.tracks import track_assets, track_rng
    from streetaug.placement.track import TrackConfig, plan_tracks, track_frames

    frames = track_frames(samples)
    index = {s.token: k for k, s in enumerate(samples)}
    vehicles = [np.array([[*b.center[:2], b.center[2] - b.wlh[2] / 2] for b in s.boxes
                          if b.category.startswith("vehicle.")]).reshape(-1, 3) for s in samples]
    rows, planned = [], 0
    for seed in seeds:
        config = BatchConfig(dataroot=str(SEQ), version="v1.0-mini", seed=seed, tracks=3)
        assets = track_assets(config, scene_token, 3, samples[0].location)
        plan = plan_tracks(frames, assets, track_rng(seed, "tracks", scene_token), TrackConfig(), samples[0].location)
        planned += len(plan.tracks)
        for t in plan.tracks:
            if t.motion != "parked":
                continue
            xy, z = t.T_global_from_object[0, :2, 3], t.T_global_from_object[:, 2, 3]
            ks = [index[tok] for tok in t.sample_tokens]
            ref = int(np.argmin([np.linalg.norm(frames[k].T_global_from_ego[:2, 3] - xy) for k in ks]))
            rel_now, rel_before = [], []
            for q, k in enumerate(ks):
                v = vehicles[k]
                near = v[np.linalg.norm(v[:, :2] - xy, axis=1) < RADIUS_M]
                if len(near) >= MIN_VEHICLES:
                    ground = float(np.median(near[:, 2]))
                    rel_now.append(z[q] - ground)
                    rel_before.append(z[ref] - ground)
            if len(rel_now) >= 3:
                rows.append({"seed": seed, "track": t.track_index, "keyframes": len(ks), "with_reference": len(rel_now),
                             "spread_m": round(float(np.ptp(rel_now)), 3),
                             "spread_constant_height_m": round(float(np.ptp(rel_before)), 3),
                             "height_range_m": round(float(np.ptp(z)), 3)})
    spread = np.array([r["spread_m"] for r in rows])
    before = np.array([r["spread_constant_height_m"] for r in rows])
    return {"seeds": seeds, "tracks_planned": planned, "tracks_asked": 3 * len(seeds), "parked_with_reference": rows,
            "median_spread_m": round(float(np.median(spread)), 3) if len(rows) else None,
            "median_spread_constant_height_m": round(float(np.median(before)), 3) if len(rows) else None}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-5", help="Track seeds, a range a-b or a comma list.")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    if not (SEQ / "v1.0-mini").is_dir():
        print(f"skipped: the real dev scene is not at {SEQ}")
        return
    from streetaug.datasets.nuscenes import NuScenesReader
    from streetaug.placement.height_drift import static_bottoms

    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b) + 1)) if b else [int(s) for s in args.seeds.split(",")]
    t0 = time.perf_counter()
    reader = NuScenesReader(SEQ, "v1.0-mini")
    samples = [reader.sample(t) for t in reader.sample_tokens()]
    bottoms = static_bottoms(samples)
    result = {"data": "nuscenes-seq scene-0916 (41 keyframes)", "static_objects": int(len(bottoms)),
              "leave_one_out": leave_one_out(samples, bottoms), "tracks": parked_tracks(samples, reader.scene_of(samples[0].token)["token"], seeds)}
    result["seconds"] = round(time.perf_counter() - t0, 1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / "height_drift.json.tmp"
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(out / "height_drift.json")
    print(json.dumps({k: v for k, v in result.items() if k != "tracks"}, indent=1))
    t = result["tracks"]
    print(f"tracks planned {t['tracks_planned']}/{t['tracks_asked']}; parked spread vs the keyframe's vehicles: "
          f"median {t['median_spread_m']} m (constant height: {t['median_spread_constant_height_m']} m)")


if __name__ == "__main__":
    main()
