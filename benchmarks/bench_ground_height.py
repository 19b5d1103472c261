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
fewer than 3 such vehicles are left out. nuScenes' global frame drifts in height from keyframe to keyframe (ego
z = 0; :mod:`streetaug.placement.height_drift`), so each reference bottom is first carried into the
placement's keyframe by the drift the static annotated objects measure there (``all``); ``all_raw`` is the
uncorrected reference (what this benchmark reported before 2026-12-02's third session).
Writes ``benchmarks/results/ground_height_<tag>.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
RADIUS_M, MIN_OBJECTS = 8.0, 3


def _reference_drift_module():
    """This checkout's :mod:`streetaug.placement.height_drift`, loaded by path (the reference stays the same
    when ``PYTHONPATH`` points ``streetaug`` at another checkout)."""
    spec = importlib.util.spec_from_file_location("reference_height_drift", ROOT / "placement" / "height_drift.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _annotated_instances(tokens: list[str]) -> list[SimpleNamespace]:
    """Per keyframe (``tokens`` order) its annotations as boxes with instance tokens, read from the tables."""
    rows = json.loads((SEQ / "v1.0-mini" / "sample_annotation.json").read_text())
    per = {t: [] for t in tokens}
    for r in rows:
        if r["sample_token"] in per:
            per[r["sample_token"]].append(SimpleNamespace(center=np.array(r["translation"], np.float64),
                                                          wlh=np.array(r["size"], np.float64),
                                                          instance_token=r["instance_token"]))
    return [SimpleNamespace(boxes=per[t]) for t in tokens]


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
    drift = _reference_drift_module()
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
    keyframe_of = {t: k for k, t in enumerate(tokens)}
    owner_k = np.array([keyframe_of[t] for t in owner])
    static_m = drift.static_bottoms(_annotated_instances(tokens))
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
                dz = drift.height_drift_m(static_m, xyz[:2], keyframe_of[token])  # (K,) relative to this keyframe
                rows.append({"sample": token, "ground_source": pl.ground_source,
                             "distance_from_ego_m": float(np.linalg.norm(xyz[:2] - ego_xy)),
                             "error_m": float(xyz[2] - np.median(ground_z[near] - dz[owner_k[near]])),
                             "error_raw_m": float(xyz[2] - np.median(ground_z[near]))})
    err = np.abs([r["error_m"] for r in rows])
    err_raw = np.abs([r["error_raw_m"] for r in rows])
    far = np.array([r["distance_from_ego_m"] > 25 for r in rows])

    def summary(e: np.ndarray) -> dict:
        return {"n": int(len(e)), "median_abs_m": float(np.median(e)), "p90_abs_m": float(np.percentile(e, 90)),
                "max_abs_m": float(e.max()), "share_above_0.5_m": float(np.mean(e > 0.5)),
                "share_above_1_m": float(np.mean(e > 1.0))}

    doc = {"tag": args.tag, "data": "nuscenes-seq scene-0916", "stride": args.stride, "cars_per_camera": 3,
           "reference": f"median bottom of >= {MIN_OBJECTS} annotated vehicles of other keyframes within {RADIUS_M} m, "
                        "carried into the placement's keyframe by the height drift (all_raw: not carried)",
           "ground_sources": sources, "all": summary(err), "beyond_25_m": summary(err[far]), "all_raw": summary(err_raw),
           "seconds": time.perf_counter() - t0, "rows": rows}
    out = Path(args.out) / f"ground_height_{args.tag}.json"
    write_json_atomic(out, doc)
    a, f, r = doc["all"], doc["beyond_25_m"], doc["all_raw"]
    print(f"{args.tag}: {a['n']} placements, |ground error| median {a['median_abs_m']:.2f} m, p90 {a['p90_abs_m']:.2f}, "
          f"max {a['max_abs_m']:.2f}, > 0.5 m {a['share_above_0.5_m']:.0%}, > 1 m {a['share_above_1_m']:.0%}; "
          f"beyond 25 m: median {f['median_abs_m']:.2f}, > 0.5 m {f['share_above_0.5_m']:.0%}; sources {sources}; "
          f"raw reference: median {r['median_abs_m']:.2f}, p90 {r['p90_abs_m']:.2f}, max {r['max_abs_m']:.2f}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
