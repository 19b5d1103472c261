"""Tracks through whole scenes (issue 17): what `streetaug batch --tracks` inserts on the real dev scene, how
faithfully (independent audit), and at what speed against today's per-sample batch on the same work.

Usage: ``python benchmarks/bench_tracks.py [--out benchmarks/results] [--quick] [--data DIR] [--sequence DIR]``

Runs, on ``../shared/data/nuscenes-seq`` (real scene-0916: 41 keyframes x 6 cameras, 1600 x 900), default
quality and lighting level, seed 0, each into a fresh folder:

* ``--tracks 4`` on 1 and on 2 local worker processes (the same work: every keyframe, every camera);
* the per-sample batch (``--n-objects 1``, today's mode) on 2 workers over the same images, for CPU seconds
  per image;

then audits the 2-worker tracks output (:func:`streetaug.augment.evaluation.track_audit.audit_tracks`: should
be visible vs rendered per camera, pop-in/out in view, rule violations per keyframe, LiDAR points) and the
devkit's ``box_velocity`` of every new annotation against the trajectory. With ``--sequence DIR`` (a sequence
scene generated with sweeps: ``streetaug make-samples --sequence --sweeps --out DIR``) it also times
``--tracks 3 --sweeps`` there. ``--quick``: 6 keyframes, 3 cameras. Skipped (exit 0) without the shared data.
Writes ``tracks.json``; prints medians and ratios measured in this run.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from streetaug.augment.batch import BatchConfig, RunOptions, run_batch
from streetaug.augment.batch.tracks import saved_scene_tracks
from streetaug.augment.evaluation.track_audit import audit_tracks, velocity_errors

REPO = Path(__file__).resolve().parents[1]


def timed_run(config: BatchConfig, out: Path, workers: int) -> dict:
    t0 = time.perf_counter()
    summary = run_batch(config, out, RunOptions(workers=workers, progress=False, contact_sheet=12))
    wall = time.perf_counter() - t0
    run = summary["this_run"]
    return {"workers": workers, "images": run["images"], "wall_s": round(wall, 1),
            "images_per_s": round(run["images"] / wall, 4), "worker_cpu_s": run["worker_cpu_s"],
            "cpu_s_per_image": round(run["worker_cpu_s"] / max(run["images"], 1), 3),
            "status": summary.get("counts"), "tracks": summary.get("tracks"), "sweeps": summary.get("sweeps")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "nuscenes-seq")
    ap.add_argument("--sequence", type=Path, default=None, help="a sequence scene generated with --sweeps")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--keep", type=Path, default=None, help="keep the outputs under this folder")
    args = ap.parse_args()
    if not (args.data / "v1.0-mini" / "sample.json").is_file():
        print(f"skipped: {args.data} (real nuScenes scene-0916) not present")
        return
    work = Path(args.keep or tempfile.mkdtemp(prefix="bench_tracks_"))
    cameras = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT") if args.quick else ()
    limit = 6 if args.quick else None
    base = dict(dataroot=str(args.data.resolve()), version="v1.0-mini", cameras=cameras, limit=limit, seed=0)
    results: dict = {"data": str(args.data), "quick": args.quick, "cameras": list(cameras) or "all",
                     "limit": limit, "quality": "default", "level": "auto"}
    runs = {}
    for name, cfg, workers in (("tracks_2_workers", BatchConfig(**base, tracks=4), 2),
                               ("tracks_1_worker", BatchConfig(**base, tracks=4), 1),
                               ("per_sample_2_workers", BatchConfig(**base, n_objects=1), 2)):
        out = work / name
        shutil.rmtree(out, ignore_errors=True)
        runs[name] = timed_run(cfg, out, workers)
        print(name, json.dumps({k: v for k, v in runs[name].items() if k != "tracks"}))
    results["runs"] = runs
    t2, t1, ps = runs["tracks_2_workers"], runs["tracks_1_worker"], runs["per_sample_2_workers"]
    results["speedup_2_vs_1_workers"] = round(t2["images_per_s"] / t1["images_per_s"], 3)
    results["cpu_per_image_tracks_over_per_sample"] = round(t2["cpu_s_per_image"] / ps["cpu_s_per_image"], 3)
    out = work / "tracks_2_workers"
    audit = audit_tracks(out, args.data, "v1.0-mini", cameras)
    errors = velocity_errors(out, "v1.0-mini", saved_scene_tracks(out), 0)
    results["audit"] = {k: v for k, v in audit.items() if k != "per_scene"}
    results["audit_per_scene"] = {s: {k: v for k, v in a.items() if k != "lidar_pts"} for s, a in audit["per_scene"].items()}
    results["velocity_error_mps"] = {"n": len(errors), "median": round(float(np.median(errors)), 4) if errors else None,
                                     "p95": round(float(np.percentile(errors, 95)), 4) if errors else None,
                                     "max": round(float(np.max(errors)), 4) if errors else None}
    results["tracks"] = [{k: t.to_json()[k] for k in ("track_index", "motion", "speed_mps", "direction_source",
                                                       "anchor_camera")} | {"keyframes": len(t.sample_tokens)}
                         for s in saved_scene_tracks(out) for t in s.tracks]
    if args.sequence is not None:
        cfg = BatchConfig(dataroot=str(args.sequence.resolve()), version="v1.0-sequence", seed=0, tracks=3,
                          sweeps=True)
        seq_out = work / "sequence_sweeps"
        shutil.rmtree(seq_out, ignore_errors=True)
        results["sequence_sweeps_2_workers"] = timed_run(cfg, seq_out, 2)
        print("sequence_sweeps", json.dumps(results["sequence_sweeps_2_workers"]))
    print(json.dumps({k: results[k] for k in ("speedup_2_vs_1_workers", "cpu_per_image_tracks_over_per_sample",
                                              "audit", "velocity_error_mps")}, indent=1))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / ("tracks_quick.json" if args.quick else "tracks.json")).write_text(json.dumps(results, indent=1) + "\n")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
