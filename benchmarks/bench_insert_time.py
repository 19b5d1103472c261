"""Time per insertion: one procedural car, default preset, level auto, in-process, one camera at a time.

Usage::

    nice python benchmarks/bench_insert_time.py --tag after [--reps 4]
    # another checkout's code (a shim folder whose streetaug/{augment,cli,placement,datasets} link to it):
    PYTHONPATH=/tmp/shim_before nice python benchmarks/bench_insert_time.py --tag before
    # two checkouts interleaved (old, new, new, old, ...), pooled per checkout into insert_time_<tag>.json:
    nice python benchmarks/bench_insert_time.py --tag s6_x --compare /tmp/shim_old /tmp/shim_new --rounds 2

Items: CAM_FRONT of the three bundled sample scenes and four real scene-0916 views (keyframes 4, 16, 28
CAM_FRONT and 8 CAM_BACK, when ``../shared/data/nuscenes-seq`` is there). Each rep draws its own car and
seed; the first rep is a warm-up (imports, first-use tables) and is left out. Reports the median CPU
seconds (``time.process_time``: all threads) of ``insert_into_sample`` and of its render stage per item,
and the median of each stage the pipeline times (``timing_s``: lighting, placement -- the scene depth
included --, local_light, render ...; wall seconds) and the CPU seconds of placement and of the scene
depth inside it (``cpu_stage_s``), per item and over all items, and writes them with
every run to ``benchmarks/results/insert_time_<tag>.json``. One process, one item after the other: run
the two checkouts back to back (``--rounds`` alternations are left to the caller) on an otherwise idle
machine. Torch runs on one thread (``torch.set_num_threads(1)``).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import inspect  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tag", default="after")
    p.add_argument("--reps", type=int, default=4)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--compare", nargs=2, metavar=("OLD_SHIM", "NEW_SHIM"),
                   help="run this benchmark on two shim folders (PYTHONPATH) in turn, --rounds times each")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--profile", metavar="FILE",
                   help="cProfile (CPU time) the kept reps (not the warm-up) into FILE (pstats format)")
    p.add_argument("--items", help="comma-separated item names to run (default: all)")
    args = p.parse_args(argv)
    if args.compare:
        return compare(args)

    import torch

    torch.set_num_threads(1)
    import streetaug.augment.pipeline as pipeline
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.core.io import write_json_atomic
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    has_location = "location" in inspect.signature(select_assets).parameters  # older checkouts: no plates
    cpu = time_cpu_of({"placement": (pipeline.sample, "place_in_sample"),
                        "scene_depth": (pipeline.context, "scene_depth")})
    bundled = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    items = [(bundled, bundled.sample_tokens(name)[0], "CAM_FRONT", name)
             for name in ("sample-sunny", "sample-overcast", "sample-lowsun")]
    if (SEQ / "v1.0-mini").is_dir():
        real = NuScenesReader(SEQ, "v1.0-mini")
        tokens = real.sample_tokens()
        items += [(real, tokens[k], cam, f"scene-0916/{k}/{cam}")
                  for k, cam in ((4, "CAM_FRONT"), (16, "CAM_FRONT"), (28, "CAM_FRONT"), (8, "CAM_BACK"))]
    if args.items:
        items = [it for it in items if it[3] in args.items.split(",")]
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile(time.process_time)  # CPU seconds: the machine may be shared
    runs = []
    for rep in range(args.reps):
        for reader, token, cam, name in items:
            sample = reader.sample(token)
            where = {"location": sample.location} if has_location else {}
            assets = {cam: select_assets(pipeline.item_seed(rep, "asset", token, cam), 1, **where)}
            cpu.clear()
            if prof is not None and rep > 0:
                prof.enable()
            c0, w0 = time.process_time(), time.perf_counter()
            res = pipeline.insert_into_sample(sample, [sample.cameras[cam]], assets,
                                              pipeline.InsertOptions(seed=rep, n_objects=1))
            if prof is not None:
                prof.disable()
            view = res.views[cam]
            runs.append({"item": name, "rep": rep, "cpu_s": time.process_time() - c0,
                         "wall_s": time.perf_counter() - w0, "render_s": view.timing_s.get("render"),
                         "placed": len(view.objects), "timing_s": dict(view.timing_s),
                         "cpu_stage_s": dict(cpu)})
    if prof is not None:
        prof.dump_stats(args.profile)
    kept = [r for r in runs if r["rep"] > 0]
    per_item = {}
    for name in dict.fromkeys(r["item"] for r in kept):
        rs = [r for r in kept if r["item"] == name]
        rendered = [r["render_s"] for r in rs if r["placed"] and r["render_s"] is not None]
        per_item[name] = {"median_cpu_s": float(np.median([r["cpu_s"] for r in rs])),
                          "median_render_s": float(np.median(rendered)) if rendered else None,
                          "median_stage_s": stage_medians(rs), "median_cpu_stage_s": stage_medians(rs, "cpu_stage_s"),
                          "placed": sum(r["placed"] for r in rs), "runs": len(rs)}
    doc = {"tag": args.tag, "reps_kept": args.reps - 1, "load_avg": os.getloadavg(), "per_item": per_item,
           "median_cpu_s": float(np.median([r["cpu_s"] for r in kept])), "median_stage_s": stage_medians(kept),
           "median_cpu_stage_s": stage_medians(kept, "cpu_stage_s"), "runs": runs}
    out = Path(args.out) / f"insert_time_{args.tag}.json"
    write_json_atomic(out, doc)
    for name, v in per_item.items():
        render = "-" if v["median_render_s"] is None else f"{v['median_render_s']:.2f}"
        print(f"  {name:28s} cpu {v['median_cpu_s']:.2f} s, render {render} s ({v['placed']}/{v['runs']} placed)")
    print("  stages (median wall s): " + ", ".join(f"{k} {v:.3f}" for k, v in doc["median_stage_s"].items()))
    print("  CPU s: " + ", ".join(f"{k} {v:.3f}" for k, v in doc["median_cpu_stage_s"].items()))
    print(f"{args.tag}: median CPU per insertion {doc['median_cpu_s']:.2f} s; wrote {out}")


def time_cpu_of(functions: dict[str, tuple]) -> dict[str, float]:
    """Wrap each ``(module, name)`` so its CPU seconds (``time.process_time``) add up under its label in the
    returned dict (cleared by the caller per run); names a checkout lacks are skipped."""
    spent: dict[str, float] = {}
    for label, (module, name) in functions.items():
        f = getattr(module, name, None)
        if f is None:
            continue

        def timed(*a, _f=f, _label=label, **k):
            c = time.process_time()
            try:
                return _f(*a, **k)
            finally:
                spent[_label] = spent.get(_label, 0.0) + time.process_time() - c
        setattr(module, name, timed)
    return spent


def compare(args) -> None:
    """Interleaved runs of two checkouts (old first in odd rounds, new first in even ones), pooled per checkout."""
    import json
    import subprocess
    import sys
    import tempfile

    from streetaug.augment.core.io import write_json_atomic

    rounds: dict[str, list[dict]] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            order = [("old", args.compare[0]), ("new", args.compare[1])]
            for label, shim in order if k % 2 == 0 else order[::-1]:
                tag = f"{label}_r{k}"
                env = {**os.environ, "PYTHONPATH": shim}
                subprocess.run([sys.executable, __file__, "--tag", tag, "--reps", str(args.reps), "--out", tmp],
                               env=env, check=True)
                rounds[label].append(json.loads((Path(tmp) / f"insert_time_{tag}.json").read_text()))
    doc = {"tag": args.tag, "shims": {"old": args.compare[0], "new": args.compare[1]}, "rounds": args.rounds,
           "reps_kept_per_round": args.reps - 1}
    for label, docs in rounds.items():
        kept = [r for d in docs for r in d["runs"] if r["rep"] > 0]
        items = dict.fromkeys(r["item"] for r in kept)
        doc[label] = {"median_cpu_s": float(np.median([r["cpu_s"] for r in kept])),
                      "median_stage_s": stage_medians(kept), "median_cpu_stage_s": stage_medians(kept, "cpu_stage_s"),
                      "per_item": {n: {"median_cpu_s": float(np.median([r["cpu_s"] for r in kept if r["item"] == n])),
                                       "median_stage_s": stage_medians([r for r in kept if r["item"] == n]),
                                       "median_cpu_stage_s": stage_medians([r for r in kept if r["item"] == n],
                                                                           "cpu_stage_s")}
                                   for n in items},
                      "load_avg": [d.get("load_avg") for d in docs], "rounds": docs}
    out = Path(args.out) / f"insert_time_{args.tag}.json"
    write_json_atomic(out, doc)
    for label in ("old", "new"):
        stages = ", ".join(f"{k} {v:.3f}" for k, v in doc[label]["median_stage_s"].items())
        cpu = ", ".join(f"{k} {v:.3f}" for k, v in doc[label]["median_cpu_stage_s"].items())
        print(f"{label}: median CPU per insertion {doc[label]['median_cpu_s']:.3f} s; stages (wall s): {stages}; "
              f"CPU s: {cpu}")
    print(f"wrote {out}")


def stage_medians(runs: list[dict], key: str = "timing_s") -> dict[str, float]:
    """Stage -> median seconds over ``runs`` (the top-level stages of ``timing_s``: no ``render.*`` parts;
    ``key="cpu_stage_s"``: the CPU seconds of placement and of the scene depth inside it)."""
    stages = dict.fromkeys(k for r in runs for k in r.get(key, {}) if "." not in k)
    return {k: float(np.median([r[key][k] for r in runs if k in r.get(key, {})])) for k in stages}


if __name__ == "__main__":
    main()
