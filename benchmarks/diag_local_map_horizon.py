"""Where the local environment map at a placed car is wrong: per elevation and azimuth band, L1 / L2 / L3 vs the
true local light of the generated street (bundled scenes, :class:`~streetaug.augment.scenegen.ground_truth.GroundTruthScene`).

Cases: ``bench --small``'s (sample-sunny, seed 0; the default rules: the kerb under the trees, and the class
table's fixed lane / kerb weights) and test_stability_kerb's (procedural_car(3), draft, seed 0), at EV 0 and
(``--ev``) the image exposed +1 EV (truth x 2).

Per band: the solid-angle-weighted RMS of log(1 + L_est) - log(1 + L_true) (the metric of ``env_log_error``) and
the mean log ratio log(L_est / L_true) of the band's luminance (its bias, + = too bright), both over the
sun-free maps (sun disc excluded from the estimate and the truth; the sun is reported apart). Elevation is
against the ground's up at the car; azimuth is measured from the camera's forward axis projected on the ground
(0 = away from the camera, 180 = back towards it, 90 = the camera's right).

    python benchmarks/diag_local_map_horizon.py --out benchmarks/results/diag_local_map_horizon.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.select import select_assets
from streetaug.augment.core import camera_envmap_directions, equirect_solid_angles, luminance, rotate_vectors, transform_points
from streetaug.augment.core.response import hdr_to_ldr_uint8, ldr_uint8_to_hdr
from streetaug.augment.lighting.api import estimate_lighting
from streetaug.augment.pipeline import InsertOptions, item_seed, place_in_view
from streetaug.augment.scenegen.ground_truth import GroundTruthScene
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

ELEVATION_BANDS_DEG = ((-90, -10), (-10, 0), (0, 10), (10, 30), (30, 90))
AZIMUTH_BANDS_DEG = ((-45, 45), (45, 135), (135, 225), (225, 315))  # ahead, right, back, left
H, W = 64, 128


def _bands(est: np.ndarray, true: np.ndarray, up: np.ndarray, fwd: np.ndarray) -> dict:
    """Per-band RMS log error and luminance bias of two sun-free (H, W, 3) camera-frame maps."""
    d = camera_envmap_directions(H, W)
    omega = equirect_solid_angles(H, W)
    elev = np.degrees(np.arcsin(np.clip(d @ up, -1, 1)))
    right = np.cross(up, fwd)  # camera frame with up = -y: forward x up ... sign checked by az of +x below
    az = np.degrees(np.arctan2(d @ (-right), d @ fwd)) % 360.0
    dlog = np.log1p(np.maximum(est, 0)) - np.log1p(np.maximum(true, 0))
    sq = (dlog**2).mean(axis=2)
    ratio = np.log(np.maximum(luminance(est), 1e-6) / np.maximum(luminance(true), 1e-6))

    def stats(mask: np.ndarray) -> dict:
        w = omega * mask
        s = w.sum()
        return {"rms_log": float(np.sqrt((w * sq).sum() / s)), "bias_log": float((w * ratio).sum() / s),
                "est_lum": float((w * luminance(est)).sum() / s), "true_lum": float((w * luminance(true)).sum() / s),
                "solid_angle_sr": float(s)}

    out = {"all": stats(np.ones((H, W), bool))}
    for lo, hi in ELEVATION_BANDS_DEG:
        out[f"elev {lo}..{hi}"] = stats((elev >= lo) & (elev < hi))
    for lo, hi in AZIMUTH_BANDS_DEG:  # near the horizon only (-10..30), where glass reflects
        a = az if lo >= 0 else (az + 180) % 360 - 180
        out[f"az {lo % 360}..{hi % 360} (elev -10..30)"] = stats((a >= lo) & (a < hi) & (elev >= -10) & (elev < 30))
        for elo, ehi in ELEVATION_BANDS_DEG[1:4]:  # the cells near the horizon
            out[f"az {lo % 360}..{hi % 360} elev {elo}..{ehi}"] = stats((a >= lo) & (a < hi) & (elev >= elo) & (elev < ehi))
    return out


def fresnel_dielectric(cos_i: np.ndarray, n: float = 1.5) -> np.ndarray:
    """Unpolarised Fresnel reflectance of one air-glass interface at incidence cosine ``cos_i``."""
    cos_i = np.clip(cos_i, 1e-6, 1.0)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_i**2)) / n
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin_t**2))
    rs = ((cos_i - n * cos_t) / (cos_i + n * cos_t)) ** 2
    rp = ((cos_t - n * cos_i) / (cos_t + n * cos_i)) ** 2
    return 0.5 * (rs + rp)


def glass_reflections(asset, T_cam_from_object: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The directions (N, 3) (camera frame) the camera-facing glass triangles mirror, their weights (N,)
    (projected area / distance^2 x Fresnel; occlusion by the body ignored) and incidence angles (N,) (deg)."""
    glass = np.array([m.opacity < 1.0 for m in asset.materials])[asset.face_material]
    tri = asset.vertices[asset.faces[glass]]  # (F, 3, 3) object frame
    tri = tri @ T_cam_from_object[:3, :3].T + T_cam_from_object[:3, 3]
    c = tri.mean(axis=1)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n = n / np.maximum(2 * area, 1e-12)[:, None]
    d = c / np.linalg.norm(c, axis=1, keepdims=True)
    dn = np.sum(d * n, axis=1)
    flip = dn > 0  # faces wound either way: take the side facing the camera
    n[flip] *= -1
    dn = -np.abs(dn)
    r = d - 2 * dn[:, None] * n
    cos_i = -dn
    w = area * cos_i / np.sum(c**2, axis=1) * fresnel_dielectric(cos_i)
    # one side of a pane only (the outer face): the camera-facing side of triangles whose normal points away from
    # the car's centre
    centre = T_cam_from_object[:3, 3] + 0.7 * T_cam_from_object[:3, 2]
    outward = np.sum((c - centre) * n, axis=1) > 0
    keep = outward & (w > 0)
    return r[keep], w[keep], np.degrees(np.arccos(cos_i[keep]))


