"""``predict-light`` time per level (L1, L2, L3), one thread, in-process, on two real keyframes (issue #16).

Usage: ``python benchmarks/bench_lighting_levels_time.py [--runs 5] [--rounds 2] [--old /tmp/old_shim]``

Scenes: the one-north keyframe (``nuscenes-real``) and scene-0916 keyframe 8 (``nuscenes-seq``), CAM_FRONT
alone (1600 x 900), the sample's LiDAR and boxes. The work timed is ``estimate_views_lighting([CAM_FRONT],
location, level, lidar=..., boxes=...)`` with the image decoded first (what ``predict-light`` runs per
estimate); one warm-up estimate per scene and level, then ``--runs`` timed ones. Wall and CPU seconds and the
estimate's own stage timings (``timing_s``); medians per revision over ``--rounds`` x ``--runs``.

``--old DIR``: also runs the code importable from DIR (a directory holding a ``streetaug`` package of an older
revision, e.g. symlinks into a ``git worktree``), each round in a fresh subprocess per revision, in the order
new-old, old-new, ... (both see the same machine load); the ratio new / old is reported per scene and level.
The first round also scores each estimate's rendered CAM_FRONT (self view) and CAM_BACK (PSNR, si-PSNR; with
``--old`` new minus old). Writes ``results/lighting_levels_time.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
SCENES = {  # name: (dataset dir, sample token or None, keyframe index in scene or None, scene)
    "one-north": (SHARED / "nuscenes-real", "ca9a282c9e77460f8360f564131a8af5", None, None),
    "scene-0916_k8": (SHARED / "nuscenes-seq", None, 8, "scene-0916"),
}
LEVELS = ("L1", "L2", "L3")
CAMERA = "CAM_FRONT"
QUALITY_CAMERAS = ("CAM_FRONT", "CAM_BACK")  # the self view and a view through the volume (first round only)


def measure(runs: int, quality: bool) -> dict:
    """{scene: {level: {"wall": [s], "cpu": [s], "stages": {stage: [s]}}}, "module": path} of this process;
    with ``quality`` also {"quality": {scene: {level: {camera: {"psnr", "si_psnr"}}}}} (rendered views)."""
    import torch

    import streetaug.augment.lighting.build as build_module
    from streetaug.augment.evaluation.novel_view import score_lighting
    from streetaug.augment.lighting.api import estimate_views_lighting
    from streetaug.datasets.nuscenes import NuScenesReader

    torch.set_num_threads(1)
    out: dict = {"module": build_module.__file__, "quality": {}}
    for name, (root, token, keyframe, scene) in SCENES.items():
        reader = NuScenesReader(root, "v1.0-mini")
        sample = reader.sample(token if token is not None else reader.sample_tokens(scene)[keyframe])
        view = sample.cameras[CAMERA]
        _ = np.asarray(view.image), sample.lidar, sample.boxes  # decoded / loaded first
        per_level = {}
        for level in LEVELS:
            def run():
                return estimate_views_lighting([view], sample.location, level, lidar=sample.lidar, boxes=sample.boxes)

            run()  # warm-up (imports, caches of the first call)
            wall, cpu, stages = [], [], {}
            for _ in range(runs):
                t0, c0 = time.perf_counter(), time.process_time()
                est = run()
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
                for k, v in est.timing_s.items():
                    stages.setdefault(k, []).append(float(v))
            per_level[level] = {"wall": wall, "cpu": cpu, "stages": stages}
            if quality:
                out["quality"].setdefault(name, {})[level] = {
                    cam: score_lighting(est, sample.cameras[cam]) for cam in QUALITY_CAMERAS}
        out[name] = per_level
    return out


def summary(rounds: list[dict]) -> dict:
    """Medians over all rounds and runs: {scene: {level: {wall_s, cpu_s, n, stages_s}}}."""
    res = {}
    for scene in SCENES:
        res[scene] = {}
        for level in LEVELS:
            rs = [r[scene][level] for r in rounds]
            stages = sorted({k for r in rs for k in r["stages"]})
            res[scene][level] = {
                "wall_s_median": float(np.median([x for r in rs for x in r["wall"]])),
                "cpu_s_median": float(np.median([x for r in rs for x in r["cpu"]])),
                "n": sum(len(r["wall"]) for r in rs),
                "stages_s_median": {k: float(np.median([x for r in rs for x in r["stages"].get(k, [])]))
                                    for k in stages},
            }
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--label", default="new")
    ap.add_argument("--old", type=Path, default=None, help="directory whose streetaug package is the old code")
    ap.add_argument("--old-label", default="old")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--quality", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "lighting_levels_time.json")
    args = ap.parse_args()
    if args.child:
        print(json.dumps(measure(args.runs, args.quality)))
        return
    for root, *_ in SCENES.values():
        if not root.exists():
            raise SystemExit(f"{root} not found")
    labels = [args.label] + ([args.old_label] if args.old is not None else [])
    runs: dict[str, list] = {label: [] for label in labels}
    modules: dict[str, str] = {}
    quality: dict[str, dict] = {}
    for i in range(args.rounds):
        for label in labels if i % 2 == 0 else labels[::-1]:
            env = dict(os.environ)
            if label != args.label:
                env["PYTHONPATH"] = str(args.old)
            cmd = [sys.executable, __file__, "--child", "--runs", str(args.runs)] + (["--quality"] if i == 0 else [])
            res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
            r = json.loads(res.stdout.strip().splitlines()[-1])
            modules[label] = r.pop("module")
            q = r.pop("quality")
            if q:
                quality[label] = q
            runs[label].append(r)
            print(f"round {i + 1}/{args.rounds} {label} done", file=sys.stderr, flush=True)
    summ = {label: summary(r) for label, r in runs.items()}
    result = {"threads": 1, "camera": CAMERA, "runs": args.runs, "rounds": args.rounds,
              "load_average_1_5_15": list(os.getloadavg()), "modules": modules, "summary": summ,
              "quality": quality}
    if args.old is not None:
        result["ratio_new_over_old"] = {
            scene: {level: {k: summ[args.label][scene][level][k] / summ[args.old_label][scene][level][k]
                            for k in ("wall_s_median", "cpu_s_median")} for level in LEVELS} for scene in SCENES}
    for label in labels:
        for scene in SCENES:
            line = ", ".join(f"{lv} {summ[label][scene][lv]['wall_s_median']:.3f} s (cpu "
                             f"{summ[label][scene][lv]['cpu_s_median']:.3f})" for lv in LEVELS)
            print(f"{label:>4s} {scene:14s} {line}")
    if args.old is not None:
        for scene in SCENES:
            line = ", ".join(f"{lv} x{result['ratio_new_over_old'][scene][lv]['wall_s_median']:.2f}" for lv in LEVELS)
            print(f"new/old {scene:14s} wall {line}")
    for label in quality:
        for scene, by_level in quality[label].items():
            line = ", ".join(f"{lv} {cam} {v['psnr']:.3f} dB" for lv, cams in by_level.items() for cam, v in cams.items())
            print(f"{label:>4s} {scene:14s} PSNR {line}")
    if args.old is not None and args.old_label in quality and args.label in quality:
        result["psnr_new_minus_old_db"] = {
            scene: {lv: {cam: quality[args.label][scene][lv][cam]["psnr"] - v["psnr"] for cam, v in cams.items()}
                    for lv, cams in by_level.items()} for scene, by_level in quality[args.old_label].items()}
        print("PSNR new - old (dB):", json.dumps(result["psnr_new_minus_old_db"]))
    result["raw"] = runs
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
