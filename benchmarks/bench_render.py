"""Renderer speed: median wall time per full 1600x900 insertion, per preset, with a per-stage breakdown.

Usage: ``python benchmarks/bench_render.py [--runs 5] [--out benchmarks/results/render_speed.json]``

Scenes: (1) the bundled sample scenes (``examples/nuscenes-samples``: CAM_FRONT of sample-sunny,
sample-overcast, sample-lowsun) with what the pipeline gives the renderer -- LiDAR-densified depth,
the L1 lighting estimate, a placed procedural car; (2) a Lambertian ground plane seen by a level
nuScenes-like camera (1.5 m high), lit by an analytic sky + sun and by an HDR panorama from
``../shared/data/hdri`` when present, procedural cars 15 m ahead.  1600 x 900, one core (BLAS
threads pinned to 1); the time is the renderer's (``render_insertion``: inputs decoded, no file I/O).

The machine may be shared, so next to wall time (``timing_s`` of the renderer) each run records its
CPU time, and Embree's raw occlusion rate on the same car is measured right before each preset's
runs (a fixed micro-benchmark in the same process).  ``unloaded_equiv_s`` rescales the wall time by
that rate against ``UNLOADED_EMBREE_OCCLUDED_RAYS_PER_S`` (measured on this machine when it was
nearly idle): a rough estimate of the idle-machine time.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from render_fixtures import NUSCENES_K, SHARED_DATA, ground_scene, read_hdri_light, sunny_light  # noqa: E402

from streetaug.augment.assets.procedural import procedural_car  # noqa: E402
from streetaug.augment.core import pose_camera_to_transform  # noqa: E402
from streetaug.augment.render import QUALITY_PRESETS, prepare_asset, render_insertion  # noqa: E402


def sample_scenes(cars) -> list:
    """(name, image, K, depth, light, ev, [(car, T, ground normal)]) for CAM_FRONT of each bundled scene."""
    from streetaug.augment.core import rotate_vectors
    from streetaug.augment.lighting.api import estimate_lighting
    from streetaug.augment.pipeline import InsertOptions, place_in_view, scene_depth_for_view
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    out = []
    for scene in ("sample-sunny", "sample-overcast", "sample-lowsun"):
        sample = reader.sample(reader.sample_tokens(scene)[0])
        view = sample.cameras["CAM_FRONT"]
        depth = scene_depth_for_view(sample, view)
        light = estimate_lighting(view, sample.location, "L1").light_cam
        placed = []
        for seed in range(6):
            car = cars[len(placed) % len(cars)]
            p = place_in_view(sample, view, [car], [], InsertOptions(seed=seed))
            if p.placements:
                pl = p.placements[0]
                placed.append((car, view.T_cam_from_global @ pl.T_global_from_object,
                               rotate_vectors(view.T_cam_from_global, pl.ground_normal_global[None])[0]))
            if len(placed) == 3:
                break
        if placed:
            out.append((scene, view.image, view.K, depth, light, 0.0, placed))
    return out


def ground_scenes(cars) -> list:
    """The synthetic ground-plane scenes (analytic sun; the sky panorama when present)."""
    lights = {"analytic_sun": sunny_light()}
    if (SHARED_DATA / "hdri" / "sky.hdr").is_file():
        lights["hdri_sky"] = read_hdri_light("sky")
    poses = [pose_camera_to_transform(1.0, 1.5, 15.0, yaw) for yaw in (35.0, 150.0, 260.0)]
    out = []
    for name, light in lights.items():
        image, depth, ev = ground_scene(light)
        out.append((name, image, NUSCENES_K, depth, light, ev, [(c, T, None) for c, T in zip(cars, poses)]))
    return out


def embree_raw_rate(asset, n_rays: int = 1_000_000) -> dict:
    """Rays/s of the bare RayScene calls (including its float conversions) on rays aimed at the car."""
    scene = prepare_asset(asset).scene
    rng = np.random.default_rng(0)
    d = rng.normal(size=(n_rays, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = asset.vertices.mean(axis=0)
    origins = centre - 10.0 * d + rng.normal(scale=1.0, size=(n_rays, 3))
    out = {}
    for name, fn in (("intersect", scene.intersect), ("occluded", scene.occluded)):
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            fn(origins, d)
            times.append(time.perf_counter() - t0)
        out[f"{name}_rays_per_s"] = n_rays / float(np.median(times))
    return out


UNLOADED_EMBREE_OCCLUDED_RAYS_PER_S = 12.5e6  # this machine at load average 1.2 (2 cores), 300k rays


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="runs per preset and scene (median reported)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "render_speed.json")
    args = ap.parse_args()

    cars = [procedural_car(seed) for seed in (0, 1, 2)]
    scenes = sample_scenes(cars) + ground_scenes(cars)

    results: dict = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                                 "cpu_count": os.cpu_count(), "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
                                 "load_avg_at_start": os.getloadavg()},
                     "image": [1600, 900], "presets": {}}
    for scene_name, image, K, depth, light, ev, placed in scenes:
        for preset in ("draft", "default", "high"):
            runs = []
            for car, T, _ in placed:  # warm the per-asset caches (BVH), as in a batch
                render_insertion(image, K, depth, light, car, T, quality="draft", ev=ev, seed=0)
            raw = embree_raw_rate(cars[0], 300_000)["occluded_rays_per_s"]
            for i in range(args.runs if preset != "high" else max(1, args.runs // 2)):
                car, T, normal = placed[i % len(placed)]
                t0, c0 = time.perf_counter(), time.process_time()
                res = render_insertion(image, K, depth, light, car, T, normal, quality=preset, ev=ev, seed=i)
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                runs.append({"wall_s": wall, "cpu_s": cpu, "timing_s": res.timing_s, "rays": res.stats["rays"],
                             "rays_total": res.stats["rays_total"], "car": car.name,
                             "object_pixels": float(res.coverage.sum())})
            raw = 0.5 * (raw + embree_raw_rate(cars[0], 300_000)["occluded_rays_per_s"])
            key = f"{preset}/{scene_name}"
            med = {stage: float(np.median([r["timing_s"][stage] for r in runs])) for stage in runs[0]["timing_s"]}
            rays = float(np.median([r["rays_total"] for r in runs]))
            cpu = float(np.median([r["cpu_s"] for r in runs]))
            equiv = med["total"] * raw / UNLOADED_EMBREE_OCCLUDED_RAYS_PER_S
            results["presets"][key] = {
                "median_total_s": med["total"], "median_cpu_s": cpu, "median_stage_s": med, "median_rays": rays,
                "rays_per_s_overall": rays / med["total"], "embree_raw_occluded_rays_per_s": raw,
                "overall_rate_vs_embree_raw": rays / med["total"] / raw,
                "unloaded_equiv_s": equiv, "unloaded_equiv_stage_s": {k: v * raw / UNLOADED_EMBREE_OCCLUDED_RAYS_PER_S for k, v in med.items()},
                "runs": runs,
                "settings": {k: getattr(QUALITY_PRESETS[preset], k) for k in QUALITY_PRESETS[preset].__dataclass_fields__},
            }
            print(f"{key:30s} total {med['total']*1000:7.1f} ms | " + " ".join(
                f"{k} {v*1000:.0f}" for k, v in med.items() if k != "total") + f" | rays {rays/1e6:.2f} M, "
                f"{rays/med['total']/1e6:.2f} M rays/s overall = {rays/med['total']/raw:.2f} x embree raw "
                f"({raw/1e6:.2f} M/s now) | CPU {cpu*1000:.0f} ms | unloaded-equivalent {equiv*1000:.0f} ms", flush=True)
    for preset in ("draft", "default", "high"):
        keys = [k for k in results["presets"] if k.startswith(preset + "/")]
        results.setdefault("summary", {})[preset] = {
            "median_total_s": float(np.median([results["presets"][k]["median_total_s"] for k in keys])),
            "median_cpu_s": float(np.median([results["presets"][k]["median_cpu_s"] for k in keys])),
            "median_unloaded_equiv_s": float(np.median([results["presets"][k]["unloaded_equiv_s"] for k in keys]))}
    results["embree_raw"] = embree_raw_rate(cars[0])
    results["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print("embree raw:", {k: f"{v/1e6:.2f} M/s" for k, v in results["embree_raw"].items()},
          f"| peak RSS {results['peak_rss_mb']:.0f} MB")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2, default=float) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
