"""Time per insertion: one procedural car, default preset, level auto, in-process, one camera at a time.

Usage::

    nice python benchmarks/bench_insert_time.py --tag after [--reps 4]
    # another checkout's code (a shim folder whose streetaug/{augment,cli,placement,datasets} link to it):
    PYTHONPATH=/tmp/shim_before nice python benchmarks/bench_insert_time.py --tag before

Items: CAM_FRONT of the three bundled sample scenes and four real scene-0916 views (keyframes 4, 16, 28
CAM_FRONT and 8 CAM_BACK, when ``../shared/data/nuscenes-seq`` is there). Each rep draws its own car and
seed; the first rep is a warm-up (imports, first-use tables) and is left out. Reports the median CPU
seconds (``time.process_time``: all threads) of ``insert_into_sample`` and of its render stage per item,
and writes them with every run to ``benchmarks/results/insert_time_<tag>.json``. One process, one item
after the other: run the two checkouts back to back on an otherwise idle machine.
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
    args = p.parse_args(argv)

    import streetaug.augment.pipeline as pipeline
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.core.io import write_json_atomic
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    has_location = "location" in inspect.signature(select_assets).parameters  # older checkouts: no plates
    bundled = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    items = [(bundled, bundled.sample_tokens(name)[0], "CAM_FRONT", name)
             for name in ("sample-sunny", "sample-overcast", "sample-lowsun")]
    if (SEQ / "v1.0-mini").is_dir():
        real = NuScenesReader(SEQ, "v1.0-mini")
        tokens = real.sample_tokens()
        items += [(real, tokens[k], cam, f"scene-0916/{k}/{cam}")
                  for k, cam in ((4, "CAM_FRONT"), (16, "CAM_FRONT"), (28, "CAM_FRONT"), (8, "CAM_BACK"))]
    runs = []
    for rep in range(args.reps):
        for reader, token, cam, name in items:
            sample = reader.sample(token)
            where = {"location": sample.location} if has_location else {}
            assets = {cam: select_assets(pipeline.item_seed(rep, "asset", token, cam), 1, **where)}
            c0, w0 = time.process_time(), time.perf_counter()
            res = pipeline.insert_into_sample(sample, [sample.cameras[cam]], assets,
                                              pipeline.InsertOptions(seed=rep, n_objects=1))
            view = res.views[cam]
            runs.append({"item": name, "rep": rep, "cpu_s": time.process_time() - c0,
                         "wall_s": time.perf_counter() - w0, "render_s": view.timing_s.get("render"),
                         "placed": len(view.objects)})
    kept = [r for r in runs if r["rep"] > 0]
    per_item = {}
    for name in dict.fromkeys(r["item"] for r in kept):
        rs = [r for r in kept if r["item"] == name]
        rendered = [r["render_s"] for r in rs if r["placed"] and r["render_s"] is not None]
        per_item[name] = {"median_cpu_s": float(np.median([r["cpu_s"] for r in rs])),
                          "median_render_s": float(np.median(rendered)) if rendered else None,
                          "placed": sum(r["placed"] for r in rs), "runs": len(rs)}
    doc = {"tag": args.tag, "reps_kept": args.reps - 1, "per_item": per_item,
           "median_cpu_s": float(np.median([r["cpu_s"] for r in kept])), "runs": runs}
    out = Path(args.out) / f"insert_time_{args.tag}.json"
    write_json_atomic(out, doc)
    for name, v in per_item.items():
        render = "-" if v["median_render_s"] is None else f"{v['median_render_s']:.2f}"
        print(f"  {name:28s} cpu {v['median_cpu_s']:.2f} s, render {render} s ({v['placed']}/{v['runs']} placed)")
    print(f"{args.tag}: median CPU per insertion {doc['median_cpu_s']:.2f} s; wrote {out}")


if __name__ == "__main__":
    main()
