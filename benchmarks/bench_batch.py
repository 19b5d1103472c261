"""Batch throughput: images/s with 1 and 2 local workers and a 2-worker Dask LocalCluster, peak RSS per
worker, and the projected wall time / cost of all nuScenes trainval keyframes (34,149 samples x 6 cameras).

Usage: ``python benchmarks/bench_batch.py [--replicas 12] [--quality default] [--repeats 1]
[--real] [--out benchmarks/results/batch_throughput.json]``

A dataset of its own (e.g. the real scene-0916): ``python benchmarks/bench_batch.py --dataroot
../shared/data/nuscenes-seq --version v1.0-mini [--limit 8] [--cameras CAM_FRONT,...] [--workers 2 1]
--out ...``: the first ``--limit`` keyframes (all cameras unless ``--cameras``), one run per worker count and
repeat. Each run also gives how busy the workers were by their tasks' wall time (sum of the samples' wall
seconds in the workers / (wall x workers)), robust to other jobs on the cores, and the driver's seconds
outside the workers (before the first dispatch, after the last result).

Dataset: the bundled sample scenes (1600x900; CAM_FRONT, CAM_FRONT_LEFT, CAM_BACK) replicated R times
with fresh tokens (files linked, not copied), so that there are enough samples to keep two workers
busy; each replica gets its own placements (seeds derive from the sample token). ``--real`` also
times the real nuScenes keyframe (../shared/data/nuscenes-real), replicated the same way, on one worker.
Wall time covers everything a user waits for (worker start-up, tables, contact sheet). The machine
may be shared: the load average before and after each run is recorded.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.batch import BatchConfig, RunOptions, read_log, run_batch  # noqa: E402
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "nuscenes-real"
TRAINVAL_SAMPLES = 34_149
TRAINVAL_CAMERAS = 6
# Replicated tables get fresh tokens; these are shared between replicas.
SHARED_TABLES = ("calibrated_sensor", "sensor", "log", "map", "category", "attribute", "visibility")


def replicate_dataset(src: Path, dst: Path, version: str, replicas: int) -> Path:
    """A dataroot with every sample of ``src`` repeated ``replicas`` times (new tokens, linked files)."""
    tables = {p.stem: json.loads(p.read_text()) for p in (src / version).glob("*.json")}
    own = [t for t in tables if t not in SHARED_TABLES]
    tokens = {r["token"] for t in own for r in tables[t]}
    out: dict[str, list[dict]] = {t: list(tables[t]) if t in SHARED_TABLES else [] for t in tables}
    (dst / version).mkdir(parents=True)
    if (src / "maps").is_dir():
        os.symlink(src.resolve() / "maps", dst / "maps")
    for k in range(replicas):
        def new(token: str) -> str:
            return hashlib.md5(f"replica{k}|{token}".encode()).hexdigest() if token in tokens else token

        def remap(value):
            if isinstance(value, str):
                return new(value)
            if isinstance(value, list) and all(isinstance(v, str) for v in value):
                return [new(v) for v in value]
            return value

        for t in own:
            for orig in tables[t]:
                row = {key: remap(v) for key, v in orig.items()}
                if t == "scene":
                    row["name"] = f"{row['name']}-r{k}"
                if t == "sample_data":
                    name = Path(orig["filename"])
                    row["filename"] = str(name.parent / f"r{k}__{name.name}")
                if t == "lidarseg":
                    row["filename"] = f"lidarseg/{version}/{row['sample_data_token']}_lidarseg.bin"
                if t in ("sample_data", "lidarseg"):
                    (dst / row["filename"]).parent.mkdir(parents=True, exist_ok=True)
                    os.symlink((src / orig["filename"]).resolve(), dst / row["filename"])
                out[t].append(row)
    for t, rows in out.items():
        (dst / version / f"{t}.json").write_text(json.dumps(rows))
    return dst


def busy_by_wall(rows: list, wall_s: float, workers: int) -> dict:
    """Sum of the samples' wall seconds in the workers (``seconds`` x cameras; every batch version logs it)
    over ``wall_s`` x ``workers``, and the per-sample walls' spread (what a last sample leaves idle)."""
    per_sample: dict[str, float] = {}
    for r in rows:
        per_sample[r.sample_token] = per_sample.get(r.sample_token, 0.0) + float(r.seconds or 0.0)
    busy = sum(per_sample.values())
    walls = sorted(per_sample.values())
    return {"busy_fraction": round(busy / (wall_s * workers), 3), "busy_workers": round(busy / wall_s, 2),
            "sample_wall_s_p50_max": [round(float(np.median(walls)), 2), round(walls[-1], 2)] if walls else None}


