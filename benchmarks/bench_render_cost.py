"""Render-stage cost on real scene-0916 inserts: capture the renderer's inputs once, replay them per checkout.

Usage::

    # 1. capture: insert through the pipeline (default options, all 6 cameras of some keyframes), pickle
    #    every render_insertion call (+ one near car per CAM_FRONT, moved to ~11 m on its ground plane)
    nice python benchmarks/bench_render_cost.py capture --keyframes 4,16,28 --out /tmp/render_cost_inputs.pkl
    # 2. replay two checkouts interleaved (fresh subprocesses, shim folders on PYTHONPATH), one thread
    nice python benchmarks/bench_render_cost.py compare /tmp/shim_old /tmp/shim_new --inputs /tmp/render_cost_inputs.pkl \
        --rounds 3 --json benchmarks/results/render_cost_s6.json
    # profile one checkout's replay
    nice python benchmarks/bench_render_cost.py replay --inputs /tmp/render_cost_inputs.pkl --profile /tmp/render.prof

Replays time ``render_insertion`` alone (CPU seconds, ``time.process_time``, torch / BLAS on one thread) and
keep its ``timing_s`` stages (shadow, foreground = raycast + shade, composite); the images of the two
checkouts are compared (PSNR over the object's pixel box, LDR) so a speed-up that changes the picture shows.
The inputs are pictures of the shared data: they stay in /tmp, never in the repository.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
NEAR_DISTANCE_M = 11.0


def capture(args) -> None:
    """Run the pipeline on scene-0916 keyframes; pickle the renderer's inputs of every insert."""
    import torch

    torch.set_num_threads(1)
    import streetaug.augment.pipeline as pipeline
    import streetaug.augment.pipeline.objects as objects
    from streetaug.augment.assets.select import select_assets
    from streetaug.datasets.nuscenes import NuScenesReader

    calls: list[dict] = []
    real_render = objects.render_insertion

    def recording(image, K, depth_m, light, asset, T, **kw):
        calls.append({"image": image, "K": K, "depth_m": depth_m, "light": light, "asset": asset, "T": np.asarray(T),
                      "kw": kw, "item": current["item"]})
        return real_render(image, K, depth_m, light, asset, T, **kw)

    objects.render_insertion = recording
    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens()
    current = {}
    for k in [int(x) for x in args.keyframes.split(",")]:
        sample = reader.sample(tokens[k])
        chans = [c for c in CAMERAS if c in sample.cameras]
        views = [sample.cameras[c] for c in chans]
        assets = {c: select_assets(pipeline.item_seed(k, "asset", tokens[k], c), 1, location=sample.location) for c in chans}
        current["item"] = f"kf{k}"
        pipeline.insert_into_sample(sample, views, assets, pipeline.InsertOptions(seed=k, n_objects=1))
    for i, c in enumerate(calls):
        c["item"] += f"/{sum(d['item'].split('/')[0] == c['item'] for d in calls[:i])}"
    near = [dict(c, T=_moved_to(c["T"], c["kw"].get("ground_normal_cam"), NEAR_DISTANCE_M), item=c["item"] + "/near")
            for c in calls if np.linalg.norm(c["T"][:3, 3]) > NEAR_DISTANCE_M + 2 and abs(c["T"][0, 3]) < 4.0]
    calls += near[: args.near]
    for c in calls:  # the asset's cached preparation (Embree scene) is rebuilt by each replay
        c["asset"] = _bare(c["asset"])
    with open(args.out, "wb") as f:
        pickle.dump(calls, f)
    print(f"captured {len(calls)} renders ({len(near[: args.near])} near) -> {args.out}")


def _bare(asset):
    """The asset without caches attached to it (they are not picklable and belong to one process)."""
    import copy

    a = copy.copy(asset)
    for key in [k for k in vars(a) if k.startswith("_")]:
        try:
            object.__delattr__(a, key)
        except AttributeError:
            pass
    return a


def _moved_to(T: np.ndarray, up_cam, distance_m: float) -> np.ndarray:
    """The pose moved along its own ground plane to ``distance_m`` from the camera (same bearing)."""
    T = np.array(T, dtype=np.float64)
    n = np.asarray(T[:3, 2] if up_cam is None else up_cam, dtype=np.float64)
    n = n / np.linalg.norm(n)
    t = T[:3, 3]
    p = t * (distance_m / np.linalg.norm(t))
    T[:3, 3] = p + n * (n @ t - n @ p)
    return T


