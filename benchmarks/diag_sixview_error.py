"""Where the six-view forward error sits: the paper's protocol (lighting from the 6 cameras at keyframe t,
CAM_FRONT's real view at t + 3 through the map at the new centre), its squared error split by region.

Usage: ``python benchmarks/diag_sixview_error.py [--stride 4] [--level auto] [--png /tmp/light]``

For every source keyframe (every ``--stride``-th with a t + 3) the t + 3 CAM_FRONT prediction of
``bench_real_lighting`` (320 px, at its camera's auto-exposure) is compared with the real image pixel by pixel.
Each pixel's share of the summed squared error (and its mean squared error) is reported by

* **region**: sky (the image's sky mask at t + 3), vehicle (inside an annotated vehicle box at t + 3; ``moved``
  if that instance's centre moved > 0.5 m since t), road (depth known, point below 0.3 m), vegetation (greener
  than red and blue by 5 %), facade (the rest with depth), other (no depth, not sky);
* **distance** of the true surface (t + 3 LiDAR densified; sky apart);
* **image row band** (6 bands, top first);
* **seen at t**: the ray from the t + 3 centre hits a t camera's seen-surface mesh (the prediction comes from a
  seen surface) and that surface is the true one (hit distance within 25 % of the t + 3 depth), hits a wrong
  surface, or misses (volume / dome); sky pixels: whether the direction is inside a t camera's sky.

Oracle gains (dB of the whole view if ...): the sky perfect, each region perfect, near field (< 10 m) perfect,
unseen perfect, each row band perfect, the exposure perfect per channel (a gain per channel in linear
radiance, least squares in LDR), the low frequencies perfect (Gaussian 4 px: prediction - blur(prediction) +
blur(truth)), the best shift of +-4 px (registration).

Uses the target's LiDAR and boxes only to *diagnose*; nothing of t + 3 enters the prediction. PNGs (prediction
| truth | error) only with ``--png``, outside the repository. Writes ``diag_sixview_error.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_lighting import CAMERAS, SEQ, lighting  # noqa: E402

from streetaug.augment.core import hdr_to_ldr, invert_transform, pixel_rays, transform_points  # noqa: E402
from streetaug.augment.core.io import write_json_atomic  # noqa: E402
from streetaug.augment.evaluation.novel_view import paper_pairs, psnr, real_view  # noqa: E402
from streetaug.augment.lighting.build import lidar_points_in_volume  # noqa: E402
from streetaug.augment.lighting.evidence import image_sky_mask, prepare_image  # noqa: E402
from streetaug.augment.lighting.multiview import _observe, volume_frame  # noqa: E402
from streetaug.augment.lighting.predicted_view import auto_exposed, predicted_radiance, view_rays  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
W = 320
DIST_EDGES = (0.0, 5.0, 10.0, 20.0, 40.0, np.inf)
N_BANDS = 6


def target_geometry(sample, view, w: int = W):
    """(depth (h, w) camera-z m, inf unknown; sky (h, w) bool; height (h, w) m above the ego's ground) of ``view``
    from its own sample's LiDAR (diagnosis only)."""
    T_global_from_vol = volume_frame(view)
    T_vol_from_global = invert_transform(T_global_from_vol)
    T_vol_from_cam = T_vol_from_global @ np.asarray(view.T_global_from_cam)
    lidar_vol = lidar_points_in_volume(sample.lidar, T_vol_from_global)
    obs = _observe(view, T_vol_from_cam, 1.0, lidar_vol, None)
    T_cam_from_vol = invert_transform(T_vol_from_cam)
    up = np.asarray(T_vol_from_cam)[2, :3]
    work = prepare_image(np.asarray(view.image), view.K, up / np.linalg.norm(up),
                         transform_points(T_cam_from_vol, lidar_vol))
    sky = image_sky_mask(work)
    h = int(round(view.height * w / view.width))
    depth = cv2.resize(obs.depth_view.depth_m, (w, h), interpolation=cv2.INTER_NEAREST)
    sky = cv2.resize(sky.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    depth = np.where(sky, np.inf, depth)
    rays, _ = view_rays(view, w)
    rays_z1 = rays / rays[:, 2:3]
    p_vol = transform_points(T_vol_from_cam, rays_z1 * np.where(np.isfinite(depth), depth, 0).reshape(-1, 1))
    height = np.where(np.isfinite(depth), p_vol[:, 2].reshape(h, w), np.nan)
    return depth, sky, height


def box_masks(sample, earlier, view, w: int = W):
    """(vehicle (h, w) bool, moved (h, w) bool): pixels inside an annotated vehicle's projected box at the
    view's sample, and those of instances that moved > 0.5 m since ``earlier``."""
    h = int(round(view.height * w / view.width))
    s = w / view.width
    K = np.asarray(view.K) * np.array([[s], [s], [1.0]])
    before = {b.instance_token: np.asarray(b.center) for b in earlier.boxes}
    veh = np.zeros((h, w), np.uint8)
    mov = np.zeros((h, w), np.uint8)
    T = np.asarray(view.T_cam_from_global)
    for b in sample.boxes:
        if not b.category.startswith("vehicle"):
            continue
        c = transform_points(T, b.corners())
        if (c[:, 2] < 0.5).any():
            continue
        uv = (c[:, :2] / c[:, 2:3]) @ K[:2, :2].T + K[:2, 2]
        hull = cv2.convexHull(uv.astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(veh, hull, 1)
        p0 = before.get(b.instance_token)
        if p0 is None or np.linalg.norm(np.asarray(b.center) - p0) > 0.5:
            cv2.fillConvexPoly(mov, hull, 1)
    return veh > 0, mov > 0


def seen_status(sl, view, depth, sky, source):
    """(h, w) int: 0 sky seen at t, 1 sky not seen, 2 mesh hit on the true surface, 3 mesh hit on a wrong one,
    4 no mesh hit (volume / dome)."""
    rays, h = view_rays(view, W)
    T = invert_transform(sl.T_global_from_vol) @ np.asarray(view.T_global_from_cam)
    centre = sl.hybrid.lift_out_of_solid(T[:3, 3])
    dirs = rays @ T[:3, :3].T
    hit, t, _ = sl.hybrid.seen.trace(np.repeat(centre[None], len(dirs), 0), dirs)
    z = (t * rays[:, 2]).reshape(h, W)  # camera-z of the hit
    hit = hit.reshape(h, W)
    out = np.full((h, W), 4, np.int8)
    true = hit & np.isfinite(depth) & (np.abs(z - depth) <= 0.25 * depth)
    out[hit & ~true] = 3
    out[true] = 2
    # sky: the direction inside a source camera's sky mask
    seen_sky = np.zeros(len(dirs), bool)
    for c in CAMERAS:
        v = source.cameras[c]
        R = np.asarray(v.T_cam_from_global)[:3, :3] @ np.asarray(sl.T_global_from_vol)[:3, :3]
        d = dirs @ R.T
        ok = d[:, 2] > 1e-3
        uv = (d[:, :2] / np.where(ok, d[:, 2], 1)[:, None]) @ np.asarray(v.K)[:2, :2].T + np.asarray(v.K)[:2, 2]
        inside = ok & (uv[:, 0] >= 0) & (uv[:, 0] < v.width) & (uv[:, 1] >= 0) & (uv[:, 1] < v.height)
        seen_sky |= inside
    sky_seen = seen_sky.reshape(h, W)
    out[sky & sky_seen] = 0
    out[sky & ~sky_seen] = 1
    return out


def per_channel_exposure_oracle(rad, truth):
    """The prediction with the best gain per channel (linear radiance; LDR least squares by golden search)."""
    out = np.empty_like(truth)
    for ch in range(3):
        lo, hi = np.log(1 / 8), np.log(8)
        f = lambda g: float(((hdr_to_ldr(rad[..., ch:ch + 1].repeat(3, -1) * np.exp(g))[..., 0] - truth[..., ch]) ** 2).mean())
        for _ in range(40):
            a, b = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
            if f(a) < f(b):
                hi = b
            else:
                lo = a
        g = 0.5 * (lo + hi)
        out[..., ch] = hdr_to_ldr(rad[..., ch:ch + 1].repeat(3, -1) * np.exp(g))[..., 0]
    return out


def shift_oracle(pred, truth, k: int = 4):
    """PSNR of the prediction at its best integer shift within +-k px (the border cropped)."""
    best = -np.inf
    t = truth[k:-k, k:-k]
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            p = pred[k + dy: pred.shape[0] - k + dy, k + dx: pred.shape[1] - k + dx]
            best = max(best, psnr(p, t))
    return best


def split(err, masks: dict) -> dict:
    total = float(err.sum())
    n = err.size
    return {name: {"share_of_error": float(err[m].sum() / total), "pixel_fraction": float(m.sum() / n),
                   "mse": float(err[m].mean()) if m.any() else None,
                   "psnr_in_region": float(10 * np.log10(1 / max(err[m].mean(), 1e-12))) if m.any() else None}
            for name, m in masks.items()}


def oracle(pred, truth, masks: dict) -> dict:
    base = psnr(pred, truth)
    out = {}
    for name, m in masks.items():
        p = pred.copy()
        p[m] = truth[m]
        out[name] = psnr(p, truth) - base
    return out


def keyframe(reader, tokens, t, level, png: Path | None) -> dict:
    src, tgt = reader.sample(tokens[t]), reader.sample(tokens[t + 3])
    sl, dt = lighting(src, list(CAMERAS), level)
    view = tgt.cameras["CAM_FRONT"]
    truth = real_view(view)
    raw = predicted_radiance(replace(sl, input_mean_ldr={}), view)
    rad = auto_exposed(sl, view, raw)
    pred = hdr_to_ldr(rad)
    err = ((pred - truth) ** 2).mean(axis=-1)  # (h, w)
    depth, sky, height = target_geometry(tgt, view)
    veh, moved = box_masks(tgt, src, view)
    rgb = truth
    green = (rgb[..., 1] > 1.05 * rgb[..., 0]) & (rgb[..., 1] > 1.05 * rgb[..., 2])
    has_d = np.isfinite(depth)
    road = has_d & (np.nan_to_num(height, nan=9.0) < 0.3) & ~veh
    regions = {"sky": sky & ~veh, "vehicle_static": veh & ~moved, "vehicle_moved": moved, "road": road,
               "vegetation": has_d & ~road & ~veh & green & ~sky,
               "facade": has_d & ~road & ~veh & ~green & ~sky, "other": ~has_d & ~sky & ~veh}
    dist = {f"{lo:g}-{hi:g}m": has_d & (depth >= lo) & (depth < hi) for lo, hi in zip(DIST_EDGES[:-1], DIST_EDGES[1:])}
    dist["no_depth"] = ~has_d
    h = err.shape[0]
    bands = {f"rows_{i}": np.zeros_like(sky) for i in range(N_BANDS)}
    for i in range(N_BANDS):
        bands[f"rows_{i}"][i * h // N_BANDS:(i + 1) * h // N_BANDS] = True
    status = seen_status(sl, view, depth, sky, src)
    names = ("sky_seen_at_t", "sky_unseen_at_t", "mesh_true_surface", "mesh_wrong_surface", "no_mesh_hit")
    seen = {n: status == i for i, n in enumerate(names)}
    ex = per_channel_exposure_oracle(rad, truth)
    blur = lambda a: cv2.GaussianBlur(a.astype(np.float32), (0, 0), 4.0, borderType=cv2.BORDER_REPLICATE)
    lowfreq = np.clip(pred - blur(pred) + blur(truth), 0, 1)
    highfreq = np.clip(blur(pred) + (truth - blur(truth)), 0, 1)
    base = psnr(pred, truth)
    mean_rgb = {"pred": pred.reshape(-1, 3).mean(0).tolist(), "truth": truth.reshape(-1, 3).mean(0).tolist()}
    for name in ("sky", "road", "facade", "vegetation"):
        m = regions[name]
        if m.any():
            mean_rgb[f"{name}_pred"] = pred[m].mean(0).tolist()
            mean_rgb[f"{name}_truth"] = truth[m].mean(0).tolist()
    row = {"t": t, "chosen": sl.level, "seconds": dt, "psnr": base,
           "by_region": split(err, regions), "by_distance": split(err, dist), "by_row_band": split(err, bands),
           "by_seen_at_t": split(err, seen),
           "oracle_gain_db": oracle(pred, truth, regions | {"near_lt_10m": has_d & (depth < 10)}
                                    | {"unseen": seen["sky_unseen_at_t"] | seen["no_mesh_hit"] | seen["mesh_wrong_surface"]}
                                    | bands | seen)
           | {"exposure_per_channel": psnr(ex, truth) - base,
              "low_frequencies_sigma4px": psnr(lowfreq, truth) - base,
              "high_frequencies_sigma4px": psnr(highfreq, truth) - base,
              "best_shift_4px": shift_oracle(pred, truth) - psnr(pred[4:-4, 4:-4], truth[4:-4, 4:-4])},
           "mean_rgb": mean_rgb}
    if png is not None:
        png.mkdir(parents=True, exist_ok=True)
        e = np.clip(np.sqrt(err) * 3, 0, 1)[..., None].repeat(3, -1)
        lab = np.zeros_like(pred)
        colours = {"sky": (0.3, 0.6, 1), "road": (0.5, 0.5, 0.5), "facade": (0.8, 0.5, 0.3), "vegetation": (0.2, 0.8, 0.2),
                   "vehicle_static": (1, 1, 0), "vehicle_moved": (1, 0, 1), "other": (0, 0, 0)}
        for n, c in colours.items():
            lab[regions[n]] = c
        st = np.zeros_like(pred)
        for i, c in enumerate([(0.3, 0.6, 1), (0, 0, 0.4), (0, 0.8, 0), (1, 0, 0), (1, 1, 0)]):
            st[status == i] = c
        sheet = np.concatenate([np.concatenate([pred, truth], 1), np.concatenate([e, lab], 1),
                                np.concatenate([st, 0.5 * (pred + truth)], 1)], 0)
        cv2.imwrite(str(png / f"sixview_t{t:02d}.png"), (sheet[..., ::-1] * 255).astype(np.uint8))
    return row


def summarise(rows: list[dict]) -> dict:
    out: dict = {"psnr_median": float(np.median([r["psnr"] for r in rows]))}
    for group in ("by_region", "by_distance", "by_row_band", "by_seen_at_t"):
        out[group] = {k: {"share_of_error_mean": float(np.mean([r[group][k]["share_of_error"] for r in rows])),
                          "pixel_fraction_mean": float(np.mean([r[group][k]["pixel_fraction"] for r in rows]))}
                      for k in rows[0][group]}
    out["oracle_gain_db_mean"] = {k: float(np.mean([r["oracle_gain_db"][k] for r in rows]))
                                  for k in rows[0]["oracle_gain_db"]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stride", type=int, default=4)
    ap.add_argument("--level", default="auto")
    ap.add_argument("--keyframes", default=None)
    ap.add_argument("--png", type=Path, default=None, help="write prediction / truth sheets here (not in the repo)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    ap.add_argument("--name", default="diag_sixview_error.json")
    args = ap.parse_args()
    if args.png is not None and ROOT in args.png.resolve().parents:
        raise SystemExit("--png must be outside the repository (no pictures of the shared data in it)")
    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens("scene-0916")
    pairs = paper_pairs(len(tokens))[:: args.stride]
    if args.keyframes:
        pairs = [(int(k), int(k) + 3) for k in args.keyframes.split(",")]
    rows = []
    for t, _ in pairs:
        t0 = time.perf_counter()
        rows.append(keyframe(reader, tokens, t, args.level, args.png))
        r = rows[-1]
        print(f"t={t} psnr {r['psnr']:.2f} ({time.perf_counter() - t0:.0f} s) share: "
              + ", ".join(f"{k} {v['share_of_error']:.2f}/{v['pixel_fraction']:.2f}" for k, v in r["by_region"].items())
              + " | seen: " + ", ".join(f"{k} {v['share_of_error']:.2f}/{v['pixel_fraction']:.2f}" for k, v in r["by_seen_at_t"].items())
              + " | oracle: " + ", ".join(f"{k} {v:+.2f}" for k, v in r["oracle_gain_db"].items()), flush=True)
    result = {"level": args.level, "stride": args.stride, "summary": summarise(rows),
              "even_keyframes": summarise([r for r in rows if (r["t"] // args.stride) % 2 == 0]),
              "odd_keyframes": summarise([r for r in rows if (r["t"] // args.stride) % 2 == 1]) if len(rows) > 1 else None,
              "per_keyframe": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / args.name, result)
    print(f"wrote {args.out / args.name}")


if __name__ == "__main__":
    main()
