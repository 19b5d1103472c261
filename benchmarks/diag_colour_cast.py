"""Diagnose the colour cast of inserted cars against real ones (issue #20): the CIELAB a*/b* of near-neutral
pixels (chroma < 8) per L band, for the real cars, the real road and the inserted cars of a
``bench_realism`` render cache, and the camera's neutral axis per LDR level band (G - R, G - B in DN of
near-neutral pixels of the real images).

Usage::

    nice python benchmarks/diag_colour_cast.py --cache /tmp/realism/cache_s10_cast_before [--stride 4]

Writes ``benchmarks/results/diag_colour_cast_<name of the cache>.json`` (numbers only, no pictures).

Finding on scene-0916 (h_full, 2877254): real near-neutral pixels (cars and road alike) read a* -2 at L < 10,
-1.5 at L 10-20, -1.0..-1.3 at L 20-40, 0 at L >= 50; inserted cars read a* 0 at every L. In DN: G is 2-3.5
above R and B at every level 8-96 (additive: G/R 1.24 at level 12, 1.03 at 80), none at 128-192: the
camera's tone-dependent cast, which the contract's neutral response does not have
(:func:`streetaug.augment.render.camera_look.neutral_axis`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_realism as br  # noqa: E402

L_BANDS = (0, 10, 20, 30, 40, 50, 60, 70, 80, 101)
DN_BANDS = ((0, 8), (8, 16), (16, 32), (32, 64), (64, 96), (96, 128), (128, 192), (192, 256))
MAX_CHROMA = 8.0
CHANGED_DN = 4  # an inserted car's pixel: inside its box hull and changed by more than this


def lab_bands(acc: dict[str, list[list[np.ndarray]]]) -> dict:
    out = {}
    for name, bands in acc.items():
        rows = []
        for i, parts in enumerate(bands):
            if not parts:
                continue
            s = np.concatenate(parts)
            rows.append({"L": [L_BANDS[i], L_BANDS[i + 1]], "n": int(len(s)), "a_median": float(np.median(s[:, 0])),
                         "a_mean": float(s[:, 0].mean()), "b_median": float(np.median(s[:, 1])),
                         "b_mean": float(s[:, 1].mean())})
        out[name] = rows
    return out


def main() -> None:
    from streetaug.augment.evaluation.realism import extract_crop, srgb_to_lab
    from streetaug.datasets.nuscenes import NuScenesReader

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cache", required=True, help="a bench_realism render cache (PNG + labels JSON per image)")
    p.add_argument("--stride", type=int, default=4, help="the stride the cache was rendered with")
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = p.parse_args()
    reader = NuScenesReader(str(br.SEQ), br.VERSION)
    cache = Path(args.cache)
    acc = {k: [[] for _ in L_BANDS[:-1]] for k in ("real_car", "inserted_car", "real_road")}
    dn = {b: [] for b in DN_BANDS}
    for token in br.keyframe_tokens(reader, args.stride):
        doc = json.loads((cache / f"{token}.json").read_text())
        sample = reader.sample(token)
        for channel in br.CAMERAS:
            view = sample.cameras[channel]
            orig = np.asarray(view.image)
            aug = cv2.imread(str(cache / f"{token}_{channel}.png"))[:, :, ::-1]
            real, inserted, _, _ = br.image_cars(reader, sample, view, doc[channel])
            H, W = orig.shape[:2]
            parts = [("real_road", orig[int(0.85 * H):, W // 3: 2 * W // 3][::3, ::3].reshape(-1, 3))]
            for T, wlh in real:
                crop = extract_crop(orig, view.K, T, wlh)
                parts.append(("real_car", crop.rgb[crop.car_mask]))
            for T, wlh in inserted:
                crop = extract_crop(aug, view.K, T, wlh)
                x0, y0, x1, y1 = crop.window
                changed = np.abs(orig[y0:y1, x0:x1].astype(int) - aug[y0:y1, x0:x1].astype(int)).max(-1) > CHANGED_DN
                parts.append(("inserted_car", crop.rgb[crop.car_mask & changed]))
            for name, px in parts:
                if len(px) < 10:
                    continue
                lab = srgb_to_lab(px.astype(np.float64) / 255.0)
                lab = lab[np.hypot(lab[:, 1], lab[:, 2]) < MAX_CHROMA]
                band = np.digitize(lab[:, 0], L_BANDS) - 1
                for i in range(len(L_BANDS) - 1):
                    if (band == i).any():
                        acc[name][i].append(lab[band == i, 1:])
            x = orig[::3, ::3].reshape(-1, 3).astype(np.float64)
            m = x.mean(1)
            neutral = (x.max(1) - x.min(1)) <= 0.12 * m + 6
            for lo, hi in DN_BANDS:
                dn[(lo, hi)].append(x[neutral & (m >= lo) & (m < hi)])
    axis = []
    for (lo, hi), parts in dn.items():
        x = np.concatenate(parts)
        if len(x):
            axis.append({"level": [lo, hi], "n": int(len(x)), "mean_rgb": x.mean(0).round(2).tolist(),
                         "G_minus_R": float((x[:, 1] - x[:, 0]).mean()), "G_minus_B": float((x[:, 1] - x[:, 2]).mean())})
    doc = {"cache": str(cache), "stride": args.stride, "neutral_pixels_lab_by_L": lab_bands(acc),
           "real_neutral_axis_dn": axis}
    out = Path(args.out) / f"diag_colour_cast_{cache.name}.json"
    out.write_text(json.dumps(doc, indent=1))
    for name, rows in doc["neutral_pixels_lab_by_L"].items():
        print(name)
        for r in rows:
            print(f"  L {r['L'][0]:3d}-{r['L'][1]:3d}  n {r['n']:7d}  a* {r['a_median']:+.2f} ({r['a_mean']:+.2f})  "
                  f"b* {r['b_median']:+.2f} ({r['b_mean']:+.2f})")
    print("real neutral axis (DN)")
    for r in axis:
        print(f"  level {r['level']}: n {r['n']:8d}  G-R {r['G_minus_R']:+.2f}  G-B {r['G_minus_B']:+.2f}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
