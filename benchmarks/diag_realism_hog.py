"""What does the realism check's HOG see?  Diagnostics of the real-vs-inserted classifier's shape features.

Usage::

    nice python benchmarks/diag_realism_hog.py --tag s10_after_em \
        --caches /tmp/realism/cache_s10_after_em_seed0,/tmp/realism/cache_s10_after_em_seed1,...

Reads the render caches of :mod:`bench_realism` (one per insertion seed; the crops are selected exactly as
there: ``image_cars`` / ``collect_crops``) and, per seed, with the benchmark's size matching:

* ``hog``: HOG-only accuracy (keyframe-grouped 5-fold, :func:`classifier_accuracy`), and the same with the
  crops' pixels outside (``car_only``) or inside (``context_only``) the box hull replaced by their mean colour;
* ``viewing_angle``: accuracy on sets matched by projected height *and* viewing angle (object yaw to the
  camera ray, :data:`YAW_BINS_DEG`; or which end faces the camera, :data:`END_BINS_DEG`: front seen / side-on /
  rear seen) against random subsets of the height-only matched set of the same size (several draws), and the
  angle distributions of both sets;
* ``geometry_only``: the HOG of the box hull's binary mask (the box's projection alone: viewpoint and crop
  aspect, no pixels), and a classifier on (yaw to ray, crop aspect, distance);
* ``silhouette``: the HOG of a GrabCut mask seeded by the box hull (the same method on both sets; for
  inserted cars checked against the true silhouette, the pixels the insertion changed inside the hull), and
  box tightness (silhouette area / hull area, its top and side gaps);
* ``confounds``: inserted visible fraction, crop clipping by the image border, other boxes' overlap;
* ``weights``: mean HOG difference (inserted - real) and the logistic regression's weight energy per
  8x8-pixel cell and per orientation bin (a 64 px crop, 8 x 8 cells, 9 orientations), pooled over the seeds.

Writes ``benchmarks/results/diag_realism_hog_<tag>.json`` and, outside the repository, picture sheets under
``--sheets`` (default ``/tmp/hog``): crops of real and inserted cars side by side by viewing angle, the mean
HOG difference maps.  Pictures of real data are never committed.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_realism as br  # noqa: E402

YAW_BINS_DEG = (0.0, 30.0, 60.0, 90.01)
N_DRAWS = 10
HOG = cv2.HOGDescriptor((64, 64), (16, 16), (8, 8), (8, 8), 9)


def facing_camera_deg(T_cam_from_box: np.ndarray) -> float:
    """Angle (deg, 0..180) between a box's heading and the direction from it to the camera, in its ground plane:
    0 = its front faces the camera (nose seen), 180 = its rear does, 90 = side-on."""
    up = T_cam_from_box[:3, 2]
    heading, to_cam = T_cam_from_box[:3, 0], -T_cam_from_box[:3, 3]
    h, r = heading - (heading @ up) * up, to_cam - (to_cam @ up) * up
    c = h @ r / max(np.linalg.norm(h) * np.linalg.norm(r), 1e-12)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


_car_placement = br.car_placement


def _car_placement_with_facing(zones, view, T_cam_from_box, wlh, crop, kerb_m):
    out = _car_placement(zones, view, T_cam_from_box, wlh, crop, kerb_m)
    return {**out, "facing_camera_deg": facing_camera_deg(T_cam_from_box)}


br.car_placement = _car_placement_with_facing  # diagnostics only: the crops and their selection are unchanged
END_BINS_DEG = (0.0, 60.0, 120.0, 180.01)  # front seen / side-on / rear seen


def hog_of(gray_u8: np.ndarray) -> np.ndarray:
    return HOG.compute(cv2.resize(gray_u8, (64, 64), interpolation=cv2.INTER_AREA)).ravel()


def luma_u8(rgb: np.ndarray) -> np.ndarray:
    from streetaug.augment.evaluation.realism import luma

    return np.clip(luma(rgb), 0, 255).astype(np.uint8)


def filled(crop, where: np.ndarray) -> np.ndarray:
    """The crop with the pixels ``where`` set to the mean colour of the others."""
    if where.all() or not where.any():
        return crop.rgb
    return np.where(where[..., None], crop.rgb[~where].mean(axis=0), crop.rgb).astype(np.uint8)


def grabcut_mask(crop) -> np.ndarray:
    """(h, w) bool: GrabCut foreground seeded by the box hull (probable foreground inside, background outside,
    sure background a margin beyond); the hull itself where GrabCut fails."""
    hull = crop.car_mask.astype(np.uint8)
    far = cv2.dilate(hull, np.ones((7, 7), np.uint8)) == 0
    mask = np.where(hull > 0, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    mask[far] = cv2.GC_BGD
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    try:
        cv2.grabCut(np.ascontiguousarray(crop.rgb[:, :, ::-1]), mask, None, bgd, fgd, 4, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return crop.car_mask.copy()
    fg = (mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)
    return fg & crop.car_mask


def changed_mask(original: np.ndarray, augmented: np.ndarray, crop) -> np.ndarray:
    """Pixels of an inserted car's crop that the insertion changed (> 12 levels in any channel), in the hull."""
    x0, y0, x1, y1 = crop.window
    diff = np.abs(original[y0:y1, x0:x1].astype(int) - augmented[y0:y1, x0:x1].astype(int)).max(axis=2)
    return (diff > 12) & crop.car_mask


