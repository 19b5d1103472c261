"""LiDAR insertion: points on inserted cars against real cars at the same distance, and its cost.

Usage: ``python benchmarks/bench_lidar_insert.py [--seeds 16] [--out benchmarks/results/lidar_insert.json]``

For each sample (the bundled scenes, and the real keyframe in ``../shared/data/nuscenes-real`` when present)
and each seed, one procedural car is placed per camera as ``streetaug batch`` would (same seeds, same
rules), then put into the keyframe sweep with :func:`augment.pipeline.lidar.insert_placements_into_sweep`,
with and without the beams that returned nothing (``use_empty_beams``). Reported per distance bin (LiDAR to
box centre): the median number of points in an inserted car's box both ways, the annotated cars' own
``num_lidar_pts`` in the same bins (the real sample: 8 cars; the bundled scenes: the generator's parked
cars), and the median time of one insertion.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.assets.select import select_assets  # noqa: E402
from streetaug.augment.pipeline.lidar import insert_placements_into_sweep  # noqa: E402
from streetaug.augment.pipeline import InsertOptions, item_seed, place_in_sample  # noqa: E402
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot  # noqa: E402
from streetaug.datasets.lidarseg import read_lidar_points, read_lidarseg_labels  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()
BINS_M = ((10.0, 20.0), (20.0, 30.0), (30.0, 45.0))


def dataset_rows(reader: NuScenesReader, seeds: int) -> tuple[list[dict], list[dict], list[float]]:
    """(inserted cars, annotated cars, insertion seconds) over every sample of a dataset."""
    inserted, annotated, seconds = [], [], []
    class_index = {c["name"]: c["index"] for c in reader.table("category") if "index" in c}
    for token in (s["token"] for s in reader.table("sample")):
        sample = reader.sample(token)
        sd = reader.lidar_sample_data(token)
        if sd is None:
            continue
        points = read_lidar_points(reader.dataroot / sd["filename"])
        seg = reader.lidarseg_path(sd["token"])
        labels = None if seg is None else read_lidarseg_labels(seg, num_points=len(points))
        T_global_from_lidar = reader.T_global_from_ego(sd) @ reader.T_ego_from_sensor(sd)
        origin = T_global_from_lidar[:3, 3]
        for b in sample.boxes:
            if b.category == "vehicle.car" and b.token:
                n = reader.get("sample_annotation", b.token).get("num_lidar_pts")
                annotated.append({"sample": token, "distance_m": float(np.linalg.norm(b.center[:2] - origin[:2])),
                                  "points": int(n)})
        views = list(sample.cameras.values())
        for seed in range(seeds):
            assets = {v.channel: select_assets(item_seed(seed, "asset", token, v.channel), 1) for v in views}
            placed = place_in_sample(sample, views, assets, InsertOptions(seed=seed))
            if not placed.placements:
                continue
            counts = {}
            for use in (True, False):
                t = time.perf_counter()
                out = insert_placements_into_sweep(points, labels, T_global_from_lidar, placed.placements, placed.assets,
                                                   sample.boxes, class_index, use_empty_beams=use)
                if use:
                    seconds.append(time.perf_counter() - t)
                counts[use] = out.num_lidar_pts
            for i, p in enumerate(placed.placements):
                inserted.append({"sample": token, "seed": seed, "camera": placed.placed_for[i],
                                 "distance_m": float(np.linalg.norm(p.box.center[:2] - origin[:2])),
                                 "points": counts[True][i], "points_without_empty_beams": counts[False][i]})
    return inserted, annotated, seconds


def by_bin(rows: list[dict], key: str) -> dict:
    out = {}
    for lo, hi in BINS_M:
        vals = [r[key] for r in rows if lo <= r["distance_m"] < hi]
        out[f"{lo:.0f}-{hi:.0f} m"] = {"n": len(vals), "median": float(np.median(vals)) if vals else None}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=16, help="placements per sample (seeds 0..N-1)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "lidar_insert.json")
    args = ap.parse_args()
    result = {"bins_m": BINS_M, "datasets": {}}
    sets = [("bundled", NuScenesReader(bundled_dataroot(), BUNDLED_VERSION))]
    if REAL.exists():
        sets.append(("real", NuScenesReader(REAL, "v1.0-mini")))
    for name, reader in sets:
        inserted, annotated, seconds = dataset_rows(reader, args.seeds)
        summary = {
            "inserted_cars": len(inserted),
            "inserted_points": by_bin(inserted, "points"),
            "inserted_points_without_empty_beams": by_bin(inserted, "points_without_empty_beams"),
            "annotated_car_points": by_bin(annotated, "points"),
            "insertion_ms_median": 1e3 * float(np.median(seconds)) if seconds else None,
        }
        result["datasets"][name] = summary | {"inserted": inserted}  # the annotations themselves stay in the data
        print(f"{name}: {len(inserted)} inserted cars, insertion {summary['insertion_ms_median']:.1f} ms (median)")
        for b in summary["inserted_points"]:
            a, w, r = (summary[k][b] for k in ("inserted_points", "inserted_points_without_empty_beams",
                                                "annotated_car_points"))
            print(f"  {b:>8}: inserted median {a['median']} points (without empty beams {w['median']}; n={a['n']}), "
                  f"annotated cars {r['median']} (n={r['n']})")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
