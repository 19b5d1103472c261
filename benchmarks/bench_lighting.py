"""Lighting benchmark: accuracy of each level against ground truth, novel-view radiance on real data, speed.

Usage: ``python benchmarks/bench_lighting.py [--runs 3] [--quick] [--out benchmarks/results]``

1. **Bundled sample scenes** (ground truth known): the street is regenerated in-process by
   ``augment.scenegen`` with the scene's own parameters; the true local environment map at a point is traced
   with its renderer (rays from the point: sky model where they escape, the shaded street where they hit,
   shading = pattern albedo x (sun with shadow rays + sky gathered over 8 cosine rays)), on the images'
   radiometric scale (x exposure k). Points: 0.5 m above the road 8-40 m ahead of CAM_FRONT, three in the
   sun and three in a building's shadow (by the true sun visibility). Per level (built from CAM_FRONT +
   LiDAR, as batch does with one camera): sun direction error (ephemeris path), sun/sky ratio error of the
   distant light, and per point the diffuse irradiance error over 6 normals (sun included), the sun
   transmittance error and the log-encoded env-map error ``mean_w (log(1 + x^) - log(1 + x))^2`` (sun excluded).
   The same errors with the lighting built from all three cameras (``all_cameras``: what batch builds).
2. **Real sample** (``../shared/data/nuscenes-real``): novel-view radiance PSNR / si-PSNR as in the paper:
   the lighting is built from some cameras, the target camera's image is rendered through
   ``envmap_at(target camera centre)`` (256 x 512 map, bilinear) with the contract's camera response at EV 0
   and compared with its real image at 320 x 180 (si-PSNR: the prediction scaled by the least-squares factor).
   Monocular: CAM_FRONT -> CAM_FRONT_LEFT, CAM_BACK; leave-one-out: each camera from the other two.
   The same on the bundled scenes. Also reported: PSNR with the target camera's auto-exposure modelled
   (``exposure.auto_exposure_ev``: metered to the sources' mean LDR level; nuScenes cameras each expose on
   their own, and nothing of the target image is used), and two oracles that use the target image (its
   mean colour; its mean colour per row): ceilings for predictions that carry no structure of a view the
   sources never saw.
   **Paper protocol** (section ``forward``): the paper's novel view is the front camera 1.5 s later, which
   mostly sees what the input saw. No later frame exists for the real sample, so this runs on the bundled
   scenes, whose truth the scene renderer traces: CAM_FRONT moved ``FORWARD_M`` along the street, lighting
   from CAM_FRONT (monocular) or all three cameras (multi-view).
   **Street prior ablation** (section ``street_prior``): the same L3 monocular / leave-one-out scores with the
   street prior of :mod:`augment.lighting.fill` on and off (``build.STREET_PRIOR_WEIGHT`` = inf: the shading
   model alone colours unobserved surfaces), on the bundled scenes and the real sample.
3. **Speed** (one core, BLAS and torch threads 1): ``predict-light`` work for a 1600 x 900 image = estimate
   + local env map at the query point (files excluded), per level, image-only path (what the CLI runs) and
   with the sample's LiDAR; median of ``--runs``; plus a grid-resolution sweep for L3.

Writes ``lighting_bench.json`` and ``lighting_envmaps.png`` (GT vs each level at a shadowed and a lit point).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from streetaug.augment.core import (  # noqa: E402
    equirect_solid_angles,
    hdr_to_ldr,
    hdr_to_ldr_uint8,
    invert_transform,
    luminance,
    pixel_rays,
    transform_points,
)
from streetaug.augment.lighting.api import estimate_lighting, estimate_sample_lighting, estimate_views_lighting  # noqa: E402

try:  # the instant front door (absent in older revisions this script is compared with)
    from streetaug.augment.lighting.api import estimate_instant_lighting  # noqa: E402
except ImportError:  # pragma: no cover
    estimate_instant_lighting = None
from streetaug.augment.lighting.exposure import auto_exposure_ev  # noqa: E402
from streetaug.augment.lighting.levels import L3_GRID  # noqa: E402
from streetaug.augment.lighting.light import DistantLight  # noqa: E402
from streetaug.augment.lighting.volume import sample_world_equirect  # noqa: E402
from streetaug.augment.evaluation.metrics import env_log_error  # noqa: E402
from streetaug.augment.evaluation.novel_view import psnr, si_psnr  # noqa: E402
from streetaug.augment.lighting.predicted_view import view_rays  # noqa: E402
from streetaug.augment.scenegen.ground_truth import GroundTruthScene, ground_truth_light, read_ground_truth  # noqa: E402
from streetaug.augment.scenegen.make import SAMPLE_SCENES  # noqa: E402
from streetaug.datasets.bundled import bundled_dataroot  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
LEVELS = ("L0", "L1", "L2", "L3")
ENV_H, ENV_W = 64, 128
NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
NOVEL_W = 320
ALL_SECTIONS = ("speed", "bundled", "real", "forward", "street_prior", "grid")


# ----------------------------------------------------------------------------- ground truth of the bundled scenes


# ----------------------------------------------------------------------------- metrics


def irradiance(light: DistantLight, normals: np.ndarray) -> np.ndarray:
    """(len(normals), 3) irradiance of a distant light on surfaces with camera-frame unit normals."""
    from streetaug.augment.core import camera_envmap_directions

    H, W = light.envmap.shape[:2]
    d = camera_envmap_directions(H, W).reshape(-1, 3)
    w = equirect_solid_angles(H, W).reshape(-1)
    cos = np.maximum(normals @ d.T, 0.0) * w[None]
    e = cos @ light.envmap.reshape(-1, 3).astype(np.float64)
    if light.sun is not None:
        e = e + np.maximum(normals @ light.sun.direction, 0.0)[:, None] * np.asarray(light.sun.irradiance_rgb)[None]
    return e


def irradiance_error(light: DistantLight, truth: DistantLight) -> float:
    """Mean relative error of the luminance irradiance over the six axis normals (``NORMALS``), sun included."""
    e_est, e_gt = luminance(irradiance(light, NORMALS)), luminance(irradiance(truth, NORMALS))
    return float(np.mean(np.abs(e_est - e_gt) / np.maximum(e_gt, 1e-9)))


def sun_sky_ratio(light: DistantLight, up_cam: np.ndarray) -> float:
    """Horizontal irradiance of the sun over that of the sky (luminance); 0 without a sun."""
    e = irradiance(DistantLight(light.envmap, None), up_cam[None])[0]
    sun = 0.0 if light.sun is None else float(luminance(light.sun.irradiance_rgb)) * max(float(light.sun.direction @ up_cam), 0.0)
    return sun / max(float(luminance(e)), 1e-12)


def sources_mean_ldr(sample, sources: list[str]) -> float:
    """Mean LDR level (0-1) of the source cameras' images: what an unseen camera's auto-exposure meters to."""
    return float(np.mean([np.asarray(sample.cameras[c].image).mean() / 255.0 for c in sources]))


def render_novel_view(sl, view, ref_view, width: int = NOVEL_W) -> np.ndarray:
    """Linear radiance (h, w, 3) the lighting predicts for a camera, through envmap_at(camera centre).

    ``ref_view`` is the lighting's reference camera (L0/L1: its distant light is turned into the target's frame;
    nothing is fitted to the target image).
    """
    rays, h = view_rays(view, width)
    if sl.hybrid is None:
        # L0/L1: the reference camera's distant light turned into the target's frame (never fitted to the target)
        ref = sl.per_view[sl.reference]
        light = ref.light_cam.rotated(view.T_cam_from_global[:3, :3] @ ref_view.T_global_from_cam[:3, :3])
        return light.radiance(np.zeros_like(rays), rays).reshape(h, width, 3)
    T = invert_transform(sl.T_global_from_vol) @ view.T_global_from_cam
    env = sl.hybrid.envmap_at(sl.hybrid.lift_out_of_solid(T[:3, 3]), 256, 512)
    with torch.no_grad():
        rad = sample_world_equirect(torch.from_numpy(env), torch.from_numpy(rays @ T[:3, :3].T).float()).numpy()
    return rad.reshape(h, width, 3)


def novel_view_scores(sample, sources: list[str], target: str, level: str, grid=None) -> dict:
    sl = estimate_views_lighting([sample.cameras[c] for c in sources], sample.location, level, lidar=sample.lidar,
                                 boxes=sample.boxes, grid=grid)
    view = sample.cameras[target]
    rad = render_novel_view(sl, view, sample.cameras[sources[0]])
    h, w = rad.shape[:2]
    gt = cv2.resize(np.asarray(view.image), (w, h), interpolation=cv2.INTER_AREA) / 255.0
    return {"sources": sources, "target": target, "level": sl.level} | scores(rad, gt, sources_mean_ldr(sample, sources))


def scores(rad: np.ndarray, gt: np.ndarray, source_mean_ldr: float) -> dict:
    """PSNR of a predicted view (linear radiance) against the real one (LDR in [0, 1]): at the lighting's own
    exposure (EV 0), with the target camera's auto-exposure modelled (metered to the sources' mean level, see
    ``exposure.auto_exposure_ev``; uses nothing of the target image), and scale-invariant (the paper's si-PSNR)."""
    pred = hdr_to_ldr(rad)
    pred_ae = hdr_to_ldr(rad, auto_exposure_ev(rad, source_mean_ldr))
    return {"psnr": psnr(pred, gt), "psnr_auto_exposure": psnr(pred_ae, gt), "si_psnr": si_psnr(pred, gt),
            "pred": pred, "gt": gt}


def oracle_scores(gt: np.ndarray) -> dict:
    """PSNR of predictions that know the target image (not methods: how much of a view's own layout a score
    needs): its mean colour, its mean colour per image row (per elevation, for a level camera), and its mean
    colour in each cell of a 4 x 4 and an 8 x 8 grid."""
    h, w = gt.shape[:2]

    def cells(n: int) -> np.ndarray:
        return cv2.resize(cv2.resize(gt, (n, n), interpolation=cv2.INTER_AREA), (w, h), interpolation=cv2.INTER_NEAREST)

    return {"target_mean_colour": psnr(np.broadcast_to(gt.mean((0, 1)), gt.shape), gt),
            "target_row_means": psnr(np.broadcast_to(gt.mean(1, keepdims=True), gt.shape), gt),
            "target_4x4_means": psnr(cells(4), gt), "target_8x8_means": psnr(cells(8), gt)}


def mean_scores(rows: list[dict]) -> dict:
    return {"psnr_mean": float(np.mean([r["psnr"] for r in rows])),
            "psnr_auto_exposure_mean": float(np.mean([r["psnr_auto_exposure"] for r in rows])),
            "si_psnr_mean": float(np.mean([r["si_psnr"] for r in rows])),
            "per_target": [{k: r[k] for k in ("sources", "target", "psnr", "psnr_auto_exposure", "si_psnr") if k in r}
                           for r in rows]}


NOVEL_SETUPS = {
    "monocular": [(["CAM_FRONT"], "CAM_FRONT_LEFT"), (["CAM_FRONT"], "CAM_BACK")],
    "leave_one_out": [(["CAM_FRONT_LEFT", "CAM_BACK"], "CAM_FRONT"), (["CAM_FRONT", "CAM_BACK"], "CAM_FRONT_LEFT"),
                      (["CAM_FRONT", "CAM_FRONT_LEFT"], "CAM_BACK")],
    # not a novel view: each camera re-rendered from the lighting built from itself (what the representation
    # keeps of what it saw; the paper's novel view, 1.5 s later, mostly shows content of the input view)
    "in_view": [(["CAM_FRONT"], "CAM_FRONT"), (["CAM_FRONT_LEFT"], "CAM_FRONT_LEFT"), (["CAM_BACK"], "CAM_BACK")],
}


def novel_view_table(sample, levels=("L1", "L3"), grid=None) -> tuple[dict, list]:
    out, images = {}, []
    for setup, pairs in NOVEL_SETUPS.items():
        for level in levels:
            rows = [novel_view_scores(sample, src, tgt, level, grid) for src, tgt in pairs]
            out[f"{setup}/{level}"] = mean_scores(rows)
            if level == levels[-1]:
                images += [np.concatenate([r["gt"], r["pred"]], axis=1) for r in rows]
                oracle = [oracle_scores(r["gt"]) for r in rows]
                out[f"{setup}/oracle"] = {k: float(np.mean([o[k] for o in oracle])) for k in oracle[0]} | {
                    "per_target": [{"target": r["target"]} | o for r, o in zip(rows, oracle)]}
    return out, images


FORWARD_M = 10.0  # the paper's novel view: the front camera 1.5 s later (~7 m/s in town)


def forward_view(view, forward_m: float):
    """The same camera with its ego moved ``forward_m`` along the ego's +x (a later frame of a straight drive)."""
    step = np.eye(4)
    step[0, 3] = forward_m
    return replace(view, T_global_from_ego=view.T_global_from_ego @ step)


def true_view(gts: GroundTruthScene, view, width: int = NOVEL_W) -> np.ndarray:
    """True radiance (h, w, 3) a bundled scene's camera sees (its renderer's shading, no camera effects)."""
    rays, h = view_rays(view, width)
    rays_global = rays / np.linalg.norm(rays, axis=1, keepdims=True) @ view.T_global_from_cam[:3, :3].T
    origins = np.tile(view.T_global_from_cam[:3, 3], (len(rays), 1))
    return gts.radiance(origins, rays_global).reshape(h, width, 3)


def forward_section(levels=("L0", "L1", "L2", "L3", "auto")) -> dict:
    """The paper's protocol on the bundled scenes (ground truth known): lighting from CAM_FRONT (monocular) or
    all cameras of the sample (multi-view); target: CAM_FRONT ``FORWARD_M`` further along the street, its true
    image traced by the scene's renderer and compared with ``envmap_at(new camera centre)`` at EV 0 (the
    bundled cameras share one exposure)."""
    dataroot = bundled_dataroot()
    reader = NuScenesReader(dataroot, "v1.0-samples")
    out: dict = {"forward_m": FORWARD_M}
    for name in sorted(SAMPLE_SCENES):
        sample = reader.sample(reader.sample_tokens(name)[0])
        gts = GroundTruthScene(dataroot, name)
        front = sample.cameras["CAM_FRONT"]
        target = forward_view(front, FORWARD_M)
        gt = hdr_to_ldr(true_view(gts, target))
        scene: dict = {"oracle": oracle_scores(gt)}
        for setup, sources in (("monocular", ["CAM_FRONT"]), ("multi_view", sorted(sample.cameras))):
            source_mean = sources_mean_ldr(sample, sources)
            for level in levels:
                sl = estimate_views_lighting([sample.cameras[c] for c in sources], sample.location, level,
                                             lidar=sample.lidar, boxes=sample.boxes)
                r = scores(render_novel_view(sl, target, front), gt, source_mean)
                scene[f"{setup}/{level}"] = {"chosen_level": sl.level} | {
                    k: r[k] for k in ("psnr", "psnr_auto_exposure", "si_psnr")}
        out[name] = scene
        print(f"forward {FORWARD_M:.0f} m {name}: " + ", ".join(
            f"{k} {v['psnr']:.2f}/{v['si_psnr']:.2f}" for k, v in scene.items() if k != "oracle"), flush=True)
    scenes = [out[n] for n in sorted(SAMPLE_SCENES)]
    out["mean"] = {key: {m: float(np.mean([sc[key][m] for sc in scenes])) for m in ("psnr", "psnr_auto_exposure", "si_psnr")}
                   for key in scenes[0] if key != "oracle"}
    out["mean"]["oracle"] = {m: float(np.mean([sc["oracle"][m] for sc in scenes])) for m in scenes[0]["oracle"]}
    return out


# ----------------------------------------------------------------------------- sections


def timed(fn, runs: int):
    """(result, median wall seconds, wall seconds per run); CPU seconds per run in ``LAST_CPU``."""
    times, cpu, out = [], [], None
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    LAST_CPU[:] = cpu
    return out, float(np.median(times)), [float(t) for t in times]


LAST_CPU: list = []


def bundled_section(runs: int, quick: bool) -> tuple[dict, list]:
    dataroot = bundled_dataroot()
    reader = NuScenesReader(dataroot, "v1.0-samples")
    results, tiles = {}, []
    for name in sorted(SAMPLE_SCENES):
        sample = reader.sample(reader.sample_tokens(name)[0])
        view = sample.cameras["CAM_FRONT"]
        _ = view.image, sample.lidar
        gts = GroundTruthScene(dataroot, name)
        points, vis_true = gts.test_points(view)
        gt_lights = [gts.local_light(transform_points(view.T_global_from_cam, p[None])[0], view.T_cam_from_global)
                     for p in points]
        gt_distant = ground_truth_light(dataroot, name, "CAM_FRONT", ENV_H, ENV_W)
        up_cam = np.array(read_ground_truth(dataroot, name)["cameras"]["CAM_FRONT"]["up_direction_camera"])
        gt_ratio = sun_sky_ratio(gt_distant, up_cam)
        scene_out = {"points_camera": points.tolist(), "true_sun_visibility": vis_true.tolist(),
                     "true_sun_sky_ratio": gt_ratio, "levels": {}}
        gt_dir = np.array(read_ground_truth(dataroot, name)["cameras"]["CAM_FRONT"]["sun_direction_camera"])
        level_envs = {}
        for level in (*LEVELS, "auto"):
            def run():
                return estimate_sample_lighting(sample, ["CAM_FRONT"], level).for_view(view)
            est, t_med, _ = timed(run, 1 if quick else runs)
            cpu_build = float(np.median(LAST_CPU))
            _, t_query, _ = timed(lambda: est.light_at(points[0]), 1 if quick else runs)
            cpu_query = float(np.median(LAST_CPU))
            lights = [est.light_at(p, ENV_H, ENV_W) for p in points]
            e_err, s_err, env_err = [], [], []
            for lt, gl in zip(lights, gt_lights):
                e_err.append(irradiance_error(lt, gl))
                if gts.sky.sun_visibility >= 0.5:  # transmittance only means something with a visible sun
                    v_est = 0.0 if lt.sun is None or est.light_cam.sun is None else lt.sun.visibility / max(est.light_cam.sun.visibility, 1e-9)
                    v_gt = 0.0 if gl.sun is None else gl.sun.visibility / gts.sky.sun_visibility
                    s_err.append(abs(v_est - v_gt))
                env_err.append(env_log_error(lt.envmap, gl.envmap))
            ang = None
            if est.sun_dir_cam is not None:
                ang = float(np.degrees(np.arccos(np.clip(est.sun_dir_cam @ gt_dir / np.linalg.norm(gt_dir), -1, 1))))
            ratio = sun_sky_ratio(est.light_cam, up_cam)
            scene_out["levels"][level] = {
                "chosen_level": est.level, "reason": est.reason, "time_s_median": t_med, "cpu_s_median": cpu_build,
                "local_envmap_128x256_s_median": t_query, "local_envmap_cpu_s_median": cpu_query,
                "sun_direction_error_deg": ang, "sun_sky_ratio": ratio,
                "sun_sky_ratio_error_rel": abs(ratio - gt_ratio) / gt_ratio if gt_ratio > 0 else None,
                "irradiance_error_rel_mean": float(np.mean(e_err)), "irradiance_error_rel_per_point": e_err,
                "sun_transmittance_error_mean": float(np.mean(s_err)) if s_err else None,
                "env_log_mse_mean": float(np.mean(env_err)),
            }
            level_envs[level] = lights
            print(f"{name} {level:>4} ({est.level}): t {t_med:.2f} s (cpu {cpu_build:.2f}), irradiance err {np.mean(e_err):.3f}, "
                  f"sun vis err {np.mean(s_err) if s_err else float('nan'):.2f}, env log-mse {np.mean(env_err):.4f}",
                  flush=True)
        # tiles: GT and each level at a shadowed and a lit point
        for i in ([int(np.argmin(vis_true)), int(np.argmax(vis_true))]):
            row = [gt_lights[i].to_envmap(ENV_H, ENV_W)] + [level_envs[lv][i].to_envmap(ENV_H, ENV_W) for lv in LEVELS]
            tiles.append(np.concatenate([hdr_to_ldr_uint8(e) for e in row], axis=1))
        # the same points lit by the lighting of all the sample's cameras (what `streetaug batch` builds)
        for level in (*LEVELS[1:], "auto"):
            est = estimate_sample_lighting(sample, sorted(sample.cameras), level).for_view(view)
            e_err, env_err = [], []
            for p, gl in zip(points, gt_lights):
                lt = est.light_at(p, ENV_H, ENV_W)
                e_err.append(irradiance_error(lt, gl))
                env_err.append(env_log_error(lt.envmap, gl.envmap))
            scene_out.setdefault("all_cameras", {})[level] = {
                "chosen_level": est.level, "irradiance_error_rel_mean": float(np.mean(e_err)),
                "env_log_mse_mean": float(np.mean(env_err))}
            print(f"{name} {level:>4} ({est.level}) all cameras: irradiance err {np.mean(e_err):.3f}, "
                  f"env log-mse {np.mean(env_err):.4f}", flush=True)
        novel, _ = novel_view_table(sample, ("L1", "L3"))
        scene_out["novel_view"] = novel
        results[name] = scene_out
    return results, tiles


def real_section(quick: bool) -> tuple[dict, list]:
    if not REAL.exists():
        return {"skipped": f"{REAL} not found"}, []
    sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    levels = ("L0", "L1", "L2", "L3") if not quick else ("L1", "L3")
    table, images = novel_view_table(sample, levels)
    for k, v in table.items():
        if k.endswith("/oracle"):
            print(f"real novel view {k}: target mean colour {v['target_mean_colour']:.2f} dB, "
                  f"row means {v['target_row_means']:.2f} dB, 4x4 means {v['target_4x4_means']:.2f} dB, "
                  f"8x8 means {v['target_8x8_means']:.2f} dB", flush=True)
        else:
            print(f"real novel view {k}: PSNR {v['psnr_mean']:.2f} dB (auto-exposure {v['psnr_auto_exposure_mean']:.2f}), "
                  f"si-PSNR {v['si_psnr_mean']:.2f} dB", flush=True)
    return table, images


def street_prior_section() -> dict:
    """L3 novel-view PSNR / si-PSNR with the street prior on and off, per sample (bundled scenes + real)."""
    from streetaug.augment.lighting import build

    reader = NuScenesReader(bundled_dataroot(), "v1.0-samples")
    samples = [(n, reader.sample(reader.sample_tokens(n)[0])) for n in sorted(SAMPLE_SCENES)]
    if REAL.exists():
        samples.append(("real", NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)))
    weight = build.STREET_PRIOR_WEIGHT
    out: dict = {"prior_weight": weight}
    try:
        for label, w in (("off", float("inf")), ("on", weight)):
            build.STREET_PRIOR_WEIGHT = w
            for name, sample in samples:
                for setup in ("monocular", "leave_one_out"):
                    rows = [novel_view_scores(sample, src, tgt, "L3") for src, tgt in NOVEL_SETUPS[setup]]
                    out.setdefault(name, {}).setdefault(setup, {})[label] = mean_scores(rows)
    finally:
        build.STREET_PRIOR_WEIGHT = weight
    for name, _ in samples:
        print("street prior " + name + ": " + ", ".join(
            f"{setup} L3 {v['off']['psnr_mean']:.2f} -> {v['on']['psnr_mean']:.2f} dB "
            f"(si {v['off']['si_psnr_mean']:.2f} -> {v['on']['si_psnr_mean']:.2f})" for setup, v in out[name].items()),
            flush=True)
    return out


