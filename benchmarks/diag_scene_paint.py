"""Does the paint band measure a car's albedo?  Issue #20's paint-mix-from-the-scene check.

Usage::

    nice python benchmarks/diag_scene_paint.py --cache /tmp/realism/cache_s10_before_seed0 --seed 0 --n-objects 6

Reads a ``bench_realism`` render cache (the inserted cars' labels and augmented images of every 4th keyframe of
scene-0916) and, per car, measures :func:`~streetaug.augment.assets.scene_paint.paint_band_rgb` / the image's
reference level (:func:`~streetaug.augment.assets.scene_paint.image_reference_level`):

* inserted cars (their paint is known: the assets ``select_assets`` drew for the image, by ``object_index``):
  the ratio of the paint's albedo (luminance) to the band's ratio, i.e. what ``ALBEDO_PER_RATIO`` should be,
  per paint family, and the estimate's rank correlation with the true albedo;
* the annotated cars of the same images (:func:`~streetaug.augment.assets.scene_paint.sample_car_ratios`):
  their estimated albedo distribution, and the family shares of the palette before (the region's table) and
  after (:func:`~streetaug.augment.assets.scene_paint.scene_paint_weights` over every sample's cars).

Nothing is written but the optional ``--out`` JSON (no pictures: shared data).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()


def family_shares(weights: np.ndarray, region: str) -> dict[str, float]:
    from streetaug.augment.assets.car_paint import paint_family, paint_palette

    out: dict[str, float] = {}
    for (name, *_), w in zip(paint_palette(region), weights):
        out[paint_family(name)] = out.get(paint_family(name), 0.0) + float(w)
    return {k: round(v, 3) for k, v in out.items()}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cache", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-objects", type=int, default=6)
    p.add_argument("--stride", type=int, default=4)
    p.add_argument("--dataroot", default=str(SEQ))
    p.add_argument("--version", default="v1.0-mini")
    p.add_argument("--scene-paint", action="store_true",
                   help="The cache's cars were drawn with the sample's own paint mix (a checkout with scene_paint).")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)

    import cv2

    import streetaug.augment.pipeline as pipeline
    from streetaug.augment.assets.car_paint import paint_family, paint_palette, paint_region_for_location
    from streetaug.augment.assets.scene_paint import (_box_rect, band_ratio, image_reference_level,
                                                      paint_band_rgb, sample_car_ratios, scene_paint_weights)
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.core import luminance, make_transform
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(args.dataroot, args.version)

    from streetaug.augment.assets.scene_paint import scene_paint_mix

    mixes_of: dict = {}

    def assets_of(token, channel, location):
        paint = None
        if args.scene_paint:  # the cache was rendered with the sample's own paint mix (bench_realism's worker)
            if token not in mixes_of:
                mixes_of[token] = scene_paint_mix(reader.sample(token), list(doc))
            paint = mixes_of[token]
        return select_assets(pipeline.item_seed(args.seed, "asset", token, channel), args.n_objects, location=location,
                             paint_weights=paint)

    cache = Path(args.cache)
    ins_rows, real_all, per_sample = [], [], []
    region = None
    for token in reader.sample_tokens()[:: args.stride]:
        if not (cache / f"{token}.json").exists():
            continue  # not rendered (yet)
        doc = json.loads((cache / f"{token}.json").read_text())
        sample = reader.sample(token)
        region = paint_region_for_location(sample.location)
        albedos = sample_car_ratios(sample)
        real_all += albedos
        per_sample.append(albedos)
        for c, objects in doc.items():
            view = sample.cameras[c]
            image = cv2.imread(str(cache / f"{token}_{c}.png"))[:, :, ::-1]
            ref = image_reference_level(image)
            T_cg = view.T_cam_from_global
            boxes = [(T_cg @ b.T_global_from_box, b.wlh) for b in sample.boxes]
            for o in objects:
                if o["category"] != "vehicle.car":
                    continue
                g = o["box_global"]
                T = T_cg @ make_transform(np.array(g["rotation"]), np.array(g["translation"]))
                d = np.linalg.norm(T[:3, 3])
                if T[2, 3] < 1.0 or d > 45:
                    continue
                others = boxes + [(T_cg @ make_transform(np.array(q["box_global"]["rotation"]),
                                                          np.array(q["box_global"]["translation"])),
                                   np.array(q["box_global"]["size"])) for q in objects if q is not o]
                nearer = [_box_rect(view.K, T2, w2) for T2, w2 in others
                          if T2[2, 3] > 1.0 and np.linalg.norm(T2[:3, 3]) < d - 0.5]
                band = paint_band_rgb(image, view.K, T, np.array(g["size"]), nearer)
                est = band_ratio(band, ref)
                if est is None:
                    continue
                # the asset: the one of its camera's draw whose box is this label's (labels carry no asset index)
                drawn = assets_of(token, o["placed_for"], sample.location)
                asset = min(drawn, key=lambda q: float(np.abs(q.wlh - np.array(g["size"])).sum()))
                paint = asset.materials[0]
                family = paint_family(asset.name.split("-")[-1].replace("_", " "))
                ins_rows.append({"family": family, "ratio": est.tolist(), "albedo": float(luminance(paint.base_color)),
                                 "estimate": float(luminance(est)), "distance_m": float(d), "n_px": len(band)})
    a = np.array([r["albedo"] for r in ins_rows])
    e = np.array([r["estimate"] for r in ins_rows])
    from scipy.stats import spearmanr

    fit = np.polyfit(a, e, 1)
    print(f"inserted cars measured: {len(ins_rows)}; spearman(albedo, band ratio) {spearmanr(a, e)[0]:.3f}; "
          f"least-squares ratio = {fit[1]:.3f} + {fit[0]:.3f} albedo (REFLECTED_RATIO, LIT_RATIO)")
    for fam in sorted({r["family"] for r in ins_rows}):
        s = np.array([r["family"] == fam for r in ins_rows])
        print(f"  {fam:7s} n={s.sum():3d} albedo {np.median(a[s]):.3f} estimate median {np.median(e[s]):.3f} "
              f"(p25 {np.percentile(e[s], 25):.3f}, p75 {np.percentile(e[s], 75):.3f})")
    # Each inserted car's most probable family by its band (car_shade_posterior) against its true paint family.
    from streetaug.augment.assets.scene_paint import car_shade_posterior

    fams = [paint_family(q[0]) for q in paint_palette(region)]
    order = sorted(set(fams), key=fams.index)
    confusion: dict = {}
    for row in ins_rows:
        post = car_shade_posterior(np.array(row["ratio"]), region)
        if post is None:
            continue
        by_family = {f: float(sum(w for w, g in zip(post, fams) if g == f)) for f in order}
        guess = max(by_family, key=by_family.get)
        confusion.setdefault(row["family"], {}).setdefault(guess, 0)
        confusion[row["family"]][guess] += 1
    hits = sum(c.get(f, 0) for f, c in confusion.items())
    print(f"inserted cars' family from their band: {hits} / {sum(sum(c.values()) for c in confusion.values())} "
          f"right; true -> guessed: {confusion}")
    r = np.array([float(luminance(x)) for x in real_all])
    print(f"real cars measured: {len(r)}; band ratio percentiles 10/25/50/75/90: "
          f"{np.round(np.percentile(r, [10, 25, 50, 75, 90]), 3).tolist()}")
    prior = np.array([q[3] for q in paint_palette(region)])
    mixes = np.array([scene_paint_weights(al, region) for al in per_sample])
    print(f"family shares, region {region}: {family_shares(prior / prior.sum(), region)}")
    print(f"family shares, mean of the samples' scene mixes: {family_shares(mixes.mean(axis=0), region)}")
    print(f"  cars per sample: {[len(al) for al in per_sample]}")
    if args.out:
        Path(args.out).write_text(json.dumps({"inserted": ins_rows, "real_albedo": r.tolist()}))


if __name__ == "__main__":
    main()
