"""Renderer speed: median wall time per full 1600x900 insertion, per preset, with a per-stage breakdown.

Usage: ``python benchmarks/bench_render.py [--runs 5] [--out benchmarks/results/render_speed.json]``

Scene: a Lambertian ground plane seen by a level nuScenes-like camera (1.5 m high), lit by an
analytic sky + sun and by an HDR panorama from ``../shared/data/hdri`` when present; procedural
cars (``augment/assets/procedural.py``) 15 m ahead.  One core: BLAS threads are pinned to 1.
Also measures Embree's raw rate on the same car (closest-hit and occlusion queries, 1M rays).
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
from streetaug.augment.conventions import pose_camera_to_transform  # noqa: E402
from streetaug.augment.render.geometry import prepare_asset  # noqa: E402
from streetaug.augment.render.insert import QUALITY_PRESETS, render_insertion  # noqa: E402


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="runs per preset and scene (median reported)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "render_speed.json")
    args = ap.parse_args()

    lights = {"analytic_sun": sunny_light()}
    if (SHARED_DATA / "hdri" / "sky.hdr").is_file():
        lights["hdri_sky"] = read_hdri_light("sky")
    cars = [procedural_car(seed) for seed in (0, 1, 2)]
    poses = [pose_camera_to_transform(1.0, 1.5, 15.0, yaw) for yaw in (35.0, 150.0, 260.0)]

    results: dict = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                                 "cpu_count": os.cpu_count(), "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
                                 "load_avg_at_start": os.getloadavg()},
                     "image": [1600, 900], "distance_m": 15.0, "presets": {}}
    for light_name, light in lights.items():
        image, depth, ev = ground_scene(light)
        for preset in ("draft", "default", "high"):
            runs = []
            for i in range(args.runs if preset != "high" else max(1, args.runs // 2)):
                car, T = cars[i % len(cars)], poses[i % len(poses)]
                render_insertion(image, NUSCENES_K, depth, light, car, T, quality=preset, ev=ev, seed=i) if i == 0 else None
                t0 = time.perf_counter()
                res = render_insertion(image, NUSCENES_K, depth, light, car, T, quality=preset, ev=ev, seed=i)
                wall = time.perf_counter() - t0
                runs.append({"wall_s": wall, "timing_s": res.timing_s, "rays": res.stats["rays"],
                             "rays_total": res.stats["rays_total"], "car": car.name,
                             "object_pixels": float(res.coverage.sum())})
            key = f"{preset}/{light_name}"
            med = {stage: float(np.median([r["timing_s"][stage] for r in runs])) for stage in runs[0]["timing_s"]}
            rays = float(np.median([r["rays_total"] for r in runs]))
            raycast = med.get("raycast", 0.0)
            results["presets"][key] = {
                "median_total_s": med["total"], "median_stage_s": med, "median_rays": rays,
                "rays_per_s_overall": rays / med["total"],
                "runs": runs,
                "settings": {k: getattr(QUALITY_PRESETS[preset], k) for k in QUALITY_PRESETS[preset].__dataclass_fields__},
            }
            print(f"{key:28s} total {med['total']*1000:7.1f} ms | " + " ".join(
                f"{k} {v*1000:.0f}" for k, v in med.items() if k != "total") + f" | rays {rays/1e6:.2f} M, "
                f"{rays/med['total']/1e6:.2f} M rays/s overall (foreground raycast alone {raycast*1000:.0f} ms)")
    results["embree_raw"] = embree_raw_rate(cars[0])
    results["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print("embree raw:", {k: f"{v/1e6:.2f} M/s" for k, v in results["embree_raw"].items()},
          f"| peak RSS {results['peak_rss_mb']:.0f} MB")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2, default=float) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
