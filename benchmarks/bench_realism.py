"""Realism check: inserted cars against real annotated cars of the same size in the same real images.

Usage::

    nice python benchmarks/bench_realism.py --tag after                       # the code of this checkout
    nice python benchmarks/bench_realism.py --tag before --code-root /tmp/realism_before   # another checkout
    nice python benchmarks/bench_realism.py --tag s8 --stride 4 --n-objects 6 --seeds 0,1,2  # mean +- std over seeds

Data: ``../shared/data/nuscenes-seq`` (scene-0916, 41 keyframes x 6 cameras). Every ``--stride``-th keyframe,
all 6 cameras: ``--n-objects`` procedural cars per camera are inserted by the pipeline's library API (what
``streetaug insert`` calls: ``insert_into_sample`` with the CLI's asset choice, default preset, seeded).

Cars compared (:mod:`streetaug.augment.evaluation.realism`): real annotated ``vehicle.car`` boxes at 10-40 m,
visibility token 4 (80-100 %), the projected box inside the image and not covered by a nearer box; inserted
cars at 10-40 m, inside the image (truncation 0), visible fraction >= 0.8. Both sets are subsampled to the
same distribution of projected box height (px bins), at most ``--max-per-class`` each. Crops are the
projected 3D box plus a margin that includes the ground under it; real crops come from the original image,
inserted ones from the augmented image of the same camera.

Reports per-feature gaps (inserted median vs real median, standardised mean difference) and a real-vs-inserted
logistic regression on HOG + Lab histogram + scalar features, 5-fold cross-validated grouped by keyframe
(0.5 = indistinguishable). With some tens of cars per set one run's accuracy moves by about +- 0.1 with the
insertion seed: ``--seeds`` runs several and reports their mean and spread. Placement diagnostics (not
classifier features: :func:`car_placement`): each car's zone against the map's road edge, its heading against
the edge and the camera ray, its distance, the road's share of its crop. Writes ``benchmarks/results/realism_<tag>.json`` and crop sheets
``/tmp/realism/sheet_<tag>_*.png`` (real images: never commit them).

Another checkout (``--code-root``): the renders run in a subprocess that imports ``streetaug.*`` from that
checkout through a shim folder (``<cache>/shim/streetaug/{augment,cli,placement,datasets}`` symlinks and an
``__init__.py``) put first on ``sys.path``; a regular package on ``sys.path`` wins over the venv's editable
finder (which is appended to ``sys.meta_path``), the worker prints the imported file to prove it. Renders
are cached under ``--cache`` (default ``/tmp/realism/cache_<tag>``), one PNG + labels JSON per image.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import inspect  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
VERSION = "v1.0-mini"
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
PACKAGES = ("augment", "cli", "placement", "datasets")


# ----------------------------------------------------------------------------- render worker (any checkout)

def make_shim(code_root: Path, cache: Path) -> Path:
    """A folder whose ``streetaug`` package is the checkout ``code_root`` (symlinks); returns the folder."""
    shim = cache / "shim"
    pkg = shim / "streetaug"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text("")
    for name in PACKAGES:
        link = pkg / name
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(code_root.resolve() / name)
    return shim


def keyframe_tokens(reader, stride: int) -> list[str]:
    return reader.sample_tokens()[::stride]


def render_worker(args) -> None:
    """Insert cars into every camera of every ``stride``-th keyframe with the imported code; cache the results."""
    if args.shim:
        sys.path.insert(0, args.shim)
    import cv2

    import streetaug.augment.pipeline as pipeline
    from streetaug.augment.assets.select import select_assets
    from streetaug.datasets.nuscenes import NuScenesReader

    print(f"render worker: streetaug.augment.pipeline from {Path(pipeline.__file__).parent}", flush=True)
    cache = Path(args.cache)
    reader = NuScenesReader(args.dataroot, args.version)
    cameras = args.cameras.split(",")
    options = pipeline.InsertOptions(quality=args.quality, seed=args.seed, n_objects=args.n_objects)
    for i, token in enumerate(keyframe_tokens(reader, args.stride)):
        done = cache / f"{token}.json"
        if done.exists():
            continue
        t0 = time.perf_counter()
        sample = reader.sample(token)
        views = [sample.cameras[c] for c in cameras]
        # Older checkouts (--code-root) have no location argument: their cars have no plates; nor the scene's
        # paint mix (the CLI's and the batch's: scene_paint_mix of the sample's own cars, here every camera).
        params = inspect.signature(select_assets).parameters
        where = {"location": sample.location} if "location" in params else {}
        if "paint_weights" in params:
            from streetaug.augment.assets.scene_paint import scene_paint_mix

            where["paint_weights"] = scene_paint_mix(sample, cameras)
        assets = {c: select_assets(pipeline.item_seed(args.seed, "asset", token, c), args.n_objects, **where)
                  for c in cameras}
        result = pipeline.insert_into_sample(sample, views, assets, options)
        doc = {}
        for c in cameras:
            r = result.views[c]
            cv2.imwrite(str(cache / f"{token}_{c}.png"), r.image[:, :, ::-1])
            doc[c] = r.objects
        done.write_text(json.dumps(doc, default=float))
        print(f"  keyframe {i * args.stride}: {sum(len(v) for v in doc.values())} labels, {time.perf_counter() - t0:.1f} s",
              flush=True)


def render(args, cache: Path) -> str:
    """Run the render worker in a subprocess with the code of ``args.code_root``; returns its git commit."""
    code_root = Path(args.code_root).resolve()
    cmd = [sys.executable, str(Path(__file__).resolve()), "--render-worker", "--cache", str(cache),
           "--stride", str(args.stride), "--n-objects", str(args.n_objects), "--seed", str(args.seed),
           "--quality", args.quality, "--dataroot", str(Path(args.dataroot).resolve()), "--version", args.version,
           "--cameras", args.cameras]
    if code_root != ROOT:
        cmd += ["--shim", str(make_shim(code_root, cache))]
    subprocess.run(cmd, check=True, cwd=str(cache))
    return subprocess.run(["git", "-C", str(code_root), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()



# ----------------------------------------------------------------------------- analysis (this checkout)

MIN_DIST_M, MAX_DIST_M = 10.0, 40.0
HEIGHT_BINS_PX = (30, 45, 60, 80, 110, 150, 220, 400)
MIN_INSERTED_VISIBLE = 0.8
MAX_COVER_BY_NEARER = 0.2


def _rect_overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Area of the intersection of rectangles a and b (x0, y0, x1, y1) over the area of a."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return max(w, 0.0) * max(h, 0.0) / max((a[2] - a[0]) * (a[3] - a[1]), 1e-9)


def image_cars(reader, sample, view, objects: list[dict]):
    """(real, inserted): lists of (T_cam_from_box, wlh) of the cars of one camera image that qualify, and
    ``others_real`` / ``others_all``: every box in front of the camera (ground statistics exclusion)."""
    from streetaug.augment.evaluation.realism import box_in_image, box_rect_px
    from streetaug.datasets.sample import Box

    K, W, H = view.K, view.width, view.height
    T_cam_from_global = view.T_cam_from_global

    def cam(box):
        return T_cam_from_global @ box.T_global_from_box

    real_all = [(cam(b), b.wlh, b) for b in sample.boxes]
    real_all = [r for r in real_all if r[0][2, 3] > 1.0]
    inserted_boxes = [Box(np.array(o["box_global"]["translation"]), np.array(o["box_global"]["size"]),
                          np.array(o["box_global"]["rotation"]), o["category"]) for o in objects]
    inserted_all = [(cam(b), b.wlh, o) for b, o in zip(inserted_boxes, objects)]
    rects = [(box_rect_px(K, T, wlh), np.linalg.norm(T[:3, 3])) for T, wlh, _ in real_all
             if np.all(np.asarray(T[:3, 3])[2] > 0)]

    def in_range(T):
        return MIN_DIST_M <= np.linalg.norm(T[:3, 3]) <= MAX_DIST_M

    real = []
    for T, wlh, b in real_all:
        if b.category != "vehicle.car" or not in_range(T) or not box_in_image(K, T, wlh, W, H):
            continue
        if reader.get("sample_annotation", b.token)["visibility_token"] != "4":
            continue
        rect, dist = box_rect_px(K, T, wlh), np.linalg.norm(T[:3, 3])
        if any(d < dist - 0.5 and _rect_overlap(rect, r) > MAX_COVER_BY_NEARER for r, d in rects):
            continue
        real.append((T, wlh))
    inserted = [(T, wlh) for T, wlh, o in inserted_all
                if o["category"] == "vehicle.car" and in_range(T) and box_in_image(K, T, wlh, W, H)
                and o["visible_fraction"] >= MIN_INSERTED_VISIBLE]
    others_real = [(T, wlh) for T, wlh, _ in real_all]
    others_all = others_real + [(T, wlh) for T, wlh, _ in inserted_all]
    return real, inserted, others_real, others_all


def _without(boxes, T):
    return [(T2, w2) for T2, w2 in boxes if not np.allclose(T2, T)]


PLACEMENT_DIAGNOSTICS = ("distance_m", "yaw_to_ray_deg", "yaw_to_edge_deg", "centre_edge_m", "footprint_min_edge_m",
                         "road_share")


def car_placement(zones, view, T_cam_from_box: np.ndarray, wlh: np.ndarray, crop, kerb_m: float) -> dict:
    """Where one car of the check stands (diagnostics, not classifier features), measured with the placement
    package's own map functions (:class:`~streetaug.placement.zones.SurfaceZones` of the camera):

    zone (``lane``: footprint on the road, farther than ``kerb_m`` from its edge; ``kerb``: on the road within
    ``kerb_m``; ``edge``: centre on the road, footprint across the edge; ``off_road``: centre off it),
    ``centre_edge_m`` / ``footprint_min_edge_m`` the signed distance (m, + on the road) of the footprint's
    centre / its most off-road corner to the road edge, ``yaw_to_edge_deg`` (0..90) the heading against the
    road edge's direction, ``yaw_to_ray_deg`` (0 end-on .. 90 side-on), ``distance_m`` camera to box centre,
    ``road_share`` the fraction of the crop outside the car's (and other cars') hulls whose ray meets the
    ground on the map's drivable area (sky and off-road ground are not road).
    """
    from streetaug.augment.evaluation.realism import ground_points_box, yaw_to_ray_deg
    from streetaug.placement.rules import footprint_corners

    T_gb = view.T_global_from_cam @ T_cam_from_box
    centre = T_gb[:2, 3]
    yaw = float(np.arctan2(T_gb[1, 0], T_gb[0, 0]))
    fp = footprint_corners(centre[None], np.array([yaw]), float(wlh[1]), float(wlh[0]))
    sd = zones.signed_distance(fp[0])
    area = zones.drivable
    if area.contains_footprints(fp)[0]:
        zone = "kerb" if area.edge_distance(fp)[0] <= kerb_m else "lane"
    else:
        zone = "edge" if zones.signed_distance(centre[None])[0] > 0 else "off_road"
    tangent = zones.edge_tangent(centre[None])[0]
    yaw_to_edge = np.degrees(np.arccos(np.clip(abs(np.cos(yaw) * tangent[0] + np.sin(yaw) * tangent[1]), 0, 1)))
    hit_box = ground_points_box(view.K, T_cam_from_box, wlh, crop.window)  # (h, w, 2) box x/y on its bottom plane
    free = ~(crop.car_mask | crop.exclude_mask)
    ok = free & np.isfinite(hit_box[..., 0])
    pts = np.c_[hit_box[ok], np.full(ok.sum(), -0.5 * wlh[2]), np.ones(ok.sum())] @ T_gb.T
    road = area.contains_points(pts[:, :2]).sum() if len(pts) else 0
    return {"zone": zone, "distance_m": float(crop.distance_m), "yaw_to_ray_deg": yaw_to_ray_deg(T_cam_from_box),
            "yaw_to_edge_deg": float(yaw_to_edge), "centre_edge_m": float(zones.signed_distance(centre[None])[0]),
            "footprint_min_edge_m": float(sd.min()), "road_share": float(road / max(free.sum(), 1))}


def collect_crops(cache: Path, args):
    """Crops of every qualifying car of the cached images: (crops, labels 0 real / 1 inserted, keyframe ids,
    image ids, placement diagnostics per crop (:func:`car_placement`))."""
    import cv2

    from streetaug.augment.evaluation.realism import extract_crop
    from streetaug.datasets.nuscenes import NuScenesReader
    from streetaug.placement import PlacementConfig, drivable_area_for_sample
    from streetaug.placement.zones import surface_zones

    reader = NuScenesReader(args.dataroot, args.version)
    config = PlacementConfig()
    crops, labels, keyframes, images, places = [], [], [], [], []
    for token in keyframe_tokens(reader, args.stride):
        doc = json.loads((cache / f"{token}.json").read_text())
        sample = reader.sample(token)
        for c in args.cameras.split(","):
            view = sample.cameras[c]
            real, inserted, others_real, others_all = image_cars(reader, sample, view, doc[c])
            original = view.image
            augmented = cv2.imread(str(cache / f"{token}_{c}.png"))[:, :, ::-1] if inserted else None
            drivable, _ = drivable_area_for_sample(sample, view, config)
            zones = surface_zones(sample, view, drivable, config) if drivable is not None else None
            for label, image, cars, others in ((0, original, real, others_real), (1, augmented, inserted, others_all)):
                for T, wlh in cars:
                    crop = extract_crop(image, view.K, T, wlh, _without(others, T))
                    crops.append(crop)
                    labels.append(label)
                    keyframes.append(token)
                    images.append(f"{token}_{c}")
                    places.append(car_placement(zones, view, T, wlh, crop, config.kerb_distance_m)
                                  if zones is not None else {"zone": "no_map"})
    return crops, np.array(labels), np.array(keyframes), np.array(images), places


def placement_summary(inserted: list[dict], real: list[dict]) -> dict:
    """Zone shares of each set and the gaps of the numeric placement diagnostics (:func:`feature_gaps`)."""
    from streetaug.augment.evaluation.realism import feature_gaps

    def shares(places):
        zones = [p["zone"] for p in places]
        return {z: zones.count(z) / max(len(zones), 1) for z in ("lane", "kerb", "edge", "off_road", "no_map")
                if z in zones}

    return {"zone_share": {"inserted": shares(inserted), "real": shares(real)},
            "gaps": feature_gaps([p for p in inserted if "distance_m" in p], [p for p in real if "distance_m" in p],
                                 PLACEMENT_DIAGNOSTICS)}


def crop_sheet(real, inserted, path: Path, row_h: int = 112, per_side: int = 4) -> None:
    """A sheet: each row ``per_side`` real crops | ``per_side`` inserted crops (sorted by box height)."""
    import cv2

    def tile(crop):
        h, w = crop.rgb.shape[:2]
        s = row_h / h
        img = cv2.resize(crop.rgb, (max(int(round(w * s)), 1), row_h), interpolation=cv2.INTER_AREA)
        img = img[:, : int(1.6 * row_h)]
        out = np.full((row_h, int(1.6 * row_h), 3), 40, np.uint8)
        out[:, : img.shape[1]] = img
        return out

    blank = np.full((row_h, int(1.6 * row_h), 3), 40, np.uint8)
    sep = np.full((row_h, 12, 3), (255, 0, 255), np.uint8)
    rows = []
    n_rows = int(np.ceil(max(len(real), len(inserted)) / per_side))
    for r in range(n_rows):
        left = [tile(c) for c in real[r * per_side:(r + 1) * per_side]]
        right = [tile(c) for c in inserted[r * per_side:(r + 1) * per_side]]
        left += [blank] * (per_side - len(left))
        right += [blank] * (per_side - len(right))
        rows.append(np.concatenate(left + [sep] + right, axis=1))
    if rows:
        path.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), np.concatenate(rows, axis=0)[:, :, ::-1])


def analyse(args, cache: Path, commit: str, render_s: float) -> dict:
    from streetaug.augment.core.io import write_json_atomic
    from streetaug.augment.evaluation.realism import (FEATURE_NAMES, classifier_accuracy, crop_descriptor,
                                                      crop_features, feature_gaps, size_matched)

    t0 = time.perf_counter()
    crops, labels, keyframes, images, places = collect_crops(cache, args)
    heights = np.array([c.box_height_px for c in crops])
    real_idx, ins_idx = np.flatnonzero(labels == 0), np.flatnonzero(labels == 1)
    rng = np.random.default_rng(args.seed)
    pick_r, pick_i = size_matched(heights[real_idx], heights[ins_idx], HEIGHT_BINS_PX, rng, args.max_per_class)
    chosen = np.concatenate([real_idx[pick_r], ins_idx[pick_i]])
    feats = [crop_features(crops[i]) for i in chosen]
    X = np.stack([crop_descriptor(crops[i], f) for i, f in zip(chosen, feats)])
    X_car = np.stack([crop_descriptor(crops[i], f, car_only=True) for i, f in zip(chosen, feats)])
    y = labels[chosen]
    n_hog = X.shape[1] - 24 - len(FEATURE_NAMES)
    # "car_only": the HOG of the box's hull alone (real cars are mostly parked on verges, inserted ones on
    # the road: the surroundings alone tell them apart)
    parts = {"all": (X, slice(None)), "hog": (X, slice(0, n_hog)), "lab_histogram": (X, slice(n_hog, n_hog + 24)),
             "scalar_features": (X, slice(n_hog + 24, None)), "all_car_only": (X_car, slice(None)),
             "hog_car_only": (X_car, slice(0, n_hog))}
    classifier = {}
    for name, (D, cols) in parts.items():
        by_keyframe = classifier_accuracy(D[:, cols], y, keyframes[chosen], seed=args.seed)
        seeds = [classifier_accuracy(D[:, cols], y, keyframes[chosen], seed=s)["accuracy_mean"] for s in range(5)]
        by_image = classifier_accuracy(D[:, cols], y, images[chosen], seed=args.seed)
        classifier[name] = {"grouped_by_keyframe": by_keyframe, "grouped_by_image": by_image,
                            "mean_over_5_fold_seeds": float(np.mean(seeds)), "std_over_5_fold_seeds": float(np.std(seeds))}
    n = len(pick_r)
    gaps = feature_gaps(feats[n:], feats[:n])
    bins = np.digitize(heights[chosen[:n]], HEIGHT_BINS_PX)
    placement = placement_summary([places[i] for i in chosen[n:]], [places[i] for i in chosen[:n]])
    doc = {
        "tag": args.tag, "commit": commit, "code_root": str(Path(args.code_root).resolve()),
        "data": f"{Path(args.dataroot).name} {args.version} ({args.cameras})", "stride": args.stride, "n_objects_per_camera": args.n_objects,
        "seed": args.seed, "quality": args.quality,
        "selection": {"distance_m": [MIN_DIST_M, MAX_DIST_M], "real_visibility_token": "4",
                      "inserted_min_visible_fraction": MIN_INSERTED_VISIBLE,
                      "max_cover_by_nearer_box": MAX_COVER_BY_NEARER, "height_bins_px": list(HEIGHT_BINS_PX)},
        "candidates": {"real": int(len(real_idx)), "inserted": int(len(ins_idx))},
        "matched_per_class": int(n),
        "matched_per_height_bin": {f"{HEIGHT_BINS_PX[k - 1]}-{HEIGHT_BINS_PX[k]}": int(np.sum(bins == k))
                                   for k in range(1, len(HEIGHT_BINS_PX))},
        "classifier": classifier,
        "feature_gaps": gaps,
        "placement_diagnostics": placement,
        "timing_s": {"render": render_s, "analysis": time.perf_counter() - t0},
    }
    out = Path(args.out) / f"realism_{args.tag}.json"
    write_json_atomic(out, doc)
    order_r = chosen[:n][np.argsort(heights[chosen[:n]])]
    order_i = chosen[n:][np.argsort(heights[chosen[n:]])]
    sheets = Path(args.sheets)
    for k in range(0, n, 24):
        crop_sheet([crops[i] for i in order_r[k:k + 24]], [crops[i] for i in order_i[k:k + 24]],
                   sheets / f"sheet_{args.tag}_{k // 24}.png")
    if args.figure:
        crop_sheet([crops[i] for i in order_r[::max(n // 8, 1)][:8]], [crops[i] for i in order_i[::max(n // 8, 1)][:8]],
                   Path(args.figure), row_h=120, per_side=4)
    acc = classifier["all"]["grouped_by_keyframe"]
    print(f"{args.tag} ({commit}): {n} real vs {n} inserted cars (of {len(real_idx)} / {len(ins_idx)}); "
          f"classifier accuracy {acc['accuracy_mean']:.3f} +- {acc['accuracy_std']:.3f} (grouped by keyframe; "
          f"0.5 = indistinguishable)")
    for name, c in classifier.items():
        print(f"  {name:16s} keyframe-grouped {c['grouped_by_keyframe']['accuracy_mean']:.3f} +- "
              f"{c['grouped_by_keyframe']['accuracy_std']:.3f}, 5 seeds {c['mean_over_5_fold_seeds']:.3f}, "
              f"image-grouped {c['grouped_by_image']['accuracy_mean']:.3f}")
    print(f"  {'feature':20s} {'inserted':>9s} {'real':>9s} {'d':>6s}")
    for name, g in gaps.items():
        print(f"  {name:20s} {g['inserted_median']:9.3f} {g['real_median']:9.3f} {g['standardised_gap']:6.2f}")
    print(f"  placement (diagnostics, not classifier features): zones inserted {placement['zone_share']['inserted']}, "
          f"real {placement['zone_share']['real']}")
    for name, g in placement["gaps"].items():
        print(f"  {name:20s} {g['inserted_median']:9.3f} {g['real_median']:9.3f} {g['standardised_gap']:6.2f}")
    print(f"wrote {out}, sheets {sheets}/sheet_{args.tag}_*.png")
    return doc


# ----------------------------------------------------------------------------- main

def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tag", default="after", help="Name of this run (results/realism_<tag>.json).")
    p.add_argument("--code-root", default=str(ROOT), help="Checkout whose code renders the inserted cars.")
    p.add_argument("--cache", default=None, help="Render cache folder (default /tmp/realism/cache_<tag>).")
    p.add_argument("--stride", type=int, default=3, help="Every stride-th keyframe.")
    p.add_argument("--n-objects", type=int, default=3, help="Cars inserted per camera.")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", default=None,
                   help="Comma-separated seeds: one run per seed (tag <tag>_seed<s>, its own cache), and a summary "
                        "realism_<tag>.json with the mean and spread over the seeds.")
    p.add_argument("--quality", default="default")
    p.add_argument("--max-per-class", type=int, default=60)
    p.add_argument("--render-only", action="store_true")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--sheets", default="/tmp/realism")
    p.add_argument("--dataroot", default=str(SEQ), help="nuScenes dataroot (default the real dev scene).")
    p.add_argument("--version", default=VERSION)
    p.add_argument("--cameras", default=",".join(CAMERAS), help="Comma-separated camera channels.")
    p.add_argument("--figure", default=None,
                   help="Also write one sheet (8 scene cars | 8 inserted, spread over the sizes) to this path; into "
                        "the repository only from data inside it (the bundled scenes): pictures of other data are "
                        "never committed.")
    p.add_argument("--render-worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--shim", default=None, help=argparse.SUPPRESS)
    return p.parse_args(argv)


def main(argv=None) -> None:
    args = parse_args(argv)
    if args.figure and Path(args.figure).resolve().is_relative_to(ROOT) \
            and not Path(args.dataroot).resolve().is_relative_to(ROOT):
        raise SystemExit(f"--figure {args.figure}: a picture of {args.dataroot} (outside the repository) would be "
                         f"committed; write it outside the repository, or use the bundled scenes")
    if args.render_worker:
        render_worker(args)
        return
    if args.seeds:
        docs = [run_one(argparse.Namespace(**{**vars(args), "seed": int(s), "tag": f"{args.tag}_seed{int(s)}",
                                              "cache": None}))
                for s in args.seeds.split(",")]
        if not args.render_only:
            summarise_seeds(args, docs)
        return
    run_one(args)


def run_one(args) -> dict | None:
    """Render (cached) and analyse one seed; the result document (None with ``--render-only``)."""
    cache = Path(args.cache or f"/tmp/realism/cache_{args.tag}")
    cache.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    commit = render(args, cache)
    render_s = time.perf_counter() - t0
    if args.render_only:
        return None
    return analyse(args, cache, commit, render_s)


def summarise_seeds(args, docs: list[dict]) -> dict:
    """``realism_<tag>.json``: per seed the classifier accuracy (keyframe-grouped), the counts and the zone shares;
    over the seeds the mean and standard deviation of the accuracies and of every gap."""
    from streetaug.augment.core.io import write_json_atomic

    def spread(values):
        v = np.asarray(values, float)
        return {"mean": float(np.nanmean(v)), "std": float(np.nanstd(v)), "values": v.tolist()}

    acc = {name: spread([d["classifier"][name]["grouped_by_keyframe"]["accuracy_mean"] for d in docs])
           for name in docs[0]["classifier"]}
    gaps = {name: {"standardised_gap": spread([d["feature_gaps"][name]["standardised_gap"] for d in docs]),
                   "inserted_median": spread([d["feature_gaps"][name]["inserted_median"] for d in docs]),
                   "real_median": spread([d["feature_gaps"][name]["real_median"] for d in docs])}
            for name in docs[0]["feature_gaps"]}
    place = {name: {"standardised_gap": spread([d["placement_diagnostics"]["gaps"][name]["standardised_gap"]
                                                for d in docs]),
                    "inserted_median": spread([d["placement_diagnostics"]["gaps"][name]["inserted_median"]
                                               for d in docs]),
                    "real_median": spread([d["placement_diagnostics"]["gaps"][name]["real_median"] for d in docs])}
             for name in docs[0]["placement_diagnostics"]["gaps"]}
    doc = {"tag": args.tag, "commit": docs[0]["commit"], "code_root": docs[0]["code_root"], "stride": args.stride,
           "n_objects_per_camera": args.n_objects, "seeds": [d["seed"] for d in docs],
           "per_seed": [{"seed": d["seed"], "tag": d["tag"], "candidates": d["candidates"],
                         "matched_per_class": d["matched_per_class"],
                         "accuracy": d["classifier"]["all"]["grouped_by_keyframe"]["accuracy_mean"],
                         "zone_share": d["placement_diagnostics"]["zone_share"]} for d in docs],
           "classifier_accuracy_over_seeds": acc, "feature_gaps_over_seeds": gaps,
           "placement_diagnostics_over_seeds": place}
    out = Path(args.out) / f"realism_{args.tag}.json"
    write_json_atomic(out, doc)
    a = acc["all"]
    print(f"{args.tag}: classifier accuracy over seeds {doc['seeds']}: {a['mean']:.3f} +- {a['std']:.3f} "
          f"({', '.join(f'{v:.3f}' for v in a['values'])}); matched "
          f"{[d['matched_per_class'] for d in docs]}; wrote {out}")
    return doc


if __name__ == "__main__":
    main()