def replay(args) -> dict:
    """Render every captured input (``--reps`` times), CPU seconds and stages per render; optional profile."""
    import torch

    torch.set_num_threads(1)
    from streetaug.augment.core import hdr_to_ldr_uint8  # noqa: F401  (import cost outside the timing)
    from streetaug.augment.render import prepare_asset, render_insertion

    import streetaug.augment.render.insert as insert_mod

    from bench_insert_time import time_cpu_of  # this folder is the script's sys.path[0]

    cpu_stage = time_cpu_of({"shadow": (insert_mod, "render_shadow"), "foreground": (insert_mod, "_foreground"),
                             "composite": (insert_mod, "composite_layers")})
    with open(args.inputs, "rb") as f:
        calls = pickle.load(f)
    for c in calls:
        prepare_asset(c["asset"])  # BVH once per asset (as a batch does), outside the timing
    render_insertion(calls[0]["image"], calls[0]["K"], calls[0]["depth_m"], calls[0]["light"], calls[0]["asset"],
                     calls[0]["T"], **calls[0]["kw"])  # warm-up
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
    rows, images = [], {}
    for rep in range(args.reps):
        for c in calls:
            if prof:
                prof.enable()
            cpu_stage.clear()
            c0 = time.process_time()
            ins = render_insertion(c["image"], c["K"], c["depth_m"], c["light"], c["asset"], c["T"], **c["kw"])
            cpu = time.process_time() - c0
            if prof:
                prof.disable()
            box = _union_box(ins.footprint.object_box, ins.footprint.shadow_box) if ins.footprint is not None else None
            rows.append({"item": c["item"], "rep": rep, "cpu_s": cpu, "timing_s": dict(ins.timing_s),
                         "cpu_stage_s": dict(cpu_stage),
                         "object_box": None if ins.footprint is None or ins.footprint.object_box is None
                         else ins.footprint.object_box.as_list(), "box": box,
                         "rays": ins.stats.get("rays", {})})
            if rep == 0 and args.images:
                images[c["item"]] = ins.image
    if prof:
        prof.dump_stats(args.profile)
    if args.images:
        np.savez_compressed(args.images, **{k.replace("/", "_"): v for k, v in images.items()})
    return {"rows": rows}


def compare(args) -> None:
    """Old / new replays interleaved in fresh subprocesses; per-stage medians, ratios, image agreement."""
    pooled: dict[str, list] = {"old": [], "new": []}
    imgs = {}
    loads = [os.getloadavg()]
    for r in range(args.rounds):
        for name, shim in (("old", args.old), ("new", args.new)) if r % 2 == 0 else (("new", args.new), ("old", args.old)):
            out = Path(args.work) / f"render_cost_{name}_{r}.json"
            img = str(Path(args.work) / f"render_cost_{name}.npz")
            env = dict(os.environ, PYTHONPATH=shim, OMP_NUM_THREADS="1")
            cmd = [sys.executable, __file__, "replay", "--inputs", args.inputs, "--reps", str(args.reps),
                   "--result", str(out)] + (["--images", img] if r < 2 else [])
            subprocess.run(cmd, env=env, check=True)
            pooled[name] += json.loads(out.read_text())["rows"]
            imgs[name] = img
            loads.append(os.getloadavg())
            print(f"round {r} {name}: median render CPU {np.median([x['cpu_s'] for x in pooled[name]]):.3f} s", flush=True)
    doc = {"what": __doc__.split("\n")[0], "inputs": args.inputs, "old": args.old, "new": args.new,
           "rounds": args.rounds, "reps": args.reps, "load_avg": loads, "summary": {}, "per_item": {}}
    for name, rows in pooled.items():
        doc["summary"][name] = _medians(rows)
    doc["summary"]["ratio_new_over_old"] = {k: doc["summary"]["new"][k] / doc["summary"]["old"][k]
                                            for k in doc["summary"]["new"] if doc["summary"]["old"].get(k)}
    near = {n: [x for x in rows if x["item"].endswith("/near")] for n, rows in pooled.items()}
    if near["old"]:
        doc["summary"]["near"] = {n: _medians(rows) for n, rows in near.items()}
    a, b = np.load(imgs["old"]), np.load(imgs["new"])
    for item in sorted({x["item"] for x in pooled["old"]}):
        o = [x for x in pooled["old"] if x["item"] == item]
        n = [x for x in pooled["new"] if x["item"] == item]
        key = item.replace("/", "_")
        entry = {"old_cpu_s": float(np.median([x["cpu_s"] for x in o])), "new_cpu_s": float(np.median([x["cpu_s"] for x in n])),
                 "old_cpu_stage_s": _medians(o), "new_cpu_stage_s": _medians(n),
                 "object_box": o[0]["object_box"], "rays_old": o[0]["rays"], "rays_new": n[0]["rays"]}
        if key in a and key in b:
            entry["psnr_box_db"] = _psnr_box(a[key], b[key], o[0]["box"])
        doc["per_item"][item] = entry
    Path(args.json).write_text(json.dumps(doc, indent=1))
    s = doc["summary"]
    print("old: " + ", ".join(f"{k} {v:.3f}" for k, v in s["old"].items()))
    print("new: " + ", ".join(f"{k} {v:.3f}" for k, v in s["new"].items()))
    print("new/old: " + ", ".join(f"{k} {v:.2f}" for k, v in s["ratio_new_over_old"].items()))
    if "near" in s:
        print("near old/new cpu: " + f"{s['near']['old']['cpu_s']:.3f} / {s['near']['new']['cpu_s']:.3f}")
    ps = [v["psnr_box_db"] for v in doc["per_item"].values() if "psnr_box_db" in v]
    if ps:
        print(f"image agreement old vs new (object box, LDR): min {min(ps):.1f} dB, median {np.median(ps):.1f} dB")
    print(f"wrote {args.json}")