def tightness(mask: np.ndarray, hull: np.ndarray) -> dict:
    """Silhouette area over hull area, and the gaps (fraction of the hull's height / width) between the hull's
    bounding rectangle and the silhouette's at the top and the sides."""
    ys, xs = np.nonzero(hull)
    if not mask.any() or not len(ys):
        return {"fill": 0.0, "top_gap": float("nan"), "side_gap": float("nan")}
    my, mx = np.nonzero(mask)
    h, w = ys.max() - ys.min() + 1, xs.max() - xs.min() + 1
    return {"fill": float(mask.sum() / hull.sum()), "top_gap": float((my.min() - ys.min()) / h),
            "side_gap": float(((mx.min() - xs.min()) + (xs.max() - mx.max())) / w)}


def load_seed(cache: Path, args) -> dict:
    """Crops and per-crop diagnostics of one cache (the benchmark's selection)."""
    from streetaug.datasets.nuscenes import NuScenesReader

    ns = argparse.Namespace(dataroot=args.dataroot, version=args.version, stride=args.stride, cameras=args.cameras)
    crops, labels, keyframes, images, places = br.collect_crops(cache, ns)
    reader = NuScenesReader(args.dataroot, args.version)
    originals, augmented = {}, {}
    extra = []
    for crop, lab, img in zip(crops, labels, images):
        token, cam = img.split("_", 1)
        if img not in originals:
            originals[img] = reader.sample(token).cameras[cam].image
        win = crop.window
        h_img, w_img = originals[img].shape[:2]
        e = {"aspect": (win[2] - win[0]) / max(win[3] - win[1], 1),
             "clipped_by_border": int(win[0] == 0 or win[1] == 0 or win[2] == w_img or win[3] == h_img),
             "other_box_share": float(crop.exclude_mask[crop.car_mask].mean()) if crop.car_mask.any() else 0.0}
        if lab == 1:
            if img not in augmented:
                augmented[img] = cv2.imread(str(cache / f"{img}.png"))[:, :, ::-1]
            e["true_mask"] = changed_mask(originals[img], augmented[img], crop)
        extra.append(e)
    # inserted visible fractions, matched to crops by their box (the labels file of each image)
    vis = []
    for crop, lab, img in zip(crops, labels, images):
        if lab == 0:
            vis.append(float("nan"))
            continue
        token, cam = img.split("_", 1)
        objs = json.loads((cache / f"{token}.json").read_text())[cam]
        best = min(objs, key=lambda o: abs(np.linalg.norm(o["box_camera"]["center"]) - crop.distance_m))
        vis.append(float(best["visible_fraction"]))
    return {"crops": crops, "labels": labels, "keyframes": keyframes, "images": images, "places": places,
            "extra": extra, "visible_fraction": np.array(vis)}


