"""The speed/accuracy sweep behind ``streetaug bench``: lighting levels x render presets on scenes whose
true lighting is known (the bundled sample scenes).

For each scene and placement (placed once, the same for every configuration):

* the **reference** composite: the car rendered at the ``high`` preset under the *true local light* at
  its centre (:class:`~streetaug.augment.scenegen.ground_truth.GroundTruthScene`: the generated street
  re-traced from that point: sky, sun with its true visibility, buildings and their shadows);
* each **configuration** (level, preset): lighting estimated at that level from the image (+ LiDAR and
  boxes), the light at the car's centre (``light_at``), rendered at that preset;
* **error**: RMSE (8-bit levels), PSNR and SSIM of the composite against the reference over the
  affected region (pixels either composite changed, grown by 4 px); the estimate's sun direction error
  and the log-encoded error of its local env map at the car vs the true one;
* **time**: lighting estimate + render, seconds in this process (scene depth is the same for all and
  excluded; files excluded).

The Pareto front is taken over (median time, mean RMSE) per configuration; ``auto`` should sit on it
or next to it.  The renderer's own error against an independent path tracer (Mitsuba) is measured by
``benchmarks/bench_render_reference.py``; :func:`renderer_reference_rows` reads its cached results.
"""

from __future__ import annotations

import csv
import io
import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from streetaug.datasets.bundled import BUNDLED_VERSION
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import CameraView, Sample

from ..assets.asset import Asset
from ..assets.select import select_assets
from ..core import InputError, atomic_path, rotate_vectors, transform_points, write_bytes_atomic, write_json_atomic
from ..lighting.api import estimate_lighting
from ..pipeline import InsertOptions, item_seed, place_in_view, scene_depth_for_view
from ..lighting.light import DistantLight
from ..render import Insertion, render_insertion
from ..scenegen.ground_truth import GroundTruthScene
from .metrics import env_log_error, psnr_db

LEVELS = ("L0", "L1", "L2", "L3", "auto")
PRESETS = ("draft", "default", "high")
SCHEMA = "streetaug.speed_accuracy/1"
# Where benchmarks/bench_render_reference.py caches the renderer's comparison with Mitsuba.
REFERENCE_RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results"


@dataclass(frozen=True)
class Case:
    """One scene + placement of the sweep.

    Attributes:
        T_cam_from_object: (4, 4) the placed car; ground_normal_cam: (3,) the ground's up (camera frame).
        depth_m: (H, W) the scene depth; center_cam: (3,) the car's centre (camera frame, metres).
        reference: the car rendered at the ``high`` preset under ``true_light``, the true local light at its
            centre (camera frame).
    """

    scene: str
    seed: int
    sample: Sample
    view: CameraView
    asset: Asset
    T_cam_from_object: np.ndarray
    ground_normal_cam: np.ndarray
    depth_m: np.ndarray
    reference: Insertion
    true_light: DistantLight
    center_cam: np.ndarray


def ssim(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    """Mean SSIM (Wang et al. 2004; Gaussian window sigma 1.5, 8-bit constants) of two uint8 RGB images
    over a boolean mask (luminance channel)."""
    x = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY).astype(np.float64)
    y = cv2.cvtColor(b, cv2.COLOR_RGB2GRAY).astype(np.float64)
    blur = lambda im: cv2.GaussianBlur(im, (11, 11), 1.5)  # noqa: E731
    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx**2, blur(y * y) - my**2, blur(x * y) - mx * my
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx**2 + my**2 + c1) * (vx + vy + c2))
    return float(s[where].mean()) if where.any() else float("nan")


def composite_errors(image: np.ndarray, reference: np.ndarray, where: np.ndarray) -> dict:
    """RMSE (8-bit levels), PSNR (dB) and SSIM of ``image`` vs ``reference`` over ``where``."""
    psnr = psnr_db(image, reference, where)
    rmse = float(255.0 * 10 ** (-psnr / 20))  # nan for an empty region, 0 for identical images
    return {"rmse": rmse, "psnr_db": psnr, "ssim": ssim(image, reference, where)}


def affected_region(source: np.ndarray, *composites: np.ndarray, grow_px: int = 4) -> np.ndarray:
    """Pixels any composite changed (by more than 1 level), grown by ``grow_px``."""
    changed = np.zeros(source.shape[:2], bool)
    for c in composites:
        changed |= np.abs(c.astype(np.int16) - source.astype(np.int16)).max(axis=2) > 1
    k = 2 * grow_px + 1
    return cv2.dilate(changed.astype(np.uint8), np.ones((k, k), np.uint8)) > 0


