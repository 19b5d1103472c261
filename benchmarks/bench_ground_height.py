"""Ground height under placed objects on the real dev scene, against the annotators' ground.

Usage::

    nice python benchmarks/bench_ground_height.py [--stride 3] [--tag after]
    # another checkout's code: a shim folder whose streetaug/{augment,cli,placement,datasets} link to it
    PYTHONPATH=/tmp/shim_before nice python benchmarks/bench_ground_height.py --tag before

Data: ``../shared/data/nuscenes-seq`` (scene-0916, 41 keyframes x 6 cameras, LiDAR, no lidarseg). Every
``--stride``-th keyframe, all 6 cameras: ``place_in_sample`` places 3 procedural cars per camera (the
CLI's asset choice, seed 0). Each placement's ground height (the object frame's origin z) is compared
with the median bottom height of the annotated vehicles of the *other* keyframes standing within 8 m
(nuScenes boxes are annotated on the LiDAR: their bottoms are the ground a car stands on); placements with
fewer than 3 such vehicles are left out. Writes ``benchmarks/results/ground_height_<tag>.json``.
"""

from __future__ import annotations

import argparse
import inspect
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
RADIUS_M, MIN_OBJECTS = 8.0, 3


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--stride", type=int, default=3)
    p.add_argument("--tag", default="after")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)

    import streetaug.augment.pipeline as pipeline
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.core.io import write_json_atomic
    from streetaug.datasets.nuscenes import NuScenesReader

    if not (SEQ / "v1.0-mini").is_dir():
        raise SystemExit(f"{SEQ}: the real dev scene is not here")
    t0 = time.perf_counter()
    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens()
    samples = {t: reader.sample(t) for t in tokens}
    centres, heights, owner = [], [], []
    for t, s in samples.items():
        for b in s.boxes:
            if not b.category.startswith("vehicle."):  # people stand on sidewalks and platforms
                continue
            centres.append(np.asarray(b.center, np.float64))
            heights.append(float(b.wlh[2]))
            owner.append(t)
    C, owner = np.array(centres), np.array(owner)
    ground_z = C[:, 2] - 0.5 * np.array(heights)
    has_location = "location" in inspect.signature(select_assets).parameters  # older checkouts: no plates
    rows, sources = [], {}
    for token in tokens[:: args.stride]:
        s = samples[token]
        views = [s.cameras[c] for c in CAMERAS]
        where = {"location": s.location} if has_location else {}
        assets = {c: select_assets(pipeline.item_seed(0, "asset", token, c), 3, **where) for c in CAMERAS}
        placed = pipeline.place_in_sample(s, views, assets, pipeline.InsertOptions(seed=0, n_objects=3))
        ego_xy = s.cameras["CAM_FRONT"].T_global_from_ego[:2, 3]
        for pl in placed.placements:
            xyz = pl.T_global_from_object[:3, 3]
            sources[pl.ground_source] = sources.get(pl.ground_source, 0) + 1
            near = (np.linalg.norm(C[:, :2] - xyz[:2], axis=1) < RADIUS_M) & (owner != token)
            if near.sum() >= MIN_OBJECTS:
                rows.append({"sample": token, "ground_source": pl.ground_source,
                             "distance_from_ego_m": float(np.linalg.norm(xyz[:2] - ego_xy)),
                             "error_m": float(xyz[2] - np.median(ground_z[near]))})
    err = np.abs([r["error_m"] for r in rows])
    far = np.array([r["distance_from_ego_m"] > 25 for r in rows])

    def summary(e: np.ndarray) -> dict:
        return {"n": int(len(e)), "median_abs_m": float(np.median(e)), "p90_abs_m": float(np.percentile(e, 90)),
                "max_abs_m": float(e.max()), "share_above_0.5_m": float(np.mean(e > 0.5)),
                "share_above_1_m": float(np.mean(e > 1.0))}

    doc = {"tag": args.tag, "data": "nuscenes-seq scene-0916", "stride": args.stride, "cars_per_camera": 3,
           "reference": f"median bottom of >= {MIN_OBJECTS} annotated vehicles of other keyframes within {RADIUS_M} m",
           "ground_sources": sources, "all": summary(err), "beyond_25_m": summary(err[far]),
           "seconds": time.perf_counter() - t0, "rows": rows}
    out = Path(args.out) / f"ground_height_{args.tag}.json"
    write_json_atomic(out, doc)
    a, f = doc["all"], doc["beyond_25_m"]
    print(f"{args.tag}: {a['n']} placements, |ground error| median {a['median_abs_m']:.2f} m, p90 {a['p90_abs_m']:.2f}, "
          f"max {a['max_abs_m']:.2f}, > 0.5 m {a['share_above_0.5_m']:.0%}, > 1 m {a['share_above_1_m']:.0%}; "
          f"beyond 25 m: median {f['median_abs_m']:.2f}, > 0.5 m {f['share_above_0.5_m']:.0%}; sources {sources}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