def glass_error(est: np.ndarray, true: np.ndarray, dirs: np.ndarray, w: np.ndarray, up: np.ndarray) -> dict:
    """The maps' luminance in the glass-mirrored directions: weighted means and log RMS."""
    from streetaug.augment.core import camera_dir_to_lonlat, sample_equirect

    lon, lat = camera_dir_to_lonlat(dirs)
    le = luminance(sample_equirect(est, lon, lat))
    lt = luminance(sample_equirect(true, lon, lat))
    ws = w / w.sum()
    elev = np.degrees(np.arcsin(np.clip(dirs @ up, -1, 1)))
    return {"est_lum": float(ws @ le), "true_lum": float(ws @ lt),
            "rms_log1p": float(np.sqrt(ws @ (np.log1p(le) - np.log1p(lt)) ** 2)),
            "elev_deg_quartiles": np.percentile(elev, [10, 25, 50, 75, 90]).round(1).tolist()}


def _sun(light) -> dict | None:
    return None if light.sun is None else {"irradiance_lum": float(luminance(np.asarray(light.sun.irradiance_rgb))),
                                           "direction": np.asarray(light.sun.direction).round(4).tolist()}


def diagnose(sample, view, center_cam: np.ndarray, up_cam: np.ndarray, truth: GroundTruthScene, ev: float,
             levels=("L1", "L2", "L3"), glass=None) -> dict:
    """The band errors of each level's local map at ``center_cam`` (camera frame) against the truth x 2^ev."""
    center_global = transform_points(view.T_global_from_cam, center_cam[None])[0]
    true_light = truth.local_light(center_global, view.T_cam_from_global, 128, 256, sky_rays=16)
    true_env = true_light.envmap.astype(np.float32) * np.float32(2.0**ev)
    import cv2

    true_env = cv2.resize(true_env, (W, H), interpolation=cv2.INTER_AREA)
    if ev:
        view = view.with_image(hdr_to_ldr_uint8(ldr_uint8_to_hdr(np.asarray(view.image)) * 2.0**ev))
    fwd = np.array([0.0, 0.0, 1.0]) - up_cam * up_cam[2]
    fwd /= np.linalg.norm(fwd)
    out = {"center_cam": center_cam.round(3).tolist(), "ev": ev, "true_sun": _sun(true_light), "levels": {}}
    if true_light.sun is not None:
        out["true_sun"]["irradiance_lum"] *= 2.0**ev
    for level in levels:
        t0 = time.perf_counter()
        est = estimate_lighting(view, sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                query_point_cam=center_cam)
        light = est.light_at(center_cam, H, W)
        env = light.envmap.astype(np.float32)
        if env.shape[:2] != (H, W):
            env = cv2.resize(env, (W, H), interpolation=cv2.INTER_AREA)
        out["levels"][level] = {"seconds": time.perf_counter() - t0, "sun": _sun(light),
                                "bands": _bands(env, true_env, up_cam, fwd)}
        if glass is not None:
            out["levels"][level]["glass"] = glass_error(env, true_env, glass[0], glass[1], up_cam)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="benchmarks/results/diag_local_map_horizon.json")
    ap.add_argument("--ev", type=float, nargs="*", default=[0.0, 1.0], help="exposures of the kerb case")
    ap.add_argument("--levels", default="L1,L2,L3")
    args = ap.parse_args()
    levels = tuple(args.levels.split(","))
    root = bundled_dataroot()
    reader = NuScenesReader(root, BUNDLED_VERSION)
    truth = GroundTruthScene(root, "sample-sunny")
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    view = sample.cameras["CAM_FRONT"]
    cases = []
    with tempfile.TemporaryDirectory() as tmp:
        rules = Path(tmp) / "rules.json"
        rules.write_text(json.dumps({"schema": "streetaug.class_rules/1", "classes": {
            "car": {"zones": {"lane": 0.6, "kerb": 0.4}, "zone_weights": "fixed"}}}))
        (asset,) = select_assets(item_seed(0, "asset", sample.token, "CAM_FRONT"), 1, location=sample.location)
        for name, a, opts, evs in (
                ("bench_small_scene", asset, InsertOptions(seed=0), [0.0]),
                ("bench_small_fixed", asset, InsertOptions(seed=0, class_rules=str(rules)), [0.0]),
                ("stability_kerb", procedural_car(3), InsertOptions(seed=0, quality="draft"), args.ev)):
            placed = place_in_view(sample, view, [a], [], opts)
            p = placed.placements[0]
            T = view.T_cam_from_global @ p.T_global_from_object
            up = rotate_vectors(view.T_cam_from_global, p.ground_normal_global[None])[0]
            center = T[:3, 3] + 0.5 * a.wlh[2] * T[:3, 2]
            for ev in evs:
                r = diagnose(sample, view, center, up, truth, ev, levels, glass_reflections(a, T))
                r["case"] = name
                r["bottom_cam"] = T[:3, 3].round(3).tolist()
                cases.append(r)
                print(name, f"EV {ev:+.0f}", "center", r["center_cam"])
                for lv, res in r["levels"].items():
                    print(f"  {lv}: " + "  ".join(f"{k} {v['rms_log']:.2f}/{v['bias_log']:+.2f}"
                                                  for k, v in res["bands"].items()))
                    g = res["glass"]
                    print(f"     glass-mirrored: est {g['est_lum']:.3f} true {g['true_lum']:.3f} rms {g['rms_log1p']:.3f} "
                          f"elev {g['elev_deg_quartiles']}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"schema": "streetaug.diag_local_map_horizon/1", "map_hw": [H, W],
                                          "cases": cases}, indent=1))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