def timed_run(dataroot: Path, version: str, out: Path, quality: str, level: str, run: RunOptions, seed: int,
              limit: int | None = None, cameras: tuple[str, ...] = ()) -> dict:
    config = BatchConfig(dataroot=str(dataroot), version=version, quality=quality, level=level, seed=seed,
                         limit=limit, cameras=cameras)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    summary = run_batch(config, out, run)
    wall = time.perf_counter() - t0
    n_images = summary["this_run"]["images"]
    rss = [w["peak_rss_mb"] for w in summary["workers"].values()]
    # Per sample CPU seconds / cameras; the median leaves out each worker's one-off warm-up (first ephemeris
    # call, caches), which a real run amortises over thousands of samples.
    rows = read_log(out / "augment_log.jsonl")
    cpu = [r.cpu_s for r in rows]
    workers = run.dask_local or run.workers
    this_run = summary["this_run"]
    return {
        "wall_s": round(wall, 2),
        "images": n_images,
        "worker_cpu_s_per_image_mean": round(summary["this_run"]["worker_cpu_s"] / n_images, 4),
        "worker_cpu_s_per_image_median": round(float(np.median(cpu)), 4),
        "busy_workers": summary["this_run"]["busy_workers"],
        "ok_images": summary["counts"].get("ok", 0),
        "failed": summary["counts"].get("failed", 0),
        "images_per_s": round(n_images / wall, 4),
        "first_result_s": summary["this_run"]["first_result_s"],
        "steady_images_per_s": summary["this_run"]["steady_images_per_s"],
        "peak_rss_mb_per_worker": sorted(rss),
        "load_avg_1min_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)],
        "stage_p50_s": {k: v["p50"] for k, v in summary["stage_seconds"].items() if "." not in k},
        "counts": summary["counts"],
        # by the tasks' wall time, over the run's whole wall (driver included) and over the dispatch-to-last-result wall
        "busy_by_wall_whole_run": busy_by_wall(rows, wall, workers),
        "busy_by_wall_dispatch_to_last": busy_by_wall(rows, this_run["wall_s"], workers),
        "driver_s": {"before_dispatch": round(wall - this_run["wall_s"] - this_run.get("finalize_s", 0.0), 2)
                     if "finalize_s" in this_run else None,
                     "finalize": this_run.get("finalize_s")},
        "timeline": this_run.get("timeline"),  # this version's own account (None before it existed)
    }


