"""L1 ``predict-light`` time on the real one-north keyframe (1600 x 900 CAM_FRONT), one thread, in-process.

Usage: ``python benchmarks/bench_l1_speed.py --label new [--runs 7] [--rounds 3] [--old /tmp/old_pkg]``

The work timed is what ``bench_lighting.py --sections speed`` times at L1: the estimate plus the local map at a
query point (``light_at(...).to_envmap(128, 256)``), image-only (what the CLI runs on a bare view) and with the
sample's LiDAR and boxes; the image is decoded first. Wall and CPU seconds per run; medians over
``--rounds`` x ``--runs``. ``--old DIR``: also runs the code importable from DIR (a directory holding a
``streetaug`` package of an older revision, e.g. symlinks into a ``git worktree``) in a subprocess,
interleaved round by round with this checkout, so both see the same machine load. Writes
``l1_speed.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
QUERY_CAM = (0.0, 1.5, 15.0)


def measure(runs: int) -> dict:
    """{"image_only" | "lidar": {"wall": [s], "cpu": [s]}} of this process's streetaug."""
    import torch

    from streetaug.augment.lighting.api import estimate_lighting
    from streetaug.datasets.nuscenes import NuScenesReader

    torch.set_num_threads(1)
    sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    view = sample.cameras["CAM_FRONT"]
    _ = view.image, sample.lidar
    q = np.array(QUERY_CAM)

    def run(lidar: bool) -> None:
        kw = dict(lidar=sample.lidar, boxes=sample.boxes, query_point_cam=q) if lidar else {}
        estimate_lighting(view, sample.location, "L1", **kw).light_at(q).to_envmap(128, 256)

    out = {}
    for lidar in (False, True):
        run(lidar)  # warm-up (imports, caches of the first call)
        wall, cpu = [], []
        for _ in range(runs):
            t0, c0 = time.perf_counter(), time.process_time()
            run(lidar)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out["lidar" if lidar else "image_only"] = {"wall": wall, "cpu": cpu}
    return out


def summary(rounds: list[dict]) -> dict:
    return {path: {f"{k}_s_median": float(np.median([x for r in rounds for x in r[path][k]])) for k in ("wall", "cpu")}
            | {"n": sum(len(r[path]["wall"]) for r in rounds)} for path in rounds[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--label", default="this checkout")
    ap.add_argument("--old", type=Path, default=None, help="directory whose streetaug package is the old code")
    ap.add_argument("--old-label", default="old")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args()
    if args.child:
        print(json.dumps(measure(args.runs)))
        return
    if not REAL.exists():
        raise SystemExit(f"{REAL} not found")
    runs: dict[str, list] = {args.label: []}
    if args.old is not None:
        runs[args.old_label] = []
    for _ in range(args.rounds):
        for label in runs:
            env = dict(os.environ)
            if label != args.label:
                env["PYTHONPATH"] = str(args.old)
            res = subprocess.run([sys.executable, __file__, "--child", "--runs", str(args.runs)], env=env,
                                 capture_output=True, text=True, check=True)
            runs[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
    result = {"threads": 1, "runs": args.runs, "rounds": args.rounds, "query_cam": QUERY_CAM,
              "summary": {label: summary(r) for label, r in runs.items()}, "raw": runs}
    for label, s in result["summary"].items():
        print(f"{label}: L1 image-only wall {s['image_only']['wall_s_median']:.3f} s (cpu "
              f"{s['image_only']['cpu_s_median']:.3f}), with LiDAR {s['lidar']['wall_s_median']:.3f} s (cpu "
              f"{s['lidar']['cpu_s_median']:.3f})", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "l1_speed.json", "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
