"""Blur / noise matching of the inserted object (``RenderSettings.match_camera``): estimation accuracy
and whether matching makes the object look like the image around it.

Usage: ``python benchmarks/bench_render_camera_effects.py [--out benchmarks/results/render_camera_effects.json]``

1. Estimation accuracy on synthetic images: random anti-aliased polygons (rendered 8x supersampled and
   area-averaged = ideal pixel integration, like the renderer's output), blurred with a Gaussian of
   known std (0 ... 3 px) and given Gaussian noise of known std (0 ... 8 levels of 255), quantised to
   uint8.  Reports the estimate and its error per (blur, noise).
2. Real photos (the bundled nuScenes-format sample images, and ``../shared/data/nuscenes-real`` when
   present): the estimate of the photo, then of the photo blurred / noised further by known amounts
   (the estimate should follow sqrt(b0^2 + b^2) and sqrt(n0^2 + n^2)).
3. Does it help: a procedural car is inserted into a real photo degraded with blur 1.5 px and noise
   4 levels, with matching off and on; the blur measured at the car's silhouette and the noise measured
   inside the car are compared with the photo's.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from render_fixtures import NUSCENES_K, SHARED_DATA, degrade, sharp_polygons, sunny_light  # noqa: E402

from streetaug.augment.assets.procedural import procedural_car  # noqa: E402
from streetaug.augment.core import pose_camera_to_transform  # noqa: E402
from streetaug.augment.render.camera_effects import estimate_blur_sigma, estimate_camera_effects, estimate_noise_sigma  # noqa: E402
from streetaug.augment.core.depth import ground_plane_depth  # noqa: E402
from streetaug.augment.render import QUALITY_PRESETS, render_insertion  # noqa: E402

BLURS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
NOISES = (0.0, 1.0, 2.0, 4.0, 8.0)  # levels of 255


def photos() -> list[tuple[str, np.ndarray]]:
    files = sorted((ROOT / "examples" / "nuscenes-samples" / "samples").glob("CAM_*/*.jpg"))
    real = SHARED_DATA / "nuscenes-real" / "samples"
    if real.is_dir():
        files += sorted(real.glob("CAM_*/*.jpg"))
    out = []
    for f in files:
        bgr = cv2.imread(str(f), cv2.IMREAD_COLOR)
        out.append((f"{f.parent.parent.parent.name}/{f.parent.name}", cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "render_camera_effects.json")
    args = ap.parse_args()
    doc: dict = {"load_avg_at_start": os.getloadavg(), "synthetic": [], "photos": [], "insertion": []}

    # 1. synthetic
    t_est = []
    for seed in (0, 1, 2):
        base = sharp_polygons(seed, 640, 360, n_polygons=40, radius_px=(20, 120))
        for b in BLURS:
            for n in NOISES:
                img = degrade(base, b, n)
                c0 = time.process_time()
                e = estimate_camera_effects(img)
                t_est.append(time.process_time() - c0)
                doc["synthetic"].append({"seed": seed, "blur_px": b, "noise_levels": n,
                                         "blur_est_px": e.blur_sigma_px, "noise_est_levels": 255 * e.noise_sigma,
                                         "edge_pixels": e.edge_pixels})
    rows = doc["synthetic"]
    summary = {}
    for n in NOISES:
        for b in BLURS:
            sel = [r for r in rows if r["blur_px"] == b and r["noise_levels"] == n]
            summary[f"blur{b}_noise{n}"] = {
                "blur_est_mean": float(np.mean([r["blur_est_px"] for r in sel])),
                "noise_est_mean": float(np.mean([r["noise_est_levels"] for r in sel]))}
    blur_err = [abs(r["blur_est_px"] - r["blur_px"]) for r in rows if r["noise_levels"] <= 4]
    noise_err = [abs(r["noise_est_levels"] - r["noise_levels"]) for r in rows]
    doc["synthetic_summary"] = {
        "blur_abs_err_px_noise_le_4": {"median": float(np.median(blur_err)), "p90": float(np.percentile(blur_err, 90)),
                                       "max": float(np.max(blur_err))},
        "noise_abs_err_levels": {"median": float(np.median(noise_err)), "p90": float(np.percentile(noise_err, 90)),
                                 "max": float(np.max(noise_err))},
        "estimate_cpu_s_median_640x360": float(np.median(t_est)), "table": summary}
    print("synthetic:", json.dumps(doc["synthetic_summary"]["blur_abs_err_px_noise_le_4"]),
          json.dumps(doc["synthetic_summary"]["noise_abs_err_levels"]))
    print("  blur estimates (rows: true blur; cols: noise levels", NOISES, ")")
    for b in BLURS:
        print(f"  {b:3.1f} px:", " ".join(f"{summary[f'blur{b}_noise{n}']['blur_est_mean']:5.2f}" for n in NOISES))

    # 2. photos: does the estimate follow added blur / noise?
    for name, img in photos():
        e0 = estimate_camera_effects(img)
        entry = {"image": name, "blur_px": e0.blur_sigma_px, "noise_levels": 255 * e0.noise_sigma, "added": []}
        f = img.astype(np.float32) / 255.0
        for b, n in ((1.0, 0.0), (2.0, 0.0), (0.0, 3.0), (0.0, 6.0), (1.5, 4.0)):
            e = estimate_camera_effects(degrade(f, b, n, seed=3))
            entry["added"].append({"blur_px": b, "noise_levels": n, "blur_est_px": e.blur_sigma_px,
                                   "noise_est_levels": 255 * e.noise_sigma,
                                   "blur_expected_px": float(np.hypot(e0.blur_sigma_px, b)),
                                   "noise_expected_levels": float(np.hypot(255 * e0.noise_sigma, n))})
        doc["photos"].append(entry)
        print(f"photo {name}: blur {e0.blur_sigma_px:.2f} px, noise {255 * e0.noise_sigma:.2f} levels; "
              + ", ".join(f"+b{a['blur_px']}/n{a['noise_levels']} -> {a['blur_est_px']:.2f} ({a['blur_expected_px']:.2f}) "
                          f"/ {a['noise_est_levels']:.2f} ({a['noise_expected_levels']:.2f})" for a in entry["added"]))

    # 3. insertion into a degraded photo, matching off / on
    light = sunny_light()
    K = NUSCENES_K
    for name, img in photos()[::3]:
        H, W = img.shape[:2]
        degraded = degrade(img.astype(np.float32) / 255.0, 1.5, 4.0, seed=5)
        target = estimate_camera_effects(degraded)
        depth = ground_plane_depth(K, W, H, np.array([0.0, -1.0, 0.0]), 1.5)
        car = procedural_car(3)
        T = pose_camera_to_transform(0.5, 1.5, 12.0, 35.0)
        entry = {"image": name, "image_blur_px": target.blur_sigma_px, "image_noise_levels": 255 * target.noise_sigma}
        for on in (False, True):
            s = dataclasses.replace(QUALITY_PRESETS["default"], match_camera=on)
            c0 = time.process_time()  # CPU time: the machine may be shared
            res = render_insertion(degraded, K, depth, light, car, T, quality=s, seed=0)
            dt = time.process_time() - c0
            inner = cv2.erode((res.coverage > 0.99).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
            rim = (cv2.dilate((res.coverage > 0.5).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0) & ~(
                cv2.erode((res.coverage > 0.5).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0)
            noise = 255 * estimate_noise_sigma(res.image, inner)
            blur, n_edges = estimate_blur_sigma(res.image, target.noise_sigma, rim)
            entry["on" if on else "off"] = {"object_noise_levels": noise, "silhouette_blur_px": blur,
                                            "silhouette_edge_pixels": n_edges, "cpu_s": dt}
        doc["insertion"].append(entry)
        print(f"insert into {name} (blur {entry['image_blur_px']:.2f} px, noise {entry['image_noise_levels']:.2f}): "
              f"off: object noise {entry['off']['object_noise_levels']:.2f}, silhouette blur {entry['off']['silhouette_blur_px']:.2f}; "
              f"on: {entry['on']['object_noise_levels']:.2f}, {entry['on']['silhouette_blur_px']:.2f} "
              f"(+{1000 * (entry['on']['cpu_s'] - entry['off']['cpu_s']):.0f} ms CPU)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2, default=float) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
