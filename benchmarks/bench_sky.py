"""Learned sky model and single-image sky predictor: accuracy on held-out real panoramas, speed, size.

Usage: ``python benchmarks/bench_sky.py [--out benchmarks/results/sky_benchmark.json] [--quick]``

Uses the shipped weights (``augment/lighting/skynet/weights``) and the HDR panoramas of
``../shared/data/hdri`` (skipped with a message when absent).  Held out from all training: ``sky``
(clear, high sun), ``sunrise`` (clear, low sun), ``venice`` (no sun).  One core (torch 1 thread, BLAS 1).

Sections (all numbers land in the JSON):

1. ``resolution``: why 32 x 128 - the resolution floor (peak error of the true dome, diffuse/mirror
   sphere MSE of the true dome vs the full-resolution panorama) and the cost (train step, inference) at
   32 x 128 and 64 x 256.
2. ``sky_reconstruction``: LDR dome -> sky vector -> HDR dome on the held-out panoramas at 8 azimuths:
   ``log-MSE`` = mean over dome pixels and channels of ``(log1p(x_hat) - log1p(x))^2`` with the dome
   exposed so its median luminance is 0.25 (LDR ~0.53), and the median angle between the decoded peak
   and ``index.json``'s ``gt_peak``; baseline: a parametric sky fit (Preetham + CIE overcast of
   ``lighting/sky.py``, sun from the saturated LDR region, turbidity / cloud cover / scale fitted to the
   unsaturated pixels, the model's sun added at that scale).
3. ``single_image``: 1600 x 900 perspective views (70 deg horizontal FOV) cut from the held-out sunny
   panoramas at 12 azimuths around the sun (level camera) + 3 tilted views with the sun in the frame;
   median angular error of the predicted sun direction (network + the explicit cues of
   ``skynet/sun_cues.py``: sun disc, clear-sky fit; and the network alone), fraction < 20 deg, calibration of the predicted
   68 % cone, how often a sun is reported; baseline: a constant guess (sun 45 deg up, straight ahead).
   Same views of ``venice`` (no sun): how often the predictor (wrongly) reports a sun.
4. ``sphere_insertion``: diffuse (albedo 0.8) and mirror spheres lit by the predicted light vs by the
   true panorama (at the view's exposure), MSE of the LDR sphere images (pixels inside the sphere);
   baselines: the constant dome of the image's mean radiance (the paper's "no light" / L0) and the
   current image-only ``estimate_lighting_from_image``; plus the metadata path (true sun direction +
   ``refine_sky`` on the sky pixels).
5. ``single_image_heldin``: the same on the training panoramas dawn and forest (+ views tilted up 15 deg)
   and sun reports on city / night: the development set of the sun cues (not a held-out measure).
6. ``bundled_scenes``: sun direction error on the bundled sample scenes' images (no metadata used).
7. ``speed_size``: inference time per image on one core, weights size on disk.
8. ``real streets`` (issue 16; ``--real`` runs only this, into ``sky_benchmark_real.json``): the single-image
   sun direction without metadata on the real dev scene's held-out keyframes (and its training keyframes),
   the one-north keyframe and 12 level views of every sunny panorama (held-out / trained on by v3), through
   the predictor and the front door ``estimate_lighting_from_image(level="auto")``; ``--before-weights`` or
   ``--before-from`` add the previous weights (see :func:`section_real_streets`).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from streetaug.augment.core import (  # noqa: E402
    camera_dir_to_lonlat,
    camera_envmap_directions,
    equirect_pixel_lonlat,
    equirect_solid_angles,
    hdr_to_ldr,
    intrinsics_from_fov,
    ldr_uint8_to_hdr,
    lonlat_to_world_dir,
    luminance,
    sample_equirect,
    world_dir_to_lonlat,
)
from streetaug.augment.core import read_image_rgb, write_image_rgb, write_json_atomic  # noqa: E402
from streetaug.augment.lighting.sky import sky_radiance, sun_irradiance  # noqa: E402
from streetaug.augment.lighting.skynet.dome import (  # noqa: E402
    angle_deg,
    camera_from_angles,
    dome_directions,
    find_peak,
    hdri_direction,
    panorama_to_dome,
    render_perspective,
)
from streetaug.augment.lighting.skynet.inputs import quantize_ldr  # noqa: E402
from streetaug.augment.lighting.skynet.model import SkyModel, SkyNetConfig  # noqa: E402
from streetaug.augment.lighting.skynet.predict import (  # noqa: E402
    decode_sky,
    encode_dome,
    get_models,
    predict_sky,
    refine_sky,
    sky_to_light,
)
from streetaug.augment.lighting.skynet.weights import LIGHT_WEIGHTS, SKY_WEIGHTS, packaged_weights  # noqa: E402
from streetaug.augment.training import data as D  # noqa: E402
from streetaug.augment.training.synth import splat_direction  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HDRI = D.default_hdri_dir()
VIEW_W, VIEW_H, VIEW_FOV = 1600, 900, 70.0
SPHERE = 64


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _gt_peaks() -> dict[str, np.ndarray]:
    idx = json.loads((HDRI / "index.json").read_text())["files"]
    return {n: hdri_direction(v["gt_peak"]["azimuth_deg"], v["gt_peak"]["elevation_deg"]) for n, v in idx.items()}


def _median_time(fn, runs: int = 7) -> float:
    fn()
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


# ----------------------------------------------------------------------------- spheres


def _sphere_geometry(size: int):
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    inside = x * x + y * y <= 1.0
    n = np.stack([x, y, -np.sqrt(np.clip(1 - x * x - y * y, 0, 1))], -1).reshape(-1, 3)
    v = np.array([0.0, 0.0, 1.0])
    refl = v[None] - 2 * (n @ v)[:, None] * n
    return n, refl, inside


def spheres(dirs_cam, radiance, omega, mirror_lookup, size=SPHERE, albedo=0.8):
    """(diffuse, mirror) sphere images (size, size, 3) seen along camera +z; directions in the camera frame."""
    n, refl, inside = _sphere_geometry(size)
    irr = np.maximum(n @ dirs_cam.T, 0.0) * omega[None] @ radiance
    diffuse = (albedo / np.pi * irr).reshape(size, size, 3) * inside[..., None]
    mirror = mirror_lookup(refl).reshape(size, size, 3) * inside[..., None]
    return diffuse, mirror, inside


def spheres_world(pano_world, R_world_from_cam, scale):
    small = cv2.resize(pano_world, (128, 64), interpolation=cv2.INTER_AREA).astype(np.float64) * scale
    d_w = lonlat_to_world_dir(*equirect_pixel_lonlat(64, 128)).reshape(-1, 3)
    omega = equirect_solid_angles(64, 128).reshape(-1)

    def lookup(refl_cam):
        lon, lat = world_dir_to_lonlat(refl_cam @ R_world_from_cam.T)
        return sample_equirect(pano_world, lon, lat) * scale

    return spheres(d_w @ R_world_from_cam, small.reshape(-1, 3), omega, lookup)


def spheres_camera(env_cam):
    small = cv2.resize(env_cam, (128, 64), interpolation=cv2.INTER_AREA).astype(np.float64)
    # INTER_AREA ignores the cos(latitude) weights; re-normalise each channel's integral
    full_int = (env_cam.reshape(-1, 3) * equirect_solid_angles(*env_cam.shape[:2]).reshape(-1, 1)).sum(0)
    omega = equirect_solid_angles(64, 128).reshape(-1)
    small_int = (small.reshape(-1, 3) * omega[:, None]).sum(0)
    small = small.reshape(-1, 3) * np.where(small_int > 0, full_int / np.maximum(small_int, 1e-30), 0.0)

    def lookup(refl_cam):
        lon, lat = camera_dir_to_lonlat(refl_cam)
        return sample_equirect(env_cam, lon, lat)

    return spheres(camera_envmap_directions(64, 128).reshape(-1, 3), small, omega, lookup)


def sphere_mse(a, b):
    (da, ma, inside), (db, mb, _) = a, b
    f = lambda x: hdr_to_ldr(x)[inside]  # noqa: E731
    return float(np.mean((f(da) - f(db)) ** 2)), float(np.mean((f(ma) - f(mb)) ** 2))


# ----------------------------------------------------------------------------- parametric baseline


def parametric_fit(ldr_dome: np.ndarray) -> np.ndarray:
    """HDR dome (H, W, 3) of the best Preetham/CIE sky (+ model sun) for an LDR dome (see module doc)."""
    H, W = ldr_dome.shape[:2]
    dirs = dome_directions(H, W).reshape(-1, 3)
    ldr = ldr_dome.reshape(-1, 3)
    hdr_obs = np.asarray(ldr_uint8_to_hdr(np.round(ldr * 255).astype(np.uint8)[None])[0], dtype=np.float64)
    sat = ldr.max(axis=1) >= 0.98
    if sat.sum() >= 1:
        sun = find_peak(np.where(sat[:, None], 1.0 + hdr_obs, 0.0).reshape(H, W, 3))
    else:
        sun = find_peak(hdr_obs.reshape(H, W, 3))
    sun = sun if sun[2] > 0.02 else np.array([sun[0], sun[1], 0.02]) / np.linalg.norm([sun[0], sun[1], 0.02])
    ok = ~sat
    best = None
    for T in (2.0, 3.0, 5.0, 8.0):
        for c in (0.0, 0.25, 0.5, 0.75, 1.0):
            m = sky_radiance(dirs, sun, T, c)
            lm, lo = luminance(m[ok]), luminance(hdr_obs[ok])
            s = float(np.exp(np.median(np.log(np.maximum(lo, 1e-6)) - np.log(np.maximum(lm, 1e-9)))))
            err = float(np.mean((np.log1p(s * m[ok]) - np.log1p(hdr_obs[ok])) ** 2))
            if best is None or err < best[0]:
                best = (err, T, c, s, m)
    _, T, c, s, m = best
    dome = (s * m).reshape(H, W, 3) + splat_direction(sun, s * sun_irradiance(sun, T, c), H, W)
    return dome


# ----------------------------------------------------------------------------- sections


def section_resolution(panos, gt) -> dict:
    out: dict = {"floor": {}, "cost": {}}
    for H, W in ((32, 128), (64, 256)):
        errs, dmse, mmse = [], [], []
        for name in D.VAL_PANORAMAS:
            pano = panos[name]
            dome = panorama_to_dome(pano, H, W)
            errs.append(float(angle_deg(find_peak(dome), gt[name])))
            # the panorama with its upper half replaced by the dome (nearest upsampling keeps the energy)
            scale = D.DOME_MEDIAN_TARGET / max(float(np.median(luminance(dome))), 1e-9)
            up = cv2.resize(dome, (pano.shape[1], pano.shape[0] // 2), interpolation=cv2.INTER_NEAREST)
            approx = pano.copy()
            approx[: pano.shape[0] // 2] = up
            R = camera_from_angles(0.0, 0.0)
            a, b = spheres_world(pano, R, scale), spheres_world(approx, R, scale)
            d, m = sphere_mse(a, b)
            dmse.append(d)
            mmse.append(m)
        out["floor"][f"{H}x{W}"] = {"peak_err_deg_median": float(np.median(errs)), "peak_err_deg": errs,
                                    "sphere_mse_diffuse": float(np.mean(dmse)), "sphere_mse_mirror": float(np.mean(mmse))}
        model = SkyModel(SkyNetConfig(height=H, width=W))
        x = torch.rand(12, 3, H, W)
        tgt = torch.rand(12, 3, H, W)
        opt = torch.optim.Adam(model.parameters())

        def step():
            li, d, z = model.encoder(x)
            loss = ((model.decoder(li, d, z) - tgt) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()

        def infer():
            with torch.no_grad():
                model.decoder(*model.encoder(x[:1]))

        out["cost"][f"{H}x{W}"] = {"train_step_b12_s": _median_time(step, 3), "encode_decode_s": _median_time(infer)}
    return out


def section_reconstruction(panos, gt, sky_model) -> dict:
    H, W = sky_model.cfg.height, sky_model.cfg.width
    res: dict = {"learned": {}, "parametric": {}}
    all_l, all_p = {"mse": [], "err": []}, {"mse": [], "err": []}
    for name in D.VAL_PANORAMAS:
        rows_l, rows_p = {"mse": [], "err": []}, {"mse": [], "err": []}
        for yaw in np.arange(8) * 45.0:
            dome = D.expose_dome(panorama_to_dome(panos[name], H, W, np.radians(yaw)), None)
            g = _rz(np.radians(yaw)).T @ gt[name]
            rec = decode_sky(encode_dome(dome, sky_model), sky_model)
            par = parametric_fit(quantize_ldr(dome))
            for rows, pred in ((rows_l, rec), (rows_p, par)):
                rows["mse"].append(float(np.mean((np.log1p(np.maximum(pred, 0)) - np.log1p(dome)) ** 2)))
                rows["err"].append(float(angle_deg(find_peak(pred), g)))
        for key, rows, acc in (("learned", rows_l, all_l), ("parametric", rows_p, all_p)):
            res[key][name] = {"log_mse": float(np.mean(rows["mse"])), "peak_err_deg_median": float(np.median(rows["err"]))}
            acc["mse"] += rows["mse"]
            acc["err"] += rows["err"]
    for key, acc in (("learned", all_l), ("parametric", all_p)):
        res[key]["all"] = {"log_mse": float(np.mean(acc["mse"])), "peak_err_deg_median": float(np.median(acc["err"]))}
        sunny = [e for e, n in zip(acc["err"], [n for n in D.VAL_PANORAMAS for _ in range(8)]) if n != "venice"]
        res[key]["sunny"] = {"peak_err_deg_median": float(np.median(sunny))}
    res["note"] = "8 azimuths per panorama; venice has no sun (its 'peak' is the brightest sky region)"
    return res


def make_views(pano, gt_dir, quick=False):
    """[(label, yaw, pitch)] around the sun: level views at 12 azimuth offsets + 3 tilted views of the sun."""
    sun_az = float(np.arctan2(gt_dir[1], gt_dir[0]))
    sun_el = float(np.degrees(np.arcsin(gt_dir[2])))
    offsets = np.arange(0, 360, 60 if quick else 30)
    views = [("level", sun_az + np.radians(o), 0.0) for o in offsets]
    pitch = float(np.clip(sun_el - 8.0, 0.0, 40.0))
    for o in (0.0, -20.0, 20.0)[: 1 if quick else 3]:
        views.append(("tilted", sun_az + np.radians(o), np.radians(pitch)))
    return views


def section_single_image(panos, gt, models, quick=False) -> tuple[dict, list]:
    from streetaug.augment.lighting.api import estimate_lighting_from_image

    K = intrinsics_from_fov(VIEW_W, VIEW_H, VIEW_FOV)
    rows = []
    figs = []
    for name in ("sky", "sunrise", "venice"):
        pano = panos[name]
        for label, yaw, pitch in make_views(pano, gt[name], quick):
            R_wc = camera_from_angles(yaw, pitch, 0.0)
            rad = render_perspective(pano, K, R_wc, VIEW_W, VIEW_H, supersample=1)
            k = D.auto_exposure(rad)
            image = np.clip(np.round(hdr_to_ldr(rad * k) * 255), 0, 255).astype(np.uint8)
            up_cam = R_wc.T @ np.array([0.0, 0.0, 1.0])
            sun_cam = R_wc.T @ gt[name]
            uv = K @ sun_cam
            in_view = bool(sun_cam[2] > 0 and 0 <= uv[0] / uv[2] < VIEW_W and 0 <= uv[1] / uv[2] < VIEW_H)
            t = time.perf_counter()
            pred = predict_sky(image, K, up_cam, models=models)
            t_pred = time.perf_counter() - t
            err = float(angle_deg(pred.direction_cam, sun_cam))
            pred_cnn = predict_sky(image, K, up_cam, models=models, use_cues=False)
            err_cnn = float(angle_deg(pred_cnn.direction_cam, sun_cam))
            prior = R_wc.T @ lonlat_to_world_dir(np.array(yaw), np.array(np.radians(45.0)))
            row = {"pano": name, "kind": label, "yaw_deg": float(np.degrees(yaw)), "pitch_deg": float(np.degrees(pitch)),
                   "sun_in_view": in_view, "err_deg": err, "err_deg_cnn_only": err_cnn,
                   "prior_err_deg": float(angle_deg(prior, sun_cam)),
                   "uncertainty_deg": pred.uncertainty_deg, "uncertainty_deg_cnn_only": pred_cnn.uncertainty_deg,
                   "visibility": pred.visibility_raw, "sun_reported": pred.confident,
                   "sun_disc_detected": "sun disc" in pred.reason, "predict_s": t_pred,
                   "predict_cues_s": pred.timing_s.get("cues", 0.0)}
            # sphere insertion: predicted light (ground = the image's mean radiance below the horizon) vs truth
            hdr_img = ldr_uint8_to_hdr(image).astype(np.float64)
            ys = np.arange(VIEW_H)
            rays_v = np.linalg.inv(K) @ np.stack([np.full(VIEW_H, VIEW_W / 2), ys, np.ones(VIEW_H)])
            below = (rays_v.T @ up_cam) < 0
            ground = hdr_img[below].reshape(-1, 3).mean(0) if below.any() else None
            truth = spheres_world(pano, R_wc, k)
            light = sky_to_light(pred.sky, pred.R_heading_from_cam, pred.sun_visibility, pred.confident,
                                 ground_radiance=ground, sky_model=models[0])
            row["mse_learned"] = sphere_mse(spheres_camera(light.to_envmap(128, 256)), truth)
            const = np.broadcast_to(hdr_img.reshape(-1, 3).mean(0), (64, 128, 3)).astype(np.float32)
            row["mse_constant"] = sphere_mse(spheres_camera(const), truth)
            try:
                est = estimate_lighting_from_image(image, K)
                row["mse_current_image_only"] = sphere_mse(spheres_camera(est.light_cam.to_envmap(128, 256)), truth)
            except Exception as e:  # the other estimator is developed in parallel; record, do not fail
                row["mse_current_image_only_error"] = f"{type(e).__name__}: {e}"
            # metadata path: the true sun direction + refinement on the sky pixels (above 2 deg)
            u, v = np.meshgrid(np.arange(VIEW_W), np.arange(VIEW_H))
            rays = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(K).T
            rays /= np.linalg.norm(rays, axis=1, keepdims=True)
            sky_mask = ((rays @ up_cam) > np.sin(np.radians(2.0))).reshape(VIEW_H, VIEW_W)
            vis_true = D.PANORAMA_SUN_VISIBILITY[name]
            base = pred.sky_raw if vis_true > 0 else pred.sky
            refined = refine_sky(base, image, K, sky_mask, up_cam, sun_cam if vis_true > 0 else None, steps=20,
                                 models=models)
            light_m = sky_to_light(refined, pred.R_heading_from_cam, vis_true, vis_true > 0, ground_radiance=ground,
                                   sky_model=models[0])
            row["mse_metadata_refined"] = sphere_mse(spheres_camera(light_m.to_envmap(128, 256)), truth)
            rows.append(row)
            if label == "tilted" or (label == "level" and abs(((np.degrees(yaw) - np.degrees(np.arctan2(gt[name][1], gt[name][0]))) + 180) % 360 - 180) in (90.0,)):
                figs.append((image, light.to_envmap(64, 128)))
    sunny = [r for r in rows if r["pano"] != "venice"]
    errs = np.array([r["err_deg"] for r in sunny])
    in_v = np.array([r["sun_in_view"] for r in sunny])
    unc = np.array([r["uncertainty_deg"] for r in sunny])
    out = {
        "views": rows,
        "sunny_views": len(sunny),
        "sun_err_deg_median": float(np.median(errs)),
        "sun_err_deg_median_in_view": float(np.median(errs[in_v])) if in_v.any() else None,
        "sun_err_deg_median_out_of_view": float(np.median(errs[~in_v])) if (~in_v).any() else None,
        "fraction_under_20deg": float(np.mean(errs < 20.0)),
        "cnn_only_err_deg_median": float(np.median([r["err_deg_cnn_only"] for r in sunny])),
        "cnn_only_fraction_under_20deg": float(np.mean([r["err_deg_cnn_only"] < 20.0 for r in sunny])),
        "prior_baseline_err_deg_median": float(np.median([r["prior_err_deg"] for r in sunny])),
        "calibration_fraction_within_68pct_cone": float(np.mean(errs <= unc)),
        "cnn_only_calibration_fraction_within_68pct_cone": float(np.mean([r["err_deg_cnn_only"] <= r["uncertainty_deg_cnn_only"]
                                                                           for r in sunny])),
        "sun_disc_detected_in_view": f"{sum(r['sun_disc_detected'] for r in sunny if r['sun_in_view'])} / {int(in_v.sum())}",
        "sun_disc_detected_out_of_view_or_no_sun": int(sum(r["sun_disc_detected"] for r in rows
                                                           if not r["sun_in_view"] or r["pano"] == "venice")),
        "predict_s_median": float(np.median([r["predict_s"] for r in rows])),
        "sun_reported_fraction_sunny": float(np.mean([r["sun_reported"] for r in sunny])),
        "sun_err_deg_median_when_reported": float(np.median(errs[[r["sun_reported"] for r in sunny]]))
        if any(r["sun_reported"] for r in sunny) else None,
        "sun_reported_fraction_venice_no_sun": float(np.mean([r["sun_reported"] for r in rows if r["pano"] == "venice"])),
        "per_pano_err_deg_median": {n: float(np.median([r["err_deg"] for r in rows if r["pano"] == n]))
                                    for n in ("sky", "sunrise")},
        "per_pano_err_deg_median_in_out_of_view": {
            n: {k: float(np.median(v)) if v else None for k, v in (
                ("in", [r["err_deg"] for r in rows if r["pano"] == n and r["sun_in_view"]]),
                ("out", [r["err_deg"] for r in rows if r["pano"] == n and not r["sun_in_view"]]))}
            for n in ("sky", "sunrise")},
    }
    mse = {}
    for key in ("mse_learned", "mse_constant", "mse_current_image_only", "mse_metadata_refined"):
        vals = [r[key] for r in rows if key in r]
        if vals:
            mse[key.removeprefix("mse_")] = {"diffuse": float(np.mean([v[0] for v in vals])),
                                             "mirror": float(np.mean([v[1] for v in vals])), "n": len(vals)}
    return out, mse, figs


def section_single_image_heldin(models, quick=False) -> dict:
    """The sun-direction numbers of ``section_single_image`` on the panoramas the networks were trained on
    (dawn: a glow, the sun just below the horizon; forest: a high sun behind pines) plus views tilted up
    15 deg, and how often a sun is (wrongly) reported on city / night.  This is the set the cue constants
    were developed on; it is not a held-out measure (the network saw these panoramas)."""
    idx = json.loads((HDRI / "index.json").read_text())["files"]
    names = ("dawn", "forest", "city", "night")
    panos = D.load_panoramas(HDRI, names)
    K = intrinsics_from_fov(VIEW_W, VIEW_H, VIEW_FOV)
    rows = []
    for name in names:
        g = idx[name]["gt_peak"]
        gt = hdri_direction(g["azimuth_deg"], g["elevation_deg"])
        views = make_views(panos[name], gt, quick)
        if name in ("dawn", "forest"):
            sun_az = float(np.arctan2(gt[1], gt[0]))
            views += [("up15", sun_az + np.radians(o + 15.0), np.radians(15.0)) for o in range(0, 360, 60 if quick else 30)]
        else:
            views = [v for v in views if v[0] == "level"][::2]
        for label, yaw, pitch in views:
            R_wc = camera_from_angles(yaw, pitch, 0.0)
            rad = render_perspective(panos[name], K, R_wc, VIEW_W, VIEW_H, supersample=1)
            image = np.clip(np.round(hdr_to_ldr(rad * D.auto_exposure(rad)) * 255), 0, 255).astype(np.uint8)
            up_cam = R_wc.T @ np.array([0.0, 0.0, 1.0])
            sun_cam = R_wc.T @ gt
            uv = K @ sun_cam
            pred = predict_sky(image, K, up_cam, models=models)
            rows.append({"pano": name, "kind": label, "yaw_deg": float(np.degrees(yaw)), "pitch_deg": float(np.degrees(pitch)),
                         "sun_in_view": bool(sun_cam[2] > 0 and 0 <= uv[0] / uv[2] < VIEW_W and 0 <= uv[1] / uv[2] < VIEW_H),
                         "err_deg": float(angle_deg(pred.direction_cam, sun_cam)), "uncertainty_deg": pred.uncertainty_deg,
                         "sun_reported": pred.confident})
    sun = [r for r in rows if r["pano"] in ("dawn", "forest")]
    errs = np.array([r["err_deg"] for r in sun])
    in_v = np.array([r["sun_in_view"] for r in sun])
    rep = np.array([r["sun_reported"] for r in sun])
    return {
        "views": rows,
        "note": "held-in (training) panoramas: development numbers, not a held-out measure",
        "sun_err_deg_median": float(np.median(errs)),
        "sun_err_deg_median_in_view": float(np.median(errs[in_v])) if in_v.any() else None,
        "sun_err_deg_median_out_of_view": float(np.median(errs[~in_v])) if (~in_v).any() else None,
        "per_pano_err_deg_median": {n: float(np.median([r["err_deg"] for r in sun if r["pano"] == n])) for n in ("dawn", "forest")},
        "fraction_under_20deg": float(np.mean(errs < 20.0)),
        "calibration_fraction_within_68pct_cone": float(np.mean(errs <= np.array([r["uncertainty_deg"] for r in sun]))),
        "sun_reported_fraction": float(rep.mean()),
        "sun_err_deg_median_when_reported": float(np.median(errs[rep])) if rep.any() else None,
        "sun_reported_no_sun_views": f"{sum(r['sun_reported'] for r in rows if r['pano'] in ('city', 'night'))} / "
                                     f"{sum(r['pano'] in ('city', 'night') for r in rows)}",
    }


def section_bundled() -> dict:
    from streetaug.datasets.nuscenes import NuScenesReader

    root = ROOT / "examples" / "nuscenes-samples"
    reader = NuScenesReader(root, "v1.0-samples")
    rows = []
    for scene in ("sample-sunny", "sample-lowsun", "sample-overcast"):
        gt = json.loads((root / "ground_truth" / scene / "lighting.json").read_text())
        for ch, cam in gt["cameras"].items():
            view = reader.camera_view(cam["sample_data_token"])
            pred = predict_sky(np.asarray(view.image), view.K)
            cnn = predict_sky(np.asarray(view.image), view.K, use_cues=False)
            rows.append({"scene": scene, "camera": ch, "err_deg": float(angle_deg(pred.direction_cam, cam["sun_direction_camera"])),
                         "err_deg_cnn_only": float(angle_deg(cnn.direction_cam, cam["sun_direction_camera"])),
                         "sun_disc_detected": "sun disc" in pred.reason,
                         "visibility": pred.visibility_raw, "uncertainty_deg": pred.uncertainty_deg,
                         "sun_reported": pred.confident, "cloud_cover": gt["sky"]["cloud_cover"]})
    clear = [r["err_deg"] for r in rows if r["cloud_cover"] < 0.5]
    return {"views": rows, "clear_err_deg_median": float(np.median(clear)),
            "clear_err_deg_median_cnn_only": float(np.median([r["err_deg_cnn_only"] for r in rows if r["cloud_cover"] < 0.5])),
            "clear_calibration_fraction_within_68pct_cone": float(np.mean([r["err_deg"] <= r["uncertainty_deg"]
                                                                          for r in rows if r["cloud_cover"] < 0.5])),
            "clear_fraction_under_20deg": float(np.mean(np.array(clear) < 20)),
            "overcast_sun_reported": [r["sun_reported"] for r in rows if r["cloud_cover"] >= 0.5]}


# ----------------------------------------------------------------------------- real street views (issue 16)


def _angle(a, b) -> float:
    return float(angle_deg(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)))


def _summary(rows: list[dict]) -> dict:
    """Medians of a set of rows: the product path's reported suns and the predictor's direction on every view."""
    if not rows:
        return {"n": 0}
    err = np.array([r["err_deg"] for r in rows])
    out = {"n": len(rows), "err_deg_median_all_views": float(np.median(err)),
           "fraction_under_20deg_all_views": float(np.mean(err < 20.0)),
           "fraction_under_15deg_all_views": float(np.mean(err < 15.0)),
           "cnn_only_err_deg_median": float(np.median([r["err_deg_cnn_only"] for r in rows])),
           "predictor_sun_reported_fraction": float(np.mean([r["sun_reported"] for r in rows])),
           "prior_baseline_err_deg_median": float(np.median([r["prior_err_deg"] for r in rows]))}
    rep = err[[r["sun_reported"] for r in rows]]
    out["err_deg_median_when_reported"] = float(np.median(rep)) if len(rep) else None
    prod = [r for r in rows if "product_sun_source" in r]
    if any("product_error" in r for r in rows):
        out["product_errors"] = sorted({r["product_error"] for r in rows if "product_error" in r})[:3]
    if prod:
        rep_p = [r["product_err_deg"] for r in prod if r["product_err_deg"] is not None]
        out["product"] = {"n": len(prod), "sun_reported_fraction": float(np.mean([r["product_err_deg"] is not None
                                                                                  for r in prod])),
                          "err_deg_median_when_reported": float(np.median(rep_p)) if rep_p else None,
                          "levels": sorted({r["product_level"] for r in prod}),
                          "sun_agrees_with_predictor": int(sum(r["product_agrees"] for r in prod)),
                          "median_s": float(np.median([r["product_s"] for r in prod]))}
    if "memorised_err_deg" in rows[0]:
        out["per_camera_mean_of_train_labels_err_deg_median"] = float(np.median([r["memorised_err_deg"] for r in rows]))
    return out


def _cue_record(pred, sun_cam) -> dict:
    """JSON-ready :attr:`SkyPrediction.cues` of one view: the sky's fraction and colour, the network's visibility,
    the clipped region under the fitted sun (its shape and surroundings) and whether the glare rule fired, with
    the directions replaced by their errors (deg) against ``sun_cam``: ``err_fit_deg`` (the clear-sky fit before
    any glare move), ``err_glare_centre_deg`` (the clipped region's centre)."""
    out = {}
    for k, v in pred.cues.items():
        if k.endswith("_cam"):
            out["err_" + k.removesuffix("_cam").removeprefix("direction_") + "_deg"] = _angle(v, sun_cam)
        elif isinstance(v, dict):
            out[k] = {kk: (None if not np.isfinite(vv) else float(vv)) for kk, vv in v.items()}
        elif isinstance(v, (bool, np.bool_)):
            out[k] = bool(v)
        else:
            out[k] = None if v is None or not np.isfinite(v) else float(v)
    fit = pred.cues.get("direction_fit_cam")
    out["elevation_fit_deg"] = None if fit is None else \
        float(np.degrees(np.arcsin(np.clip((pred.R_heading_from_cam @ fit)[2], -1, 1))))
    return out


def _view_row(image, K, sun_cam, models, product: bool) -> dict:
    """Errors (deg, camera frame) of one bare image: the predictor's direction (reported or not) and, if
    ``product``, the front door's ``estimate_lighting_from_image(level="auto")`` sun."""
    from streetaug.augment.lighting.api import estimate_lighting_from_image
    from streetaug.augment.lighting.skynet.predict import default_models
    from streetaug.augment.training.real import bare_image_prediction

    pred = bare_image_prediction(image, K, models)
    cnn = bare_image_prediction(image, K, models, use_cues=False)
    row = {"err_deg": _angle(pred.direction_cam, sun_cam), "sun_reported": bool(pred.confident),
           "err_deg_cnn_only": _angle(cnn.direction_cam, sun_cam),
           "visibility": float(pred.visibility_raw), "uncertainty_deg": float(pred.uncertainty_deg),
           "prior_err_deg": _angle([0.0, -np.sin(np.radians(45.0)), np.cos(np.radians(45.0))], sun_cam),
           "cues": _cue_record(pred, sun_cam)}
    if product:
        t = time.perf_counter()
        try:
            with default_models(models):
                est = estimate_lighting_from_image(image, K, level="auto")
        except Exception as e:  # the front door is developed in parallel; record, do not fail
            row["product_error"] = f"{type(e).__name__}: {e}"
            return row
        row["product_s"] = time.perf_counter() - t
        row["product_level"] = est.level
        row["product_sun_source"] = est.sun_source
        row["product_err_deg"] = None if est.sun_dir_cam is None else _angle(est.sun_dir_cam, sun_cam)
        same_dir = est.sun_dir_cam is not None and pred.confident and _angle(est.sun_dir_cam, pred.direction_cam) < 0.5
        row["product_agrees"] = bool(same_dir or (est.sun_dir_cam is None and not pred.confident))
    return row


def section_real_streets(models, product: bool = True, quick: bool = False,
                         parts: tuple[str, ...] = ("streets", "one_north", "panoramas", "sun_in_view")) -> dict:
    """Single-image sun direction (no metadata) on real street views and on panoramas, for one set of weights.

    * ``street_test`` / ``street_train``: scene-0916 (``../shared/data/nuscenes-seq``), keyframes 27-40 (never
      trained on; a 3-keyframe gap from the training block 0-23) and 0-23 (held-in for the v3 model);
      ``street_gap``: the gap keyframes 24-26 (never trained on; with street_test the held-out 24-40).
    * ``one_north``: the 3 cameras of ``../shared/data/nuscenes-real`` (another scene, another sun).
    * ``pano_heldout`` / ``pano_train``: 12 level 1600 x 900 views (70 deg) per sunny panorama at 30 deg azimuth
      steps from its sun (``bench_sky.make_views``' level views; a bare image is assumed level).
    * ``pano_train_sun_in_view`` / ``pano_heldout_sun_in_view``: the sun in the frame (:func:`section_sun_in_view`).

    Truth: the ephemeris (streets) or ``index.json`` (panoramas) rotated into the camera; errors in the camera
    frame.  ``err_deg_median_all_views``: the predictor's direction whether or not a sun is reported (overcast
    views still say something); ``*_when_reported``: only views where a sun is reported; ``product``: the
    front door at ``level="auto"`` (on the held-out sets only: ~2 s a view).
    """
    from streetaug.augment.training import real as R

    seq, one = D.default_hdri_dir().parent / "nuscenes-seq", D.default_hdri_dir().parent / "nuscenes-real"
    out: dict = {}
    if seq.is_dir() and "streets" in parts:
        photos = R.street_photos(seq, shadows=False)
        train_labels = {}
        for p in photos:
            if p.keyframe in R.TRAIN_KEYFRAMES:
                train_labels.setdefault(p.channel, []).append(p.sun_dir_cam)
        mean_dir = {ch: np.mean(v, axis=0) / np.linalg.norm(np.mean(v, axis=0)) for ch, v in train_labels.items()}
        for key, kfs, prod in (("street_test", R.TEST_KEYFRAMES, product), ("street_train", R.TRAIN_KEYFRAMES, False),
                               ("street_gap", R.GAP_KEYFRAMES, False)):
            rows = []
            for p in photos:
                if p.keyframe not in kfs or (quick and p.keyframe % 4):
                    continue
                row = _view_row(read_image_rgb(p.image_path), p.K, p.sun_dir_cam, models, prod)
                row.update(keyframe=p.keyframe, channel=p.channel, memorised_err_deg=_angle(mean_dir[p.channel], p.sun_dir_cam),
                           sun_elevation_deg=p.sun_elevation_deg, tilt_deg=_angle(p.up_cam, R.LEVEL_UP_CAM))
                rows.append(row)
            out[key] = {"summary": _summary(rows), "views": rows}
    if one.is_dir() and "one_north" in parts:
        rows = []
        for p in R.street_photos(one, sample_tokens=(R.ONE_NORTH_SAMPLE,), shadows=False):
            row = _view_row(read_image_rgb(p.image_path), p.K, p.sun_dir_cam, models, product)
            row.update(channel=p.channel, sun_elevation_deg=p.sun_elevation_deg)
            rows.append(row)
        out["one_north"] = {"summary": _summary(rows), "views": rows}
    if "sun_in_view" in parts:
        out.update(section_sun_in_view(models, quick))
    suns = R.panorama_sun(HDRI)
    for key, names, prod in (("pano_heldout", R.HELDOUT_PANORAMAS, product), ("pano_train", R.TRAIN_PANORAMAS_V3, False)):
        if "panoramas" not in parts:
            break
        rows = []
        for name in names:
            sun_w, vis = suns[name]
            if sun_w is None:
                continue
            pano = D.load_panoramas(HDRI, (name,))[name]
            for o, image, K, sun_cam in R.panorama_level_views(pano, sun_w, VIEW_W, VIEW_H, VIEW_FOV, 6 if quick else 12):
                row = _view_row(image, K, sun_cam, models, prod)
                row.update(pano=name, offset_deg=o, new_panorama=name not in R.OLD_PANORAMAS)
                rows.append(row)
        out[key] = {"summary": _summary(rows), "per_pano_err_deg_median": {
            n: float(np.median([r["err_deg"] for r in rows if r["pano"] == n])) for n in names if suns[n][0] is not None},
            "views": rows}
    return out


def sun_in_view_images(names, quick: bool = False):
    """Yields (panorama, yaw offset deg, pitch deg, image (900, 1600, 3) uint8, K, up_cam, sun_cam) of the views of
    :func:`section_sun_in_view` of the sunny panoramas among ``names``."""
    from streetaug.augment.training import real as R

    K = intrinsics_from_fov(VIEW_W, VIEW_H, VIEW_FOV)
    suns = R.panorama_sun(HDRI)
    for name in names:
        sun_w = suns[name][0]
        if sun_w is None:
            continue
        pano = D.load_panoramas(HDRI, (name,))[name]
        az = float(np.arctan2(sun_w[1], sun_w[0]))
        pitch = max(0.0, float(np.arcsin(sun_w[2])) - np.radians(12.0))
        for o in ((-25.0, 0.0, 25.0) if quick else (-25.0, -10.0, 0.0, 10.0, 25.0)):
            R_wc = camera_from_angles(az + np.radians(o), pitch, 0.0)
            rad = render_perspective(pano, K, R_wc, VIEW_W, VIEW_H, supersample=1)
            image = np.clip(np.round(hdr_to_ldr(rad * D.auto_exposure(rad)) * 255), 0, 255).astype(np.uint8)
            yield name, o, float(np.degrees(pitch)), image, K, R_wc.T @ np.array([0.0, 0.0, 1.0]), R_wc.T @ sun_w


def section_sun_in_view(models, quick: bool = False) -> dict:
    """The sun in the frame: views of every sunny panorama pitched up to ``max(0, elevation - 12 deg)`` at yaw
    offsets -25, -10, 0, 10, 25 deg from the sun (1600 x 900, 70 deg), predicted with the true up (a tilted
    camera with metadata-free intrinsics; a bare image would be taken as level).  ``pano_train_sun_in_view``
    (v3's training panoramas: the development set of the glare / disc rule's thresholds) and
    ``pano_heldout_sun_in_view`` (never trained on): whether the seen sun is still found and reported."""
    from streetaug.augment.training import real as R

    out = {}
    for key, names in (("pano_train_sun_in_view", R.TRAIN_PANORAMAS_V3),
                       ("pano_heldout_sun_in_view", R.HELDOUT_PANORAMAS)):
        rows = []
        for name, o, pitch, image, K, up_cam, sun_cam in sun_in_view_images(names, quick):
            pred = predict_sky(image, K, up_cam, models=models)
            cnn = predict_sky(image, K, up_cam, models=models, use_cues=False)
            rows.append({"pano": name, "offset_deg": o, "pitch_deg": pitch,
                         "err_deg": _angle(pred.direction_cam, sun_cam), "sun_reported": bool(pred.confident),
                         "err_deg_cnn_only": _angle(cnn.direction_cam, sun_cam),
                         "visibility": float(pred.visibility_raw), "uncertainty_deg": float(pred.uncertainty_deg),
                         "prior_err_deg": _angle([0.0, -np.sin(np.radians(45.0)), np.cos(np.radians(45.0))], sun_cam),
                         "cues": _cue_record(pred, sun_cam)})
        out[key] = {"summary": _summary(rows), "views": rows}
    return out


def section_speed(models, panos) -> dict:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (900, 1600, 3), dtype=np.uint8)
    K = intrinsics_from_fov(1600, 900, 70.0)
    pred = predict_sky(image, K, models=models)
    # the costly case for the cues: a level view with a large clear sky (the sky fit runs on the most pixels)
    rad = render_perspective(panos["sky"], K, camera_from_angles(0.0, 0.0, 0.0), VIEW_W, VIEW_H, supersample=1)
    sky_view = np.clip(np.round(hdr_to_ldr(rad * D.auto_exposure(rad)) * 255), 0, 255).astype(np.uint8)
    mask = np.zeros((900, 1600), bool)
    mask[:300] = True
    return {
        "predict_sky_1600x900_s": _median_time(lambda: predict_sky(image, K, models=models), 10),
        "predict_sky_1600x900_sky_view_s": _median_time(lambda: predict_sky(sky_view, K, models=models), 10),
        "predict_sky_1600x900_sky_view_cnn_only_s": _median_time(
            lambda: predict_sky(sky_view, K, models=models, use_cues=False), 10),
        "decode_sky_s": _median_time(lambda: decode_sky(pred.sky, models[0]), 10),
        "sky_to_light_128x256_s": _median_time(lambda: sky_to_light(pred.sky, pred.R_heading_from_cam, sky_model=models[0]), 5),
        "refine_sky_20_steps_s": _median_time(lambda: refine_sky(pred.sky, image, K, mask, steps=20, models=models), 3),
        "weights_bytes": {"sky": packaged_weights(SKY_WEIGHTS).stat().st_size,
                          "light": packaged_weights(LIGHT_WEIGHTS).stat().st_size},
        "parameters": {"sky_encoder": int(sum(p.numel() for p in models[0].encoder.parameters())),
                       "sky_decoder": int(sum(p.numel() for p in models[0].decoder.parameters())),
                       "light": int(sum(p.numel() for p in models[1].parameters()))},
    }