def projection(cpu_s_per_image: float, usd_per_core_hour: float) -> dict:
    """Wall time and cost for every trainval keyframe image: one worker per core, linear over machines."""
    images = TRAINVAL_SAMPLES * TRAINVAL_CAMERAS
    per_core = 1.0 / cpu_s_per_image
    core_hours = images / per_core / 3600
    rows = {}
    for cores in (2, 32):
        for machines in (1, 8, 32, 128):
            hours = core_hours / (cores * machines)
            rows[f"{machines}x{cores}-core"] = {"wall_hours": round(hours, 2),
                                                "usd": round(core_hours * usd_per_core_hour, 2)}
    return {"images": images, "images_per_s_per_core": round(per_core, 4), "core_hours": round(core_hours, 1),
            "usd_per_core_hour_assumed": usd_per_core_hour, "machines": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--replicas", type=int, default=12,
                        help="copies of the 3 bundled samples (12: 108 images, ~1 min per mode on one core)")
    parser.add_argument("--quality", default="default", choices=["draft", "default", "high"])
    parser.add_argument("--level", default="auto", choices=["L0", "L1", "L2", "L3", "auto"])
    parser.add_argument("--repeats", type=int, default=1, help="runs per mode (medians are reported)")
    parser.add_argument("--real", action="store_true", help="also time the real keyframe (1 worker)")
    parser.add_argument("--usd-per-core-hour", type=float, default=0.04,
                        help="price assumed for the projection (on-demand compute-optimised vCPU, order of magnitude)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "batch_throughput.json")
    parser.add_argument("--dataroot", type=Path, help="time this nuScenes dataroot instead of the bundled replicas")
    parser.add_argument("--version", default="v1.0-mini", help="its table folder (with --dataroot)")
    parser.add_argument("--limit", type=int, help="the first N keyframes only (with --dataroot)")
    parser.add_argument("--cameras", default="", help="comma-separated channels (with --dataroot; default all)")
    parser.add_argument("--workers", type=int, nargs="+", default=[2], help="worker counts (with --dataroot)")
    parser.add_argument("--keep", type=Path, help="move each run's output folder under this folder (with --dataroot; "
                        "to compare the outputs of two code trees)")
    parser.add_argument("--label", default="", help="a name for this code tree in the report (with --dataroot)")
    parser.add_argument("--profile", action="store_true",
                        help="with --dataroot, 1 worker: CPU seconds per image of each stage of the per-sample path "
                             "(exclusive: a stage's nested stages are taken out of it), then a cProfile run for the "
                             "top functions; written to --out")
    parser.add_argument("--top", type=int, default=40, help="functions listed by --profile")
    args = parser.parse_args()
    if args.dataroot is not None and args.profile:
        profile_main(args)
        return
    if args.dataroot is not None:
        dataset_main(args)
        return

    modes = {"1 worker (inline)": RunOptions(workers=1, progress=False, contact_sheet=0),
             "2 local processes": RunOptions(workers=2, progress=False, contact_sheet=0),
             "Dask LocalCluster, 2 workers": RunOptions(dask_local=2, progress=False, contact_sheet=0)}
    results: dict[str, list[dict]] = {m: [] for m in modes}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = replicate_dataset(bundled_dataroot(), tmp / "data", BUNDLED_VERSION, args.replicas)
        for r in range(args.repeats):
            for name, run in modes.items():  # interleaved, so that a load spike hits every mode alike
                out = tmp / f"out-{r}-{len(results[name])}-{name.split()[0]}"
                results[name].append(timed_run(data, BUNDLED_VERSION, out, args.quality, args.level, run, seed=r))
                print(f"{name}: {results[name][-1]}", flush=True)
                shutil.rmtree(out)
        real = None
        if args.real and REAL.is_dir():
            real_data = replicate_dataset(REAL, tmp / "real", "v1.0-mini", 4 * args.replicas)
            real = timed_run(real_data, "v1.0-mini", tmp / "out-real", args.quality, args.level,
                             modes["1 worker (inline)"], 0)
            print(f"real keyframe, 1 worker: {real}", flush=True)

    def median(name: str, key: str) -> float:
        return float(np.median([x[key] for x in results[name]]))

    rate1 = median("1 worker (inline)", "images_per_s")
    rate2 = median("2 local processes", "images_per_s")
    rate_dask = median("Dask LocalCluster, 2 workers", "images_per_s")
    cpu = {name: median(name, "worker_cpu_s_per_image_median") for name in modes}
    cpu1 = cpu["1 worker (inline)"]
    report = {
        "benchmark": "streetaug batch throughput",
        "dataset": f"bundled sample scenes x{args.replicas} replicas "
                   f"({3 * args.replicas} samples x 3 cameras, 1600x900)",
        "quality": args.quality,
        "level": args.level,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "runs": results,
        "median_images_per_s": {"1 worker": rate1, "2 local processes": rate2, "Dask 2 workers": rate_dask},
        "scaling_1_to_2_workers": round(rate2 / rate1, 3),
        "scaling_1_to_dask_2": round(rate_dask / rate1, 3),
        # the same after each run's first result (worker start-up excluded): what a long run scales by
        "steady_scaling_1_to_2_workers": round(median("2 local processes", "steady_images_per_s")
                                               / median("1 worker (inline)", "steady_images_per_s"), 3),
        "steady_scaling_1_to_dask_2": round(median("Dask LocalCluster, 2 workers", "steady_images_per_s")
                                            / median("1 worker (inline)", "steady_images_per_s"), 3),
        "median_worker_cpu_s_per_image": cpu,  # median over samples, then over repeats
        # What 2 workers give when each has a core of its own: 2 x (CPU per image alone / CPU per image with 2).
        "cpu_bound_scaling_2_workers": round(2 * cpu1 / cpu["2 local processes"], 3),
        "cpu_bound_scaling_dask_2": round(2 * cpu1 / cpu["Dask LocalCluster, 2 workers"], 3),
        "real_keyframe_1_worker": real,
        "projection_trainval": projection(float(np.median(list(cpu.values()))), args.usd_per_core_hour),
        "note": "wall time includes worker start-up (first_result_s: spawning, imports, the first sample), the "
                "tables and the summary; steady_* rates count from each run's first result. On a shared machine "
                "(see the load averages and busy_workers) wall scaling is meaningless; the CPU seconds per image "
                "are not (much) affected by other jobs, so the projection uses them (one worker per core).",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps({k: report[k] for k in ("median_images_per_s", "scaling_1_to_2_workers", "scaling_1_to_dask_2",
                                             "steady_scaling_1_to_2_workers", "steady_scaling_1_to_dask_2",
                                             "median_worker_cpu_s_per_image", "cpu_bound_scaling_2_workers",
                                             "cpu_bound_scaling_dask_2", "projection_trainval")}, indent=2))
    print(f"wrote {args.out}")


def dataset_main(args: argparse.Namespace) -> None:
    """``--dataroot``: each worker count in turn, ``--repeats`` times (interleaved), on the given dataset."""
    import streetaug.augment

    cameras = tuple(c for c in args.cameras.split(",") if c)
    runs: dict[str, list[dict]] = {f"{w} workers": [] for w in args.workers}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for w in args.workers:
                run = RunOptions(workers=w, progress=False, contact_sheet=12)
                out = Path(tmp) / f"out-{r}-{w}"
                result = timed_run(args.dataroot.resolve(), args.version, out, args.quality, args.level, run, 0,
                                   args.limit, cameras)
                runs[f"{w} workers"].append(result)
                print(f"{w} workers: {json.dumps(result)}", flush=True)
                if args.keep:
                    args.keep.mkdir(parents=True, exist_ok=True)
                    shutil.move(str(out), str(args.keep / out.name))
                else:
                    shutil.rmtree(out)
    report = {
        "benchmark": "streetaug batch on a dataset",
        "code": args.label or str(Path(streetaug.augment.__file__).resolve().parent.parent),
        "dataset": str(args.dataroot), "version": args.version, "limit": args.limit, "cameras": list(cameras) or "all",
        "quality": args.quality, "level": args.level,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "runs": runs,
        "medians": {name: {k: float(np.median([x[k] for x in rs])) for k in
                           ("images_per_s", "worker_cpu_s_per_image_mean", "wall_s")}
                    | {"peak_rss_mb_max": float(np.median([max(x["peak_rss_mb_per_worker"]) for x in rs])),
                       "busy_fraction": float(np.median([x["busy_by_wall_whole_run"]["busy_fraction"] for x in rs]))}
                    for name, rs in runs.items()},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report["medians"], indent=2))
    print(f"wrote {args.out}")