def make_cases(dataroot, scenes: Sequence[str], seeds: Sequence[int], camera: str = "CAM_FRONT",
               class_rules: str | None = None) -> list[Case]:
    """Place one procedural car per (scene, seed) and render its reference (high preset, true local light).

    ``class_rules``: a placement rules file (``--class-rules``), None for the built-in rules."""
    reader = NuScenesReader(dataroot, BUNDLED_VERSION)
    cases = []
    for scene in scenes:
        truth = GroundTruthScene(dataroot, scene)
        sample = reader.sample(reader.sample_tokens(scene)[0])
        view = sample.cameras[camera]
        depth_m = scene_depth_for_view(sample, view)
        # Warm-up outside the timings: first-use imports (torch for the volume levels) and the JPEG decode.
        estimate_lighting(view, sample.location, "L2", lidar=sample.lidar, boxes=sample.boxes)
        for seed in seeds:
            (asset,) = select_assets(item_seed(seed, "asset", sample.token, camera), 1, location=sample.location)
            placed = place_in_view(sample, view, [asset], [], InsertOptions(seed=seed, class_rules=class_rules))
            if not placed.placements:
                continue
            p = placed.placements[0]
            T = view.T_cam_from_global @ p.T_global_from_object
            normal = rotate_vectors(view.T_cam_from_global, p.ground_normal_global[None])[0]
            center_cam = T[:3, 3] + 0.5 * asset.wlh[2] * T[:3, 2]
            center_global = transform_points(view.T_global_from_cam, center_cam[None])[0]
            true_light = truth.local_light(center_global, view.T_cam_from_global, 128, 256, sky_rays=16)
            reference = render_insertion(view.image, view.K, depth_m, true_light, asset, T, normal, "high", seed=seed)
            cases.append(Case(scene, seed, sample, view, asset, T, normal, depth_m, reference, true_light, center_cam))
    return cases


def run_configuration(case: Case, level: str, preset: str) -> dict:
    """Estimate at ``level``, render at ``preset``; errors against the case's reference."""
    t0 = time.perf_counter()
    est = estimate_lighting(case.view, case.sample.location, level, lidar=case.sample.lidar, boxes=case.sample.boxes,
                            query_point_cam=case.center_cam)
    light = est.light_at(case.center_cam)
    t_light = time.perf_counter() - t0
    ins = render_insertion(case.view.image, case.view.K, case.depth_m, light, case.asset, case.T_cam_from_object,
                           case.ground_normal_cam, preset, seed=case.seed)
    t_render = ins.timing_s["total"]
    where = affected_region(case.view.image, ins.image, case.reference.image)
    row = {"scene": case.scene, "seed": case.seed, "level": level, "chosen_level": est.level, "preset": preset,
           "seconds": t_light + t_render, "lighting_s": t_light, "render_s": t_render,
           "affected_px": int(where.sum())}
    row.update(composite_errors(ins.image, case.reference.image, where))
    true_sun = case.true_light.sun
    if est.sun_dir_cam is not None and true_sun is not None:
        c = float(np.clip(np.dot(est.sun_dir_cam, true_sun.direction), -1, 1))
        row["sun_error_deg"] = float(np.degrees(np.arccos(c)))
    else:
        row["sun_error_deg"] = None
    row["env_log_error"] = env_log_error(light.to_envmap(32, 64), case.true_light.to_envmap(32, 64))
    return row


def summarise(rows: list[dict]) -> list[dict]:
    """One line per configuration: median seconds, mean RMSE / PSNR / SSIM / env error, Pareto flag."""
    configs: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        configs.setdefault((r["level"], r["preset"]), []).append(r)
    table = []
    for (level, preset), rs in configs.items():
        chosen = sorted({r["chosen_level"] for r in rs})
        table.append({
            "config": f"{level}/{preset}", "level": level, "preset": preset, "n": len(rs),
            "median_s": float(np.median([r["seconds"] for r in rs])),
            "rmse": float(np.mean([r["rmse"] for r in rs])),
            "psnr_db": float(np.mean([min(r["psnr_db"], 99.0) for r in rs])),
            "ssim": float(np.mean([r["ssim"] for r in rs])),
            "env_log_error": float(np.mean([r["env_log_error"] for r in rs])),
            "chosen_levels": chosen,
        })
    for t in table:
        t["pareto"] = not any(o["median_s"] <= t["median_s"] and o["rmse"] <= t["rmse"]
                              and (o["median_s"] < t["median_s"] or o["rmse"] < t["rmse"]) for o in table)
    front = sorted((t for t in table if t["pareto"]), key=lambda t: t["median_s"])
    for t in table:  # how far from the front: extra RMSE over the front's best at no more time (x 1.1 slack)
        reachable = [f["rmse"] for f in front if f["median_s"] <= 1.1 * t["median_s"]]
        t["rmse_above_front"] = float(t["rmse"] - min(reachable)) if reachable else 0.0
    return sorted(table, key=lambda t: t["median_s"])