def _union_box(*boxes) -> list[int] | None:
    """[x0, y0, x1, y1] around the given pixel boxes (None entries skipped), or None."""
    got = [b.as_list()[:4] for b in boxes if b is not None]
    if not got:
        return None
    g = np.array(got)
    return [int(g[:, 0].min()), int(g[:, 1].min()), int(g[:, 2].max()), int(g[:, 3].max())]


def _medians(rows: list[dict]) -> dict[str, float]:
    """Median CPU seconds per render and median of each timing stage (wall seconds)."""
    out = {"cpu_s": float(np.median([x["cpu_s"] for x in rows])), "cpu_s_p90": float(np.percentile([x["cpu_s"] for x in rows], 90))}
    for k in rows[0]["timing_s"]:
        out[k] = float(np.median([x["timing_s"].get(k, 0.0) for x in rows]))
    for k in ("shadow", "foreground", "composite"):
        out[f"cpu_{k}_s"] = float(np.median([x["cpu_stage_s"].get(k, 0.0) for x in rows]))
        out[f"cpu_{k}_s_mean"] = float(np.mean([x["cpu_stage_s"].get(k, 0.0) for x in rows]))
    out["cpu_s_mean"] = float(np.mean([x["cpu_s"] for x in rows]))
    return out


def _psnr_box(a: np.ndarray, b: np.ndarray, box) -> float:
    """PSNR (dB) of two uint8 images over the pixel box [x0, y0, x1, y1] (whole image if None)."""
    if box is not None:
        x0, y0, x1, y1 = box[:4]
        a, b = a[y0:y1, x0:x1], b[y0:y1, x0:x1]
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture")
    c.add_argument("--keyframes", default="4,16,28")
    c.add_argument("--near", type=int, default=2, help="near (~11 m) copies of CAM_FRONT-ish inserts")
    c.add_argument("--out", default="/tmp/render_cost_inputs.pkl")
    r = sub.add_parser("replay")
    r.add_argument("--inputs", default="/tmp/render_cost_inputs.pkl")
    r.add_argument("--reps", type=int, default=1)
    r.add_argument("--profile")
    r.add_argument("--images")
    r.add_argument("--result")
    m = sub.add_parser("compare")
    m.add_argument("old")
    m.add_argument("new")
    m.add_argument("--inputs", default="/tmp/render_cost_inputs.pkl")
    m.add_argument("--rounds", type=int, default=2)
    m.add_argument("--reps", type=int, default=1)
    m.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "render_cost_s6.json"))
    m.add_argument("--work", default="/tmp", help="folder of the replays' results and images (outside the repository)")
    args = p.parse_args(argv)
    if args.cmd == "capture":
        capture(args)
    elif args.cmd == "replay":
        res = replay(args)
        if args.result:
            Path(args.result).write_text(json.dumps(res))
        rows = res["rows"]
        for k, v in _medians(rows).items():
            print(f"  {k}: {v:.3f}")
    else:
        compare(args)


if __name__ == "__main__":
    main()