# The per-sample path's stages: (stage, module, attribute) of the function whose calls make it (a class's method
# as "Class.method"). Patched where the caller looks the name up; nested stages are taken out of their parents.
PROFILE_STAGES = (
    ("reading: tables and sample", "streetaug.datasets.nuscenes", "NuScenesReader.sample"),
    ("reading: image decode", "streetaug.datasets.nuscenes", "NuScenesReader.camera_image"),
    ("reading: LiDAR decode", "streetaug.datasets.nuscenes", "NuScenesReader.lidar_sweep"),
    ("scene paint (per sample)", "streetaug.augment.batch.job", "scene_paint_mix"),
    ("assets: procedural objects (per camera)", "streetaug.augment.batch.job", "select_assets"),
    ("context: LiDAR into each camera", "streetaug.augment.pipeline.context", "ViewContext.of"),
    ("depth: densified scene depth (per camera)", "streetaug.augment.pipeline.context", "scene_depth"),
    ("placement", "streetaug.augment.pipeline.sample", "place_in_sample"),
    ("lighting (per sample)", "streetaug.augment.pipeline.sample", "shared_sample_lighting"),
    ("local light (per object, L2/L3 volume)", "streetaug.augment.pipeline.view", "object_light"),
    ("render: reaches view (footprint)", "streetaug.augment.pipeline.view", "reaches_view"),
    ("render: veil (per image)", "streetaug.augment.pipeline.objects", "estimate_veil"),
    ("render: prepare (asset, bounce, ambient)", "streetaug.augment.render.insert", "_prepare"),
    ("render: footprint", "streetaug.augment.render.insert", "footprint"),
    ("render: shadow", "streetaug.augment.render.insert", "render_shadow"),
    ("render: foreground (camera rays, surface, denoise)", "streetaug.augment.render.insert", "_foreground"),
    ("render: foreground shading", "streetaug.augment.render.foreground", "shade"),
    ("render: ray casting (embree, every stage)", "streetaug.augment.core.raycast", "RayScene.intersect"),
    ("render: ray casting (embree, every stage)", "streetaug.augment.core.raycast", "RayScene.occluded"),
    ("ray scene builds (BVH; every stage)", "streetaug.augment.core.raycast", "RayScene.__init__"),
    ("render: occluder depth", "streetaug.augment.render.insert", "ground_snapped_depth"),
    ("render: object layers", "streetaug.augment.render.insert", "object_layers"),
    ("composite (veil, blur, noise, JPEG)", "streetaug.augment.render.insert", "composite_layers"),
    ("camera look: blur and noise estimate (per object)", "streetaug.augment.render.composite",
     "estimate_camera_effects"),
    ("camera look: neutral axis", "streetaug.augment.render.insert", "neutral_axis"),
    ("camera look: neutral axis", "streetaug.augment.pipeline.objects", "neutral_axis"),
    ("camera look: apply neutral axis", "streetaug.augment.render.insert", "apply_neutral_axis"),
    ("render: other (per object)", "streetaug.augment.pipeline.objects", "render_insertion"),
    ("labels", "streetaug.augment.pipeline.view", "object_label"),
    ("writing: images and labels", "streetaug.augment.batch.job", "write_sample"),
    ("LiDAR: objects into the sweep, written", "streetaug.augment.batch.job", "write_lidar"),
)