def renderer_reference_rows(results_dir: str | Path) -> list[dict]:
    """The cached Mitsuba comparison of the renderer presets (``render_reference.json``), if present."""
    path = Path(results_dir) / "render_reference.json"
    if not path.is_file():
        return []
    doc = json.loads(path.read_text())
    return doc.get("summary", doc.get("presets", [])) if isinstance(doc, dict) else []


def plot_chart(table: list[dict], path: str | Path, title: str) -> None:
    """speed_accuracy.png: time (log x) vs RMSE, each configuration labelled, Pareto front drawn, auto highlighted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    colours = {"draft": "tab:blue", "default": "tab:orange", "high": "tab:green"}
    for t in table:
        auto = t["level"] == "auto"
        ax.scatter(t["median_s"], t["rmse"], s=90 if auto else 36, marker="*" if auto else "o",
                   color="crimson" if auto else colours.get(t["preset"], "grey"), zorder=3,
                   edgecolors="black" if t["pareto"] else "none")
        ax.annotate(t["config"], (t["median_s"], t["rmse"]), textcoords="offset points", xytext=(4, 4), fontsize=7)
    front = sorted((t for t in table if t["pareto"]), key=lambda t: t["median_s"])
    ax.step([t["median_s"] for t in front], [t["rmse"] for t in front], where="post", color="black", lw=1,
            label="Pareto front")
    ax.set_xscale("log")
    ax.set_xlabel("seconds per insertion (lighting + render, one core; median)")
    ax.set_ylabel("composite RMSE vs reference (8-bit levels, affected region)")
    ax.set_title(title, fontsize=9)
    handles = [plt.Line2D([], [], marker="o", ls="", color=c, label=p) for p, c in colours.items()]
    handles += [plt.Line2D([], [], marker="*", ls="", color="crimson", markersize=10, label="auto level"),
                plt.Line2D([], [], color="black", label="Pareto front")]
    ax.legend(handles=handles, fontsize=7, loc="upper right")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def markdown_table(table: list[dict]) -> str:
    lines = ["| configuration | median s | RMSE | PSNR dB | SSIM | env log err | Pareto | above front | auto chose |",
             "|---|---|---|---|---|---|---|---|---|"]
    for t in table:
        lines.append(f"| {t['config']} | {t['median_s']:.3f} | {t['rmse']:.2f} | {t['psnr_db']:.2f} | "
                     f"{t['ssim']:.4f} | {t['env_log_error']:.3f} | {'yes' if t['pareto'] else ''} | "
                     f"{t['rmse_above_front']:.2f} | {', '.join(t['chosen_levels']) if t['level'] == 'auto' else ''} |")
    return "\n".join(lines) + "\n"


def run_bench(dataroot: str | Path, scenes: Sequence[str], seeds: Sequence[int], levels: Sequence[str],
              presets: Sequence[str], out_dir: str | Path, on_step: Callable[[], None] = lambda: None,
              reference_results: str | Path = REFERENCE_RESULTS, class_rules: str | None = None) -> list[dict]:
    """The sweep of ``streetaug bench``: every case x level x preset; writes ``speed_accuracy.png``, ``.csv``
    (one row per case and configuration), ``.md`` (the table) and ``.json`` into ``out_dir``.

    ``on_step`` is called after each configuration (a progress bar); ``class_rules``: the placement rules file
    (None: built-in). Returns the table (one line per
    configuration, :func:`summarise`).

    Raises:
        InputError: no placement found in any scene / seed.
    """
    cases = make_cases(dataroot, scenes, seeds, class_rules=class_rules)
    if not cases:
        raise InputError("no placement found in any scene/seed: nothing to measure")
    rows = []
    for case in cases:
        for level in levels:
            for preset in presets:
                rows.append(run_configuration(case, level, preset))
                on_step()
    table = summarise(rows)
    out_dir = Path(out_dir)
    title = (f"{len(cases)} insertions ({', '.join(scenes)}); load {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
             f"cores\nreference: high preset under the true local light of the generated street")
    plot_chart(table, out_dir / "speed_accuracy.png", title)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    write_bytes_atomic(out_dir / "speed_accuracy.csv", buf.getvalue().encode())
    write_bytes_atomic(out_dir / "speed_accuracy.md", markdown_table(table).encode())
    write_json_atomic(out_dir / "speed_accuracy.json", {
        "schema": SCHEMA, "machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(),
                                      "load_avg": os.getloadavg()},
        "cases": [{"scene": c.scene, "seed": c.seed} for c in cases], "table": table, "rows": rows,
        "renderer_vs_mitsuba": renderer_reference_rows(reference_results),
    })
    return table