def speed_section(runs: int) -> dict:
    out = {}
    if REAL.exists():
        sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    else:
        reader = NuScenesReader(bundled_dataroot(), "v1.0-samples")
        sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    view = sample.cameras["CAM_FRONT"]
    _ = view.image, sample.lidar
    query = np.array([0.0, 1.5, 15.0])
    for level in (*LEVELS, "auto"):
        def cli_path():
            est = estimate_lighting(view, sample.location, level)
            est.light_at(query).to_envmap(128, 256)
            return est
        def lidar_path():
            est = estimate_lighting(view, sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                    query_point_cam=query)
            est.light_at(query).to_envmap(128, 256)
            return est
        est, t_cli, all_cli = timed(cli_path, runs)
        cpu_cli = float(np.median(LAST_CPU))
        est2, t_lidar, all_lidar = timed(lidar_path, runs)
        cpu_lidar = float(np.median(LAST_CPU))
        out[level] = {"image_only_s_median": t_cli, "with_lidar_s_median": t_lidar, "image_only_runs": all_cli,
                      "with_lidar_runs": all_lidar, "image_only_cpu_s_median": cpu_cli,
                      "with_lidar_cpu_s_median": cpu_lidar, "chosen": [est.level, est2.level]}
        print(f"speed {level}: image-only {t_cli:.3f} s (cpu {cpu_cli:.3f}), with LiDAR {t_lidar:.3f} s "
              f"(cpu {cpu_lidar:.3f}) (chosen {est.level}/{est2.level})", flush=True)
        if estimate_instant_lighting is not None:  # what predict-light --dataroot runs: the whole instant
            def instant_path():
                est = estimate_instant_lighting(sample, "CAM_FRONT", level, query, for_map=True)
                est.light_at(query).to_envmap(128, 256)
                return est
            est3, t_inst, all_inst = timed(instant_path, runs)
            out[level] |= {"instant_s_median": t_inst, "instant_runs": all_inst, "instant_cameras": len(sample.cameras),
                           "instant_chosen": est3.level}
            print(f"speed {level}: predict-light instant ({len(sample.cameras)} cameras, map-judged auto) "
                  f"{t_inst:.3f} s (chosen {est3.level})", flush=True)
    return out


