"""Does a car's paint render at the level its colour and its light predict?  Issue #20's brightness diagnosis.

Usage::

    nice python benchmarks/diag_paint_level.py --paint white                     # F2F2EE, solid
    nice python benchmarks/diag_paint_level.py --paint silver --keyframes 0,20   # B5B8BB, metallic 0.7
    nice python benchmarks/diag_paint_level.py --paint silver --override '{"paint": {"metallic": 0.7, "flake": 0.35}}'

Procedural cars of one paint are inserted into real scene-0916 images through the pipeline's library API
(``insert_into_sample``, as ``bench_realism.py``); every ``render_insertion`` call is captured (its light,
asset, pose and result).  Per car, camera rays through its pixels find the material and face normal under
each fully visible pixel; per region (paint facing sideways ``side``, up ``top``; ``lower`` paint; glass;
tyres) it prints the mean rendered radiance (before the veil, blur and noise), what a Lambertian of the
region's base colour predicts from the car's own environment (``a (E(n) + sun) / pi``, ``E`` the envmap's
irradiance at the pixel's normal), both through the camera response (8-bit LDR), the final composite's LDR
and CIELAB; the material shares and L* of the lowest 30 % of the car's rows; and over the whole car, every material's
share of its pixels, its L* and its share of the dark pixels (L* < ``DARK_L``), with the car's L* spread.  ``--override`` replaces
material fields by name (e.g. the previous paint model) to compare.  Pictures are written nowhere (the
images are shared data); ``--out`` gets the per-car JSON (default under /tmp).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
PAINTS_SRGB = {"white": ("F2F2EE", 0.0), "silver": ("B5B8BB", 0.7), "black": ("0C0C0D", 0.0),
               "graphite": ("3C3F44", 0.6)}
DARK_L = 15.0  # L* under which a car pixel counts as dark (the real cars' 5th percentile is ~15-22)
REGIONS = ("side", "top", "lower", "glass", "tyre")


def _paint(name: str) -> tuple[float, float, float, float]:
    from streetaug.augment.assets.procedural import srgb_to_linear

    hexcode, metallic = PAINTS_SRGB[name]
    rgb = srgb_to_linear(np.array([int(hexcode[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)
    return (*rgb.tolist(), metallic)


def _overridden(asset, override: dict):
    mats = tuple(dataclasses.replace(m, **override[m.name]) if m.name in override else m for m in asset.materials)
    return dataclasses.replace(asset, materials=mats)


def pixel_hits(prep, K: np.ndarray, T: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The asset's surface seen through pixel centres (ys, xs) (N,) of a camera K, object pose T (cam <- object):
    its material index (N,) (-1: no hit) and object-frame face normal (N, 3) (0 where no hit)."""
    rays = np.stack([(xs + 0.5 - K[0, 2]) / K[0, 0], (ys + 0.5 - K[1, 2]) / K[1, 1], np.ones(len(xs))], 1)
    R, t = T[:3, :3], T[:3, 3]
    hits = prep.scene.intersect(np.tile(-R.T @ t, (len(xs), 1)), rays @ R)
    face = np.where(hits.hit, hits.face, 0)
    return (np.where(hits.hit, prep.face_material[face], -1),
            np.where(hits.hit[:, None], prep.face_normal[face], 0.0))