class StageTimer:
    """Exclusive CPU seconds (``time.process_time``) and calls per stage: wraps the stages' functions in place."""

    def __init__(self) -> None:
        self.cpu: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self._stack: list[list] = []
        self._undo: list = []

    def wrap(self, stage: str, module: str, attribute: str) -> bool:
        import functools
        import importlib

        try:
            owner = importlib.import_module(module)
        except ImportError:
            return False
        *path, name = attribute.split(".")
        for part in path:
            owner = getattr(owner, part, None)
        fn = getattr(owner, name, None) if owner is not None else None
        if fn is None:
            return False
        timer = self

        @functools.wraps(fn)
        def timed(*a, **k):
            timer._stack.append([time.process_time(), 0.0])
            try:
                return fn(*a, **k)
            finally:
                t0, child = timer._stack.pop()
                spent = time.process_time() - t0
                timer.cpu[stage] = timer.cpu.get(stage, 0.0) + spent - child
                timer.calls[stage] = timer.calls.get(stage, 0) + 1
                if timer._stack:
                    timer._stack[-1][1] += spent

        setattr(owner, name, timed)
        self._undo.append((owner, name, fn))
        return True

    def unwrap(self) -> None:
        for owner, name, fn in reversed(self._undo):
            setattr(owner, name, fn)
        self._undo.clear()


