"""Placement stage, timed on a real scene as ``insert`` runs it, with its profile and its placements.

Usage: ``python benchmarks/bench_placement_speed.py [--dataroot ../shared/data/nuscenes-seq] [--every 3]
[--seeds 2] [--against benchmarks/results/placement_speed_before.json] [--out benchmarks/results/placement_speed.json]``

Each sample (every ``--every``-th of the scene) x camera x seed is one placement of one car as the pipeline
places it (``place_objects`` with ``item_seed(seed, sample, camera)``, the default ``PlacementConfig`` and the
view's scene depth computed beforehand, as the pipeline shares it; the car's size is that of the procedural
car ``insert`` would choose). Measured: process CPU time and wall time per placement (the machine is shared:
CPU time is the steadier one; the load average is recorded), the number of ground fits (candidates stood on
the ground) per placement, and the top functions of a cProfile pass. The placements themselves are written
(the object transform of each), and with ``--against`` compared with an earlier run's: how many are the same
candidate (same zone, source, attribute) and the largest difference of the transforms.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import pstats  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.assets.select import select_assets  # noqa: E402
from streetaug.augment.pipeline import item_seed, scene_depth_for_view  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402
from streetaug.placement import ground  # noqa: E402
from streetaug.placement.config import PlacementConfig  # noqa: E402
from streetaug.placement.place import ObjectBox, place_objects  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()


def jobs(reader: NuScenesReader, every: int, seeds: int) -> list[tuple]:
    """(sample, view, depth, seed, object) of every placement to time; depth and sizes prepared untimed."""
    out = []
    for token in reader.sample_tokens()[::every]:
        sample = reader.sample(token)
        for channel, view in sample.cameras.items():
            depth = scene_depth_for_view(sample, view)
            for seed in range(seeds):
                asset = select_assets(item_seed(seed, "asset", sample.token, channel), 1, None, None, "+z", None,
                                      None, location=sample.location)[0]
                out.append((sample, view, depth, seed, ObjectBox(np.asarray(asset.wlh, float), asset.category)))
    return out


class FitCounter:
    """Counts the ground fits (points stood on the ground) of :class:`~streetaug.placement.ground.LocalGroundFitter`."""

    def __init__(self) -> None:
        self.n = 0
        cls = ground.LocalGroundFitter
        self._fit, self._many = cls.fit, getattr(cls, "fit_many", None)
        counter = self

        def fit(fitter, xy, *a, **k):
            counter.n += 1
            return counter._fit(fitter, xy, *a, **k)

        def fit_many(fitter, xy, *a, **k):
            counter.n += len(np.asarray(xy).reshape(-1, 2))
            return counter._many(fitter, xy, *a, **k)

        self.patched = [("fit", fit)] + ([("fit_many", fit_many)] if self._many else [])

    def __enter__(self) -> "FitCounter":
        for name, f in self.patched:
            setattr(ground.LocalGroundFitter, name, f)
        return self

    def __exit__(self, *exc) -> None:
        ground.LocalGroundFitter.fit = self._fit
        if self._many:
            ground.LocalGroundFitter.fit_many = self._many


def run(all_jobs: list[tuple], config: PlacementConfig) -> list[dict]:
    rows = []
    for sample, view, depth, seed, obj in all_jobs:
        with FitCounter() as fits:
            w0, c0 = time.perf_counter(), time.process_time()
            res = place_objects(sample, view, [obj], item_seed(seed, sample.token, view.channel), config, depth_m=depth)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        p = res.placements[0] if res.placements else None
        rows.append({"sample": sample.token, "camera": view.channel, "seed": seed, "wall_s": wall, "cpu_s": cpu,
                     "ground_fits": fits.n, "placed": p is not None,
                     "zone": p.zone if p else None, "ground_source": p.ground_source if p else None,
                     "attribute": p.attribute if p else None,
                     "T_global_from_object": p.T_global_from_object.tolist() if p else None})
    return rows


def stats(values) -> dict:
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)), "mean": float(v.mean()), "n": int(len(v))}


def compare(rows: list[dict], before: list[dict]) -> dict:
    keys = ("placed", "zone", "ground_source", "attribute")
    same = [all(a[k] == b[k] for k in keys) for a, b in zip(rows, before)]
    diffs = [float(np.max(np.abs(np.array(a["T_global_from_object"]) - np.array(b["T_global_from_object"]))))
             for a, b in zip(rows, before) if a["placed"] and b["placed"]]
    exact = [a["T_global_from_object"] == b["T_global_from_object"] for a, b in zip(rows, before)]
    return {"placements": len(rows), "same_candidate": int(sum(same)), "bit_identical": int(sum(exact)),
            "max_abs_diff_T": max(diffs) if diffs else 0.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataroot", type=Path, default=SHARED / "nuscenes-seq")
    ap.add_argument("--version", default="v1.0-mini")
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--against", type=Path, help="an earlier run's JSON: compare the placements")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "placement_speed.json")
    args = ap.parse_args()
    if not args.dataroot.is_dir():
        raise SystemExit(f"{args.dataroot} not found")
    reader = NuScenesReader(args.dataroot, args.version)
    all_jobs = jobs(reader, args.every, args.seeds)
    config = PlacementConfig()
    run(all_jobs[:3], config)  # warm-up (imports, caches)
    rows = run(all_jobs, config)
    prof = cProfile.Profile()
    prof.enable()
    run(all_jobs, config)
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(25)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    import streetaug.placement as placement_pkg
    result = {
        "command": "python benchmarks/bench_placement_speed.py " + " ".join(
            f"--{k} {v}" for k, v in vars(args).items() if v is not None and k != "out"),
        "code": {"commit": commit, "placement_package": str(Path(placement_pkg.__path__[0]).resolve())},
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "load_avg": os.getloadavg()},
        "dataroot": str(args.dataroot), "placements": len(rows),
        "placed": int(sum(r["placed"] for r in rows)),
        "cpu_s_per_placement": stats([r["cpu_s"] for r in rows]),
        "wall_s_per_placement": stats([r["wall_s"] for r in rows]),
        "ground_fits_per_placement": stats([r["ground_fits"] for r in rows]),
        "profile_top_cumulative": buf.getvalue().splitlines()[:60],
        "rows": rows,
    }
    if args.against is not None:
        result["against"] = {"file": str(args.against),
                             **compare(rows, json.loads(args.against.read_text())["rows"])}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    c, w, f = result["cpu_s_per_placement"], result["wall_s_per_placement"], result["ground_fits_per_placement"]
    print(f"{len(rows)} placements ({result['placed']} placed): cpu median {c['median']:.4f} s p90 {c['p90']:.4f} s, "
          f"wall median {w['median']:.4f} s, ground fits median {f['median']:.0f}, load {result['machine']['load_avg']}")
    if "against" in result:
        print("against", args.against, {k: v for k, v in result["against"].items() if k != "file"})
    print("wrote", args.out)


if __name__ == "__main__":
    main()