def grid_sweep(runs: int, quick: bool) -> dict:
    if not REAL.exists():
        return {"skipped": f"{REAL} not found"}
    sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    view = sample.cameras["CAM_FRONT"]
    _ = view.image, sample.lidar
    shapes = [(64, 64, 16), (96, 96, 24), (128, 128, 32), (160, 160, 40)] if not quick else [(96, 96, 24), (128, 128, 32)]
    out = {}
    query = np.array([0.0, 1.5, 15.0])
    for shape in shapes:
        grid = replace(L3_GRID, shape=shape)
        def run():
            sl = estimate_views_lighting([view], sample.location, "L3", lidar=sample.lidar, boxes=sample.boxes,
                                         grid=grid)
            sl.for_view(view).light_at(query).to_envmap(128, 256)
            return sl
        _, t_med, _ = timed(run, runs)
        cpu = float(np.median(LAST_CPU))
        table, _ = novel_view_table(sample, ("L3",), grid=grid)
        out["x".join(map(str, shape))] = {
            "time_s_median": t_med, "cpu_s_median": cpu,
            "monocular_psnr": table["monocular/L3"]["psnr_mean"], "monocular_si_psnr": table["monocular/L3"]["si_psnr_mean"],
            "loo_psnr": table["leave_one_out/L3"]["psnr_mean"], "loo_si_psnr": table["leave_one_out/L3"]["si_psnr_mean"],
        }
        print(f"grid {shape}: {t_med:.3f} s (cpu {cpu:.3f}), mono {out['x'.join(map(str, shape))]['monocular_psnr']:.2f} dB, "
              f"loo {out['x'.join(map(str, shape))]['loo_psnr']:.2f} dB", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="runs per timing (median reported)")
    ap.add_argument("--quick", action="store_true", help="fewer levels / grids (smoke run)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    ap.add_argument("--sections", default=",".join(ALL_SECTIONS),
                    help="comma-separated subset; a subset updates an existing lighting_bench.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    sections = set(args.sections.split(","))
    out_json = args.out / "lighting_bench.json"
    result = json.loads(out_json.read_text()) if out_json.is_file() and sections != set(ALL_SECTIONS) else {}
    result |= {"machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(),
                          "load_average_start": list(os.getloadavg()), "torch_threads": torch.get_num_threads()}}
    tiles, images = [], []
    if "speed" in sections:
        result["speed"] = speed_section(args.runs)
    if "bundled" in sections:
        result["bundled"], tiles = bundled_section(args.runs, args.quick)
    if "real" in sections:
        result["real_novel_view"], images = real_section(args.quick)
    if "forward" in sections:
        result["forward_novel_view"] = forward_section()
    if "street_prior" in sections:
        result["street_prior_ablation"] = street_prior_section()
    if "grid" in sections:
        result["grid_sweep"] = grid_sweep(args.runs, args.quick)
    result["machine"]["load_average_end"] = list(os.getloadavg())
    args.out.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(result, indent=2, default=float) + "\n")
    if tiles:
        cv2.imwrite(str(args.out / "lighting_envmaps.png"), np.concatenate(tiles, axis=0)[..., ::-1])
    if images:
        # Real nuScenes pixels: this picture stays outside the repository.
        private = Path("/tmp/streetaug_bench_lighting")
        private.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(private / "lighting_novel_views.png"),
                    (np.concatenate(images, axis=0)[..., ::-1] * 255).round().astype(np.uint8))
    print(f"wrote {out_json}")


if __name__ == "__main__":
    main()