def car_regions(cap: dict) -> dict | None:
    """Per-region statistics of one captured insertion (see the module docstring), or None when too small."""
    from streetaug.augment.core import hdr_to_ldr
    from streetaug.augment.evaluation.realism import srgb_to_lab
    from streetaug.augment.render.environment import environment_tables
    from streetaug.augment.render.sampling import lookup_irradiance
    from streetaug.augment.render.surface import prepare_asset

    ins, K, T, light, ev = cap["ins"], cap["K"], cap["T"], cap["light"], cap["ev"]
    if ins.coverage_px < 300 or ins.footprint is None or ins.footprint.object_box is None:
        return None
    prep = prepare_asset(cap["asset"])
    names = [m.name for m in prep.asset.materials]
    box = ins.footprint.object_box
    ys, xs = np.mgrid[box.slices]
    ys, xs = ys.ravel(), xs.ravel()
    mat, n_obj = pixel_hits(prep, K, T, ys, xs)
    hit = mat >= 0
    R, t = T[:3, :3], T[:3, 3]
    env = environment_tables(light.envmap)
    final = ins.image[ys, xs]
    rad = ins.object_radiance[ys, xs].astype(np.float64)
    vis = ins.mask[ys, xs] > 0.99
    glass = [names.index(n) for n in ("glass", "glass_rear") if n in names]
    sel_of = {"side": (mat == names.index("paint")) & (np.abs(n_obj[:, 2]) < 0.35),
              "top": (mat == names.index("paint")) & (n_obj[:, 2] > 0.8),
              "lower": (mat == names.index("paint_lower")) & (np.abs(n_obj[:, 2]) < 0.5) if "paint_lower" in names
              else np.zeros(len(mat), bool),
              "glass": np.isin(mat, glass), "tyre": mat == names.index("tyre")}
    out = {"distance_m": float(np.linalg.norm(t)), "visible_px": float(ins.visible_px)}
    for region, sel in sel_of.items():
        sel = sel & vis
        if sel.sum() < 20:
            continue
        n_cam = n_obj[sel] @ R.T
        E = lookup_irradiance(env.irradiance, n_cam)
        if light.sun is not None:
            E = E + np.clip(n_cam @ light.sun.direction, 0, None)[:, None] * np.asarray(light.sun.irradiance_rgb)[None]
        albedo = prep.base_color[mat[sel]]
        pred = (albedo * E / np.pi).mean(axis=0)
        mean_rad = rad[sel].mean(axis=0)
        out[region] = {"n_px": int(sel.sum()), "radiance": mean_rad.tolist(), "lambert_radiance": pred.tolist(),
                       "irradiance_over_pi": (E.mean(axis=0) / np.pi).tolist(),
                       "ldr_rendered": (255 * hdr_to_ldr(mean_rad, ev)).tolist(),
                       "ldr_lambert": (255 * hdr_to_ldr(pred, ev)).tolist(),
                       "ldr_final": final[sel].mean(axis=0).tolist(),
                       "lab_final": srgb_to_lab(final[sel][None])[0].mean(axis=0).tolist()}
    L_all = srgb_to_lab(final[None])[0][:, 0]
    seen = vis & hit
    if seen.sum() >= 20:  # every material's share of the car's pixels, its L* (median, mean) and the car's L* spread
        out["materials"] = {names[m]: [float(np.mean(mat[seen] == m)), float(np.median(L_all[seen & (mat == m)])),
                                       float(L_all[seen & (mat == m)].mean()),
                                       float(np.mean(seen[seen] & (mat[seen] == m) & (L_all[seen] < DARK_L)))]
                            for m in np.unique(mat[seen])}
        out["car_L_std"] = float(L_all[seen].std())
    rows = ys[vis & hit]
    if len(rows):
        y0, y1 = rows.min(), rows.max()
        band = vis & hit & (ys >= y0 + 0.7 * (y1 - y0))
        L = srgb_to_lab(final[None])[0][:, 0]
        out["bottom_band"] = {names[m]: [float(np.mean(mat[band] == m)), float(np.median(L[band & (mat == m)]))]
                              for m in np.unique(mat[band])}
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--paint", default="white", choices=sorted(PAINTS_SRGB))
    p.add_argument("--keyframes", default="0,12,24,36", help="Keyframe indices of the scene.")
    p.add_argument("--cameras", default="CAM_FRONT,CAM_BACK,CAM_FRONT_LEFT,CAM_BACK_RIGHT")
    p.add_argument("--override", default="{}", help='JSON {material name: {field: value}} applied to every car.')
    p.add_argument("--dataroot", default=str(SEQ))
    p.add_argument("--version", default="v1.0-mini")
    p.add_argument("--out", default="/tmp/diag_paint_level.json")
    args = p.parse_args(argv)

    import streetaug.augment.pipeline as pipeline
    import streetaug.augment.pipeline.objects as pipeline_objects
    from streetaug.augment.assets.procedural import procedural_car
    from streetaug.datasets.nuscenes import NuScenesReader

    captured: list[dict] = []
    render = pipeline_objects.render_insertion

    def capture(image, K, depth_m, light, asset, T, **kw):
        ins = render(image, K, depth_m, light, asset, T, **kw)
        captured.append(dict(K=K, light=light, asset=asset, T=T, ins=ins, ev=kw.get("ev", 0.0)))
        return ins

    pipeline_objects.render_insertion = capture
    override = json.loads(args.override)
    reader = NuScenesReader(args.dataroot, args.version)
    tokens = reader.sample_tokens()
    cams = args.cameras.split(",")
    cars = []
    for k in (int(x) for x in args.keyframes.split(",")):
        sample = reader.sample(tokens[k])
        assets = {c: [_overridden(procedural_car(1000 * k + 10 * j + i, paint=_paint(args.paint)), override)
                      for i in range(3)] for j, c in enumerate(cams)}
        captured.clear()
        pipeline.insert_into_sample(sample, [sample.cameras[c] for c in cams], assets,
                                    pipeline.InsertOptions(seed=0, n_objects=3))
        cars += [r | {"keyframe": k} for r in map(car_regions, captured) if r is not None]
    print(f"{args.paint} ({len(cars)} cars, override {override}): medians over cars")
    for region in REGIONS:
        have = [c[region] for c in cars if region in c]
        if have:
            med = {key: np.round(np.median([h[key] for h in have], axis=0), 3).tolist()
                   for key in ("radiance", "lambert_radiance", "ldr_rendered", "ldr_lambert", "ldr_final", "lab_final")}
            print(f"  {region:6s} {med}")
    shares = defaultdict(list)
    for c in cars:
        for name, (share, L) in c.get("bottom_band", {}).items():
            shares[name].append((share, L))
    print("  lowest 30 % of the rows (share, L* median):",
          {n: (round(float(np.mean([s for s, _ in v])), 3), round(float(np.median([L for _, L in v])), 1))
           for n, v in sorted(shares.items(), key=lambda kv: -np.mean([s for s, _ in kv[1]]))})
    mats = defaultdict(list)
    for c in cars:
        for name, v in c.get("materials", {}).items():
            mats[name].append(v)
    print("  car L* std (median over cars):", round(float(np.median([c["car_L_std"] for c in cars if "car_L_std" in c])), 2))
    print("  materials (mean share of the car's pixels, L* median of the per-car medians):",
          {n: (round(float(np.sum([s for s, *_ in v]) / len(cars)), 3), round(float(np.median([L for _, L, *_ in v])), 1))
           for n, v in sorted(mats.items(), key=lambda kv: -np.sum([s for s, *_ in kv[1]]))})
    print(f"  dark pixels (L* < {DARK_L:.0f}) per material, mean share of the car's pixels:",
          {n: round(float(np.sum([x[3] for x in v]) / len(cars)), 4)
           for n, v in sorted(mats.items(), key=lambda kv: -np.sum([x[3] for x in kv[1]])) if np.sum([x[3] for x in v]) > 0})
    Path(args.out).write_text(json.dumps({"paint": args.paint, "override": override, "cars": cars}, default=float))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