def size_matched(*a, **k):
    from streetaug.augment.evaluation.realism import size_matched as f

    return f(*a, **k)


def acc(X, y, groups, seed=0) -> float:
    from streetaug.augment.evaluation.realism import classifier_accuracy

    return classifier_accuracy(X, y, groups, seed=seed)["accuracy_mean"]


def analyse_seed(data: dict, seed: int) -> tuple[dict, dict]:
    """Per-seed diagnostics and the arrays pooled over seeds (HOG rows, labels, yaw)."""
    crops, labels, keyframes = data["crops"], data["labels"], data["keyframes"]
    heights = np.array([c.box_height_px for c in crops])
    yaw = np.array([p.get("yaw_to_ray_deg", np.nan) for p in data["places"]])
    real_idx, ins_idx = np.flatnonzero(labels == 0), np.flatnonzero(labels == 1)
    rng = np.random.default_rng(seed)
    pr, pi = size_matched(heights[real_idx], heights[ins_idx], br.HEIGHT_BINS_PX, rng, 60)
    chosen = np.concatenate([real_idx[pr], ins_idx[pi]])
    y, g = labels[chosen], keyframes[chosen]
    H = {}
    H["hog"] = np.stack([hog_of(luma_u8(crops[i].rgb)) for i in chosen])
    H["hog_car_only"] = np.stack([hog_of(luma_u8(filled(crops[i], ~crops[i].car_mask))) for i in chosen])
    H["hog_context_only"] = np.stack([hog_of(luma_u8(filled(crops[i], crops[i].car_mask))) for i in chosen])
    H["hog_box_hull_mask"] = np.stack([hog_of(crops[i].car_mask.astype(np.uint8) * 255) for i in chosen])
    gc = {i: grabcut_mask(crops[i]) for i in chosen}
    H["hog_grabcut_silhouette"] = np.stack([hog_of(gc[i].astype(np.uint8) * 255) for i in chosen])
    ex = [data["extra"][i] for i in chosen]
    geo = np.array([[yaw[i], ex[k]["aspect"], crops[i].distance_m] for k, i in enumerate(chosen)])
    out = {"matched_per_class": int(len(pr)), "accuracy": {k: acc(v, y, g, seed) for k, v in H.items()}}
    out["accuracy"]["geometry_scalars(yaw_to_ray,aspect,distance)"] = acc(geo, y, g, seed)
    out["accuracy"]["yaw_to_ray_only"] = acc(geo[:, :1], y, g, seed)

    # viewing angle: matched by height x yaw bin (and by height x seen end: front / side / rear), against random
    # subsets of the same size of the height-only matched set
    facing = np.array([p.get("facing_camera_deg", np.nan) for p in data["places"]])
    hog_all = {i: hog_of(luma_u8(crops[i].rgb)) for i in np.concatenate([real_idx, ins_idx])}

    def matched_vs_unmatched(angle, bins):
        code = (np.digitize(heights, br.HEIGHT_BINS_PX) * 10 + np.digitize(angle, bins)).astype(float)
        code_r, code_i = code[real_idx], code[ins_idx]
        edges = np.unique(np.concatenate([code_r, code_i])) + 0.5
        edges = np.concatenate([[edges[0] - 1.0], edges])
        va_m, va_u, n_m = [], [], []
        for draw in range(N_DRAWS):
            r = np.random.default_rng(1000 * seed + draw)
            mr, mi = size_matched(code_r, code_i, edges, r)
            if len(mr) < 10:
                continue
            m = np.concatenate([real_idx[mr], ins_idx[mi]])
            va_m.append(acc(np.stack([hog_all[i] for i in m]), labels[m], keyframes[m], draw))
            ur, ui = size_matched(heights[real_idx], heights[ins_idx], br.HEIGHT_BINS_PX, r, len(mr))
            u = np.concatenate([real_idx[ur], ins_idx[ui]])
            va_u.append(acc(np.stack([hog_all[i] for i in u]), labels[u], keyframes[u], draw))
            n_m.append(len(mr))
        return {"bins_deg": list(bins),
                "median": {"real": float(np.nanmedian(angle[chosen[y == 0]])),
                           "inserted": float(np.nanmedian(angle[chosen[y == 1]]))},
                "bin_counts": {name: np.histogram(angle[chosen[y == k]], bins)[0].tolist()
                               for k, name in ((0, "real"), (1, "inserted"))},
                "hog_accuracy_matched": float(np.mean(va_m)) if va_m else float("nan"),
                "hog_accuracy_unmatched_same_size": float(np.mean(va_u)) if va_u else float("nan"),
                "matched_per_class_mean": float(np.mean(n_m)) if n_m else 0.0, "draws": len(va_m)}

    out["viewing_angle"] = {"yaw_to_ray": matched_vs_unmatched(yaw, YAW_BINS_DEG),
                            "facing_camera(0 front seen, 180 rear seen)": matched_vs_unmatched(facing, END_BINS_DEG)}

    # silhouettes and box tightness
    tight = {"real": [], "inserted": [], "inserted_true": []}
    iou = []
    for k, i in enumerate(chosen):
        hull = crops[i].car_mask
        tight["real" if labels[i] == 0 else "inserted"].append(tightness(gc[i], hull))
        if labels[i] == 1:
            t = ex[k]["true_mask"]
            tight["inserted_true"].append(tightness(t, hull))
            iou.append(float((t & gc[i]).sum() / max((t | gc[i]).sum(), 1)))
    out["silhouette"] = {name: {key: float(np.nanmedian([t[key] for t in v]))
                                for key in ("fill", "top_gap", "side_gap")} for name, v in tight.items()}
    out["silhouette"]["grabcut_iou_with_true_inserted_median"] = float(np.median(iou)) if iou else float("nan")
    out["confounds"] = {
        "inserted_visible_fraction_median": float(np.nanmedian(data["visible_fraction"][chosen[y == 1]])),
        "inserted_visible_fraction_below_0.95": float(np.mean(data["visible_fraction"][chosen[y == 1]] < 0.95)),
        "clipped_by_border": {n: float(np.mean([ex[k]["clipped_by_border"] for k in range(len(chosen)) if y[k] == c]))
                              for c, n in ((0, "real"), (1, "inserted"))},
        "other_box_share_in_hull_median": {
            n: float(np.median([ex[k]["other_box_share"] for k in range(len(chosen)) if y[k] == c]))
            for c, n in ((0, "real"), (1, "inserted"))},
        "crop_aspect_median": {n: float(np.median(geo[y == c, 1])) for c, n in ((0, "real"), (1, "inserted"))},
    }
    pooled = {"hog": H["hog"], "hog_car_only": H["hog_car_only"], "y": y, "yaw": yaw[chosen], "chosen": chosen,
              "facing": facing[chosen]}
    return out, pooled