def profile_main(args: argparse.Namespace) -> None:
    """``--profile``: one run with the stage timers alone, one under cProfile (top functions); 1 worker, inline."""
    import cProfile
    import pstats

    import streetaug.augment
    from streetaug.augment.batch import job as _job  # noqa: F401 - the modules the stages are patched in
    from streetaug.augment.pipeline import objects as _objects, view as _view  # noqa: F401

    cameras = tuple(c for c in args.cameras.split(",") if c)
    report: dict = {"benchmark": "streetaug batch profile: CPU seconds per image of each stage (1 worker, inline)",
                    "code": args.label or str(Path(streetaug.augment.__file__).resolve().parent.parent),
                    "dataset": str(args.dataroot), "limit": args.limit, "cameras": list(cameras) or "all",
                    "quality": args.quality, "level": args.level,
                    "machine": {"cpus": os.cpu_count(), "python": platform.python_version()}}
    run = RunOptions(workers=1, progress=False, contact_sheet=0)
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("timers", "cprofile"):
            timer = StageTimer()
            missing = [f"{m}.{a}" for _, m, a in PROFILE_STAGES if not timer.wrap(_, m, a)]
            prof = cProfile.Profile(time.process_time) if mode == "cprofile" else None
            config = BatchConfig(dataroot=str(args.dataroot.resolve()), version=args.version, quality=args.quality,
                                 level=args.level, seed=0, limit=args.limit, cameras=cameras)
            load0 = os.getloadavg()[0]
            cpu0 = time.process_time()
            if prof:
                prof.enable()
            summary = run_batch(config, Path(tmp) / mode, run)
            if prof:
                prof.disable()
            cpu = time.process_time() - cpu0
            timer.unwrap()
            n = summary["this_run"]["images"]
            stages = {k: {"cpu_s_per_image": round(v / n, 4), "calls": timer.calls[k],
                          "share": round(v / cpu, 3)} for k, v in sorted(timer.cpu.items(), key=lambda kv: -kv[1])}
            rest = cpu - sum(timer.cpu.values())
            stages["other (driver, tables, the rest)"] = {"cpu_s_per_image": round(rest / n, 4), "calls": 0,
                                                          "share": round(rest / cpu, 3)}
            entry = {"images": n, "cpu_s_total": round(cpu, 2), "cpu_s_per_image": round(cpu / n, 4),
                     "load_avg_1min_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)],
                     "stages": stages, "unpatched": missing}
            if prof:
                stats = pstats.Stats(prof)
                top = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[: args.top]  # by own time
                entry["top_functions_by_own_time"] = [
                    {"function": f"{_short(f)}:{line}({name})", "own_cpu_s_per_image": round(tt / n, 4),
                     "cumulative_cpu_s_per_image": round(ct / n, 4), "calls": nc}
                    for (f, line, name), (cc, nc, tt, ct, _) in top]
                entry["note"] = "under cProfile (Python-heavy code is inflated); the timers run has the true stage costs"
            report[mode] = entry
            print(json.dumps({mode: {k: v["cpu_s_per_image"] for k, v in stages.items()}}, indent=1), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {args.out}")


def _short(path: str) -> str:
    for marker in ("site-packages/", f"{ROOT}/", "/streetaug/", "python3.11/"):
        if marker in path:
            return path.split(marker, 1)[1]
    return path


if __name__ == "__main__":
    main()