def run_real(args) -> dict:
    """Section 8 for the shipped weights (and ``--before-weights``), written to ``args.real_out``."""
    from streetaug.augment.lighting.skynet.weights import load_light_model, read_weights

    t0 = time.perf_counter()
    sky_model, net = get_models()
    res = {"machine": {"load_avg_start": os.getloadavg(), "torch_threads": 1}, "weights": {}}
    after = getattr(args, "after_weights", None)
    runs = [("after", after, (sky_model, load_light_model(after)))] if after else \
        [("after", packaged_weights(LIGHT_WEIGHTS), (sky_model, net))]
    if args.before_weights is not None:
        runs.insert(0, ("before", args.before_weights, (sky_model, load_light_model(args.before_weights))))
    for extra in getattr(args, "merge", None) or []:  # parts measured by another process (--real-parts)
        other = json.loads(Path(extra).read_text())
        for key in ("before", "after"):
            if key in other:
                res.setdefault(key, {}).update(other[key])
    if getattr(args, "before_from", None) is not None:
        earlier = json.loads(Path(args.before_from).read_text())
        res["before"] = earlier["after"]
        res["weights"]["before"] = {**earlier["weights"]["after"], "measured_in": Path(args.before_from).name,
                                    "load_avg": earlier["machine"]}
    for key, path, models in runs:
        meta = read_weights(path, "light")
        res["weights"][key] = {"file": Path(path).name, "version": meta.get("version")}
        res[key] = res.get(key, {}) | section_real_streets(models, product=not args.no_product, quick=args.quick,
                                        parts=tuple(args.real_parts.split(",")))
    for key in ("before", "after"):
        if key in res:
            for name, sec in res[key].items():
                sm = sec["summary"]
                print(f"{key:6s} {name:13s} n {sm['n']:3d}: direction median {sm.get('err_deg_median_all_views', float('nan')):5.1f} deg "
                      f"(<15 {sm.get('fraction_under_15deg_all_views', 0):.2f}, cnn {sm.get('cnn_only_err_deg_median', float('nan')):5.1f}), "
                      f"reported {sm.get('predictor_sun_reported_fraction', 0):.2f} (median {sm.get('err_deg_median_when_reported')}); "
                      f"product {sm.get('product')}")
    res["machine"]["load_avg_end"] = os.getloadavg()
    res["bench_time_s"] = time.perf_counter() - t0
    res["note"] = section_real_streets.__doc__
    write_json_atomic(args.real_out, res)
    print(f"wrote {args.real_out}")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "sky_benchmark.json")
    ap.add_argument("--quick", action="store_true", help="fewer views (a smoke run)")
    ap.add_argument("--real", action="store_true",
                    help="only section 8 (real street views and all panoramas) -> --real-out")
    ap.add_argument("--real-out", type=Path, default=ROOT / "benchmarks" / "results" / "sky_benchmark_real.json")
    ap.add_argument("--before-weights", type=Path, default=None,
                    help="also measure section 8 with this image-predictor weights file (e.g. the previous version)")
    ap.add_argument("--before-from", type=Path, default=None,
                    help="take section 8's 'before' from the 'after' of an earlier --real JSON (the run of the "
                         "previous weights) instead of re-measuring it")
    ap.add_argument("--no-product", action="store_true", help="section 8 without the (slow) front-door runs")
    ap.add_argument("--after-weights", type=Path, default=None,
                    help="section 8's 'after' with this image-predictor weights file (default: the shipped one)")
    ap.add_argument("--real-parts", default="streets,one_north,panoramas,sun_in_view",
                    help="comma list of section 8's parts to measure (streets, one_north, panoramas, sun_in_view)")
    ap.add_argument("--merge", type=Path, nargs="*", default=None,
                    help="--real JSON files of other parts (another process) merged into this one's result")
    args = ap.parse_args()
    if not (HDRI / "index.json").is_file():
        print(f"skipped: {HDRI} not found (the held-out panoramas are needed)")
        return
    torch.set_num_threads(1)
    if args.real:
        run_real(args)
        return
    t0 = time.perf_counter()
    panos = D.load_panoramas(HDRI, D.VAL_PANORAMAS)
    gt = _gt_peaks()
    models = get_models()
    result = {"machine": {"cpu": platform.processor() or platform.machine(), "load_avg_start": os.getloadavg(),
                          "torch_threads": 1}}
    result["speed_size"] = section_speed(models, panos)
    result["resolution"] = section_resolution(panos, gt)
    result["sky_reconstruction"] = section_reconstruction(panos, gt, models[0])
    single, mse, figs = section_single_image(panos, gt, models, args.quick)
    result["single_image"] = single
    result["sphere_insertion"] = mse
    result["single_image_heldin"] = section_single_image_heldin(models, args.quick)
    result["bundled_scenes"] = section_bundled()
    run_real(args)
    result["machine"]["load_avg_end"] = os.getloadavg()
    result["bench_time_s"] = time.perf_counter() - t0
    write_json_atomic(args.out, result)
    if figs:
        tiles = []
        for image, env in figs[:6]:
            img = cv2.resize(image, (256, 144), interpolation=cv2.INTER_AREA)
            envl = cv2.resize((hdr_to_ldr(env) * 255).astype(np.uint8), (256, 128), interpolation=cv2.INTER_AREA)
            tiles.append(np.concatenate([img, envl], axis=0))
        # Crops of the shared real panoramas: this picture stays outside the repository.
        write_image_rgb(Path("/tmp/streetaug_bench_sky/sky_views.png"), np.concatenate(tiles, axis=1))
    s, r = result["single_image"], result["sky_reconstruction"]
    print(f"sky reconstruction (held-out): learned log-MSE {r['learned']['all']['log_mse']:.4f}, "
          f"peak {r['learned']['sunny']['peak_err_deg_median']:.2f} deg (sunny) | parametric "
          f"{r['parametric']['all']['log_mse']:.4f}, {r['parametric']['sunny']['peak_err_deg_median']:.2f} deg")
    print(f"single image sun direction: median {s['sun_err_deg_median']:.1f} deg (in view "
          f"{s['sun_err_deg_median_in_view']}, out {s['sun_err_deg_median_out_of_view']}), "
          f"<20 deg {s['fraction_under_20deg']:.2f}, prior {s['prior_baseline_err_deg_median']:.1f} deg, "
          f"calibration {s['calibration_fraction_within_68pct_cone']:.2f} (0.68 ideal), "
          f"venice sun reported {s['sun_reported_fraction_venice_no_sun']:.2f}")
    for k, v in mse.items():
        print(f"sphere MSE {k}: diffuse {v['diffuse']:.2e} mirror {v['mirror']:.2e}")
    hi = result["single_image_heldin"]
    print(f"held-in (development) panoramas dawn/forest: median {hi['sun_err_deg_median']:.1f} deg (in view "
          f"{hi['sun_err_deg_median_in_view']}, out {hi['sun_err_deg_median_out_of_view']}), calibration "
          f"{hi['calibration_fraction_within_68pct_cone']:.2f}, no-sun views reported {hi['sun_reported_no_sun_views']}")
    print(f"bundled scenes (clear): median {result['bundled_scenes']['clear_err_deg_median']:.1f} deg")
    sp = result["speed_size"]
    print(f"per-pano median (in / out of view): {s['per_pano_err_deg_median_in_out_of_view']}; "
          f"cnn only {s['cnn_only_err_deg_median']:.1f} deg; discs in view {s['sun_disc_detected_in_view']}")
    print(f"predict_sky {sp['predict_sky_1600x900_s'] * 1e3:.0f} ms (noise image), "
          f"{sp['predict_sky_1600x900_sky_view_s'] * 1e3:.0f} ms (sky view; network only "
          f"{sp['predict_sky_1600x900_sky_view_cnn_only_s'] * 1e3:.0f} ms), refine 20 steps {sp['refine_sky_20_steps_s'] * 1e3:.0f} ms, "
          f"weights {sum(sp['weights_bytes'].values()) / 1e6:.2f} MB; wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