def cell_maps(hog_rows: np.ndarray) -> np.ndarray:
    """(N, 8, 8, 9): HOG of a 64 px crop per 8 px cell and orientation, each cell's values averaged over the up
    to four 16 px blocks (stride 8) that contain it.  OpenCV's order: blocks column by column (x outer, y
    inner), in a block its cells x outer, y inner, the 9 bins innermost."""
    n = hog_rows.shape[0]
    blocks = hog_rows.reshape(n, 7, 7, 2, 2, 9)  # (bx, by, cx, cy, bin)
    acc_ = np.zeros((n, 8, 8, 9))
    cnt = np.zeros((8, 8, 1))
    for bx in range(7):
        for by in range(7):
            for cx in range(2):
                for cy in range(2):
                    acc_[:, by + cy, bx + cx] += blocks[:, bx, by, cx, cy]
                    cnt[by + cy, bx + cx] += 1
    return acc_ / cnt  # (N, row, col, bin)


def weight_maps(pooled: list[dict]) -> dict:
    """Mean HOG difference and logistic-regression weight energy per cell and per orientation (pooled seeds)."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    X = np.concatenate([p["hog"] for p in pooled])
    y = np.concatenate([p["y"] for p in pooled])
    maps = cell_maps(X)
    diff = maps[y == 1].mean(axis=0) - maps[y == 0].mean(axis=0)  # (8, 8, 9)
    Xs = StandardScaler().fit_transform(X)
    w = LogisticRegression(C=0.05, max_iter=3000).fit(Xs, y).coef_[0]
    wm = cell_maps(w[None])[0]
    orient_deg = [int(20 * k + 10) for k in range(9)]  # gradient direction bin centres (0 = horizontal gradient)
    return {"mean_hog_difference_per_cell": np.abs(diff).sum(axis=2).round(4).tolist(),
            "mean_hog_difference_per_orientation": diff.sum(axis=(0, 1)).round(4).tolist(),
            "mean_hog_per_orientation": {"real": maps[y == 0].mean(axis=(0, 1, 2)).round(4).tolist(),
                                         "inserted": maps[y == 1].mean(axis=(0, 1, 2)).round(4).tolist()},
            "mean_hog_per_row": {"real": maps[y == 0].sum(axis=3).mean(axis=(0, 2)).round(4).tolist(),
                                 "inserted": maps[y == 1].sum(axis=3).mean(axis=(0, 2)).round(4).tolist()},
            # gradient bins 60-120 deg (bins 3-5): horizontal edges (window bands, lamp bands, bumper, the shadow line);
            # bins 0-1 and 8 (gradient within 40 deg of horizontal): vertical edges
            "horizontal_edge_energy_per_row": {
                n: maps[y == c][..., 3:6].sum(axis=3).mean(axis=(0, 2)).round(4).tolist()
                for c, n in ((0, "real"), (1, "inserted"))},
            "vertical_edge_energy_per_row": {
                n: maps[y == c][..., [0, 1, 8]].sum(axis=3).mean(axis=(0, 2)).round(4).tolist()
                for c, n in ((0, "real"), (1, "inserted"))},
            "weight_energy_per_cell": np.abs(wm).sum(axis=2).round(4).tolist(),
            "signed_weight_per_orientation": wm.sum(axis=(0, 1)).round(4).tolist(),
            "orientation_bin_centres_deg": orient_deg,
            "note": "orientation = gradient direction (0 deg: intensity changes left-right = vertical edges; "
                    "90 deg: horizontal edges); positive difference / weight = more in inserted"}, diff


def sheets(data: dict, pooled: dict, out_dir: Path, tag: str, diff: np.ndarray) -> None:
    """Crops sorted by viewing angle, real | inserted, rows of 6 + 6 at 96 px height; the HOG difference map."""
    out_dir.mkdir(parents=True, exist_ok=True)
    crops, chosen, y, yaw = data["crops"], pooled["chosen"], pooled["y"], pooled["facing"]
    row_h, per = 128, 5

    def tile(c):
        img = cv2.resize(c.rgb, (int(1.4 * row_h), row_h), interpolation=cv2.INTER_AREA)
        return img

    for lo, hi in zip(END_BINS_DEG[:-1], END_BINS_DEG[1:]):
        r = [crops[i] for i, l, a in sorted(zip(chosen, y, yaw), key=lambda t: t[2]) if l == 0 and lo <= a < hi]
        s = [crops[i] for i, l, a in sorted(zip(chosen, y, yaw), key=lambda t: t[2]) if l == 1 and lo <= a < hi]
        n = max(len(r), len(s))
        if not n:
            continue
        blank = np.full((row_h, int(1.4 * row_h), 3), 40, np.uint8)
        rows = []
        for k in range(0, n, per):
            a = [tile(c) for c in r[k:k + per]] + [blank] * (per - len(r[k:k + per]))
            b = [tile(c) for c in s[k:k + per]] + [blank] * (per - len(s[k:k + per]))
            rows.append(np.concatenate(a + [np.full((row_h, 10, 3), (255, 0, 255), np.uint8)] + b, axis=1))
        cv2.imwrite(str(out_dir / f"facing_{int(lo)}_{int(hi)}_{tag}.png"), np.concatenate(rows)[:, :, ::-1])
    # HOG difference: per orientation bin an 8x8 map, red = more in inserted, blue = more in real
    m = np.abs(diff).max() + 1e-9
    tiles = []
    for b in range(9):
        v = diff[:, :, b] / m
        img = np.zeros((8, 8, 3), np.uint8)
        img[..., 0] = np.clip(v, 0, 1) * 255
        img[..., 2] = np.clip(-v, 0, 1) * 255
        tiles.append(cv2.resize(img, (64, 64), interpolation=cv2.INTER_NEAREST))
        tiles.append(np.full((64, 4, 3), 128, np.uint8))
    cv2.imwrite(str(out_dir / f"hog_diff_{tag}.png"), np.concatenate(tiles, axis=1)[:, :, ::-1])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tag", required=True)
    p.add_argument("--caches", required=True, help="Comma-separated bench_realism render caches, one per seed.")
    p.add_argument("--seeds", default=None, help="Comma-separated seeds of the caches (default 0, 1, ...).")
    p.add_argument("--stride", type=int, default=4)
    p.add_argument("--dataroot", default=str(br.SEQ))
    p.add_argument("--version", default=br.VERSION)
    p.add_argument("--cameras", default=",".join(br.CAMERAS))
    p.add_argument("--out", default=str(br.ROOT / "benchmarks" / "results"))
    p.add_argument("--sheets", default="/tmp/hog")
    args = p.parse_args(argv)
    from streetaug.augment.core.io import write_json_atomic

    caches = [Path(c) for c in args.caches.split(",")]
    seeds = [int(s) for s in args.seeds.split(",")] if args.seeds else list(range(len(caches)))
    per_seed, pooled = [], []
    for cache, seed in zip(caches, seeds):
        data = load_seed(cache, args)
        out, pool = analyse_seed(data, seed)
        per_seed.append({"seed": seed, "cache": str(cache), **out})
        pooled.append(pool)
        if seed == seeds[0]:
            first = (data, pool)
        print(f"seed {seed}: {json.dumps(out['accuracy'], default=float)}", flush=True)
        print(f"  viewing angle: {json.dumps(out['viewing_angle'])}", flush=True)
        print(f"  silhouette: {json.dumps(out['silhouette'])}", flush=True)
        print(f"  confounds: {json.dumps(out['confounds'])}", flush=True)
    weights, diff = weight_maps(pooled)
    sheets(*first, Path(args.sheets), args.tag, diff)

    def mean_of(get):
        v = np.array([get(s) for s in per_seed], float)
        return {"mean": float(np.nanmean(v)), "std": float(np.nanstd(v)), "values": v.round(4).tolist()}

    summary = {k: mean_of(lambda s, k=k: s["accuracy"][k]) for k in per_seed[0]["accuracy"]}
    for key in per_seed[0]["viewing_angle"]:
        for m in ("hog_accuracy_matched", "hog_accuracy_unmatched_same_size"):
            summary[f"{key}: {m}"] = mean_of(lambda s, key=key, m=m: s["viewing_angle"][key][m])
    doc = {"tag": args.tag, "caches": [str(c) for c in caches], "stride": args.stride,
           "summary_over_seeds": summary, "per_seed": per_seed, "hog_weights_pooled": weights}
    out = Path(args.out) / f"diag_realism_hog_{args.tag}.json"
    write_json_atomic(out, doc)
    for k, v in summary.items():
        print(f"  {k:48s} {v['mean']:.3f} +- {v['std']:.3f}  {v['values']}")
    print(f"wrote {out}; sheets in {args.sheets}")


if __name__ == "__main__":
    main()
