"""Every nuScenes detection class (issue 18), measured: placement, box-vs-pixels containment, time, sizes.

Usage: ``python benchmarks/bench_classes.py [--seeds 2] [--seeds-small 6] [--render-real 6] [--render-bundled 4]
[--size-seeds 200] [--sheets] [--out benchmarks/results/classes.json]``

Per detection class (:data:`streetaug.augment.assets.classes.DETECTION_CLASSES`):

1. placement: one object of the class per attempt (``procedural_object(class, seed)``: the category, variant
   and size drawn from the class-sizes table) placed with ``place_objects`` (scene depth computed once per
   view), on

   * ``real-seq``: every 4th keyframe of scene-0916 (``../shared/data/nuscenes-seq``), CAM_FRONT and CAM_BACK,
     ``--seeds`` attempts per view;
   * ``real``: ``../shared/data/nuscenes-real`` (one keyframe, every camera), ``--seeds-small`` per view;
   * ``bundled``: every bundled sample, CAM_FRONT, ``--seeds-small`` per view;

   measured: placed attempts / attempts, cluster members per placed leader, zones, rule violations (every
   placement re-checked by ``audit_placements``; the failing rules), the 3 most common reasons when not placed,
   and the wall time of ``place_objects``.
2. containment: up to ``--render-real`` placed objects per class on real data (and ``--render-bundled`` on the
   bundled scenes) rendered ONE per call (``insert_placed_into_sample``, quality ``default``, level ``auto``);
   the share of the object's alpha mass (``InsertResult.mask``) inside the convex hull of its projected 3D box
   (pixel centres; also with the hull grown by half a pixel). Target >= 99.5 %.
3. time: per insertion (the view's ``timing_s`` ``render`` and ``total``, and the sample's ``total``), medians;
   asset generation time per class, median over the first 10 seeds. Threads are pinned to 1 (env) before
   numpy is imported.
4. sizes: ``--size-seeds`` assets per class; generated ``wlh`` mean / std per category vs the table's
   ``mean_wlh`` / ``std_wlh`` (with ``n_instances`` and ``source``), and the share inside ``min..max``.

``--sheets``: contact sheets of the rendered crops (around the projected box, padded): real images to
``--real-sheet`` (default ``/tmp/classes_contact_sheet_real.png``: real nuScenes pictures never go into the
repository), bundled scenes to ``docs/classes_contact_sheet.png``. Real datasets absent -> their rows are skipped.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import shapely  # noqa: E402
from PIL import Image  # noqa: E402

from streetaug.augment.assets.class_sizes import read_class_sizes  # noqa: E402
from streetaug.augment.assets.classes import CLASS_CATEGORIES, DETECTION_CLASSES, procedural_object  # noqa: E402
from streetaug.augment.core import quat_to_rotation, transform_points  # noqa: E402
from streetaug.augment.pipeline import InsertOptions, item_seed, scene_depth_for_view  # noqa: E402
from streetaug.augment.pipeline.sample import insert_placed_into_sample  # noqa: E402
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402
from streetaug.placement.audit import audit_placements  # noqa: E402
from streetaug.placement.config import PlacementConfig  # noqa: E402
from streetaug.placement.place import place_objects  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
OPTIONS = InsertOptions(quality="default", level="auto", seed=0)
GEN_TIME_SEEDS = 10


@dataclasses.dataclass(frozen=True)
class ViewRef:
    """One camera of one sample of a dataset (the reader re-opens the sample when rendering)."""

    dataset: str
    reader: NuScenesReader
    token: str
    channel: str
    scene: str


def dataset_views(seq_stride: int) -> list[tuple[str, list[ViewRef]]]:
    """The views of each dataset (real ones only when present)."""
    out = []
    seq = SHARED / "nuscenes-seq"
    if (seq / "v1.0-mini" / "sample.json").is_file():
        r = NuScenesReader(seq, "v1.0-mini")
        tokens = r.sample_tokens("scene-0916")[::seq_stride]
        out.append(("real-seq", [ViewRef("real-seq", r, t, ch, "scene-0916") for t in tokens
                                 for ch in ("CAM_FRONT", "CAM_BACK")]))
    else:
        print(f"note: {seq} not found; real-seq rows skipped")
    real = SHARED / "nuscenes-real"
    if (real / "v1.0-mini" / "sample.json").is_file():
        r = NuScenesReader(real, "v1.0-mini")
        refs = []
        for t in r.sample_tokens():
            refs += [ViewRef("real", r, t, ch, r.sample(t).scene_name) for ch in sorted(r.sample(t).cameras)]
        out.append(("real", refs))
    else:
        print(f"note: {real} not found; real rows skipped")
    b = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    refs = []
    for scene in b.table("scene"):
        refs += [ViewRef("bundled", b, t, "CAM_FRONT", scene["name"]) for t in b.sample_tokens(scene["name"])]
    out.append(("bundled", refs))
    return out


def short_reason(text: str | None) -> str:
    """A reason without its numbers and parenthesised details, so that reasons can be counted."""
    if not text:
        return "no valid placement"
    text = text.split(" (")[0]
    return re.sub(r"\d+(\.\d+)?", "#", text)[:160]


def stats(values, q=(0, 50, 100)) -> dict:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if len(v) == 0:
        return {"n": 0}
    return {"n": int(len(v)), **{f"p{p}": round(float(np.percentile(v, p)), 6) for p in q}}


def asset_seed(cls_index: int, attempt: int) -> int:
    return 1000 * cls_index + attempt


def measure_placement(datasets, seeds: int, seeds_small: int, config: PlacementConfig) -> tuple[dict, list]:
    """Placement rows per dataset and class, and the placed objects (for rendering)."""
    rows: dict = {}
    placed_objects: list[dict] = []
    for ds_name, refs in datasets:
        n_seeds = seeds if ds_name == "real-seq" else seeds_small
        acc = {c: {"attempts": 0, "placed": 0, "leaders": 0, "members": 0, "zones": Counter(),
                   "violations": Counter(), "audited": 0, "not_ok": 0, "reasons": Counter(), "rejections": Counter(), "place_s": [],
                   "attributes": Counter()} for c in DETECTION_CLASSES}
        attempt_no = Counter()
        t_ds = time.perf_counter()
        for ref in refs:
            sample = ref.reader.sample(ref.token)
            view = sample.cameras[ref.channel]
            depth = scene_depth_for_view(sample, view)
            for ci, cls in enumerate(DETECTION_CLASSES):
                a = acc[cls]
                for s in range(n_seeds):
                    seed = asset_seed(ci, attempt_no[cls])
                    attempt_no[cls] += 1
                    asset = procedural_object(cls, seed)
                    rng = item_seed(s, ref.token, ref.channel, cls)
                    t0 = time.perf_counter()
                    res = place_objects(sample, view, [asset], rng, config, depth_m=depth)
                    a["place_s"].append(time.perf_counter() - t0)
                    a["attempts"] += 1
                    if not res.placements:
                        a["reasons"][short_reason(res.class_reasons.get(cls) or res.reason)] += 1
                        a["rejections"].update({k: v for k, v in res.report.items() if v})
                        continue
                    a["placed"] += 1
                    audits = audit_placements(sample, view, res.placements, res.drivable, res.config)
                    for i, (p, aud) in enumerate(zip(res.placements, audits)):
                        a["zones"][p.zone] += 1
                        a["attributes"][str(p.attribute)] += 1
                        a["leaders" if p.cluster_of < 0 else "members"] += 1
                        a["audited"] += 1
                        if not aud.ok:
                            a["not_ok"] += 1
                            for rule, ok in aud.passed.items():
                                if not ok:
                                    a["violations"][rule] += 1
                        if p.detection_class != cls:
                            a["violations"][f"detection_class={p.detection_class}"] += 1
                        placed_objects.append({"ref": ref, "cls": cls, "seed": seed, "placement": p,
                                               "index": i, "cluster_of": p.cluster_of})
        rows[ds_name] = {}
        for cls, a in acc.items():
            rows[ds_name][cls] = {
                "attempts": a["attempts"], "placed_attempts": a["placed"],
                "placement_rate": round(a["placed"] / a["attempts"], 4) if a["attempts"] else None,
                "placements": a["audited"], "leaders": a["leaders"], "cluster_members": a["members"],
                "members_per_leader": round(a["members"] / a["leaders"], 3) if a["leaders"] else None,
                "zones": dict(a["zones"]), "attributes": dict(a["attributes"]),
                "audit_not_ok": a["not_ok"], "violated_rules": dict(a["violations"]),
                "top_reasons_not_placed": a["reasons"].most_common(3),
                # candidates rejected per rule, summed over the attempts that placed nothing
                "rejected_by_rule_when_not_placed": dict(a["rejections"].most_common()),
                "place_objects_s": stats(a["place_s"], (50, 95)),
            }
        print(f"[placement] {ds_name}: {len(refs)} views x {n_seeds} seeds x {len(DETECTION_CLASSES)} classes "
              f"in {time.perf_counter() - t_ds:.0f} s")
    return rows, placed_objects


def pick_spread(items: list[dict], n: int) -> list[dict]:
    """Up to ``n`` of ``items``, leaders first, spread over the views (round robin)."""
    by_view: dict = defaultdict(list)
    for it in sorted(items, key=lambda it: it["cluster_of"] >= 0):
        by_view[(it["ref"].dataset, it["ref"].token, it["ref"].channel)].append(it)
    # round robin over the datasets first, then over their views
    rank = Counter()
    order = {}
    for k in by_view:  # the r-th view of each dataset, then the (r+1)-th, ...
        order[k] = (rank[k[0]], k[0])
        rank[k[0]] += 1
    queues = [by_view[k] for k in sorted(by_view, key=order.get)]
    out = []
    while len(out) < n and any(queues):
        for q in queues:
            if q and len(out) < n:
                out.append(q.pop(0))
    return out


def projected_hull(view, placement):
    """The convex hull (shapely) of the box's 8 corners in pixels, and whether every corner is in front."""
    corners_cam = transform_points(view.T_cam_from_global, placement.box.corners())
    if np.any(corners_cam[:, 2] < 0.1):
        return None, corners_cam
    uv = corners_cam @ view.K.T
    uv = uv[:, :2] / uv[:, 2:]
    return shapely.convex_hull(shapely.multipoints(uv)), uv


def lidar_ground_gap(sample, placement) -> tuple[float, int]:
    """Height (m) of the box's bottom centre above an independent LiDAR ground estimate there (median of the
    lowest points within 1 m of the footprint's corners and centre, outside annotated boxes), and the number of
    points used (only points from 1 m below to 0.5 m above the bottom); nan with fewer than 5. Positive = the object stands above the measured ground (floats)."""
    pts = sample.lidar.points_global
    foot = np.vstack([placement.footprint_xy, placement.footprint_xy.mean(axis=0)])
    near = np.min(np.linalg.norm(pts[None, :, :2] - foot[:, None, :], axis=2), axis=0) <= 1.0
    for b in sample.boxes:
        local = (pts[near] - b.center) @ quat_to_rotation(b.rotation)
        inside = np.all(np.abs(local) <= np.asarray(b.wlh)[[1, 0, 2]] / 2 + 0.2, axis=1)
        near[np.flatnonzero(near)[inside]] = False
    bottom_z = float(placement.T_global_from_object[2, 3])
    z = pts[near, 2]
    z = z[(z > bottom_z - 1.0) & (z < bottom_z + 0.5)]  # near the surface (no canopies, walls' tops, pits)
    if len(z) < 5:
        return float("nan"), int(len(z))
    low = z[z <= np.percentile(z, 20) + 0.05]
    return bottom_z - float(np.median(low)), int(len(z))


def render_one(item: dict) -> dict:
    """Insert one placed object alone into its view; containment of its alpha in its projected box."""
    ref, p = item["ref"], item["placement"]
    sample = ref.reader.sample(ref.token)
    view = sample.cameras[ref.channel]
    asset = procedural_object(item["cls"], item["seed"])
    p1 = dataclasses.replace(p, asset_index=0, cluster_of=-1)
    t0 = time.perf_counter()
    res = insert_placed_into_sample(sample, [view], [p1], [asset], OPTIONS)
    wall = time.perf_counter() - t0
    ins = res.views[ref.channel]
    alpha = np.asarray(ins.mask, dtype=np.float64)
    hull, uv = projected_hull(view, p)
    out = {"dataset": ref.dataset, "scene": ref.scene, "channel": ref.channel, "class": item["cls"],
           "category": asset.category, "attribute": p.attribute, "zone": p.zone, "seed": item["seed"],
           "ground_source": p.ground_source, "drivable_source": p.drivable_source, "asset": asset.name,
           "cluster_member": item["cluster_of"] >= 0, "distance_m": round(float(p.distance_m), 2),
           "render_s": ins.timing_s.get("render"), "view_total_s": ins.timing_s.get("total"),
           "sample_total_s": res.timing_s.get("total"), "wall_s": wall,
           "alpha_mass": float(alpha.sum())}
    vs, us = np.nonzero(alpha > 0)
    w = alpha[vs, us]
    if hull is None or w.sum() <= 0:
        out.update(contained=None, contained_grown=None)
    else:
        square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
        grown = shapely.convex_hull(shapely.multipoints((uv[:, None, :] + square[None]).reshape(-1, 2)))
        out["contained"] = float(w[shapely.contains_xy(hull, us, vs)].sum() / w.sum())
        out["contained_grown"] = float(w[shapely.contains_xy(grown, us, vs)].sum() / w.sum())
        if out["contained_grown"] < 0.995:
            outside = ~shapely.contains_xy(grown, us, vs)
            out["outside_px"] = int(outside.sum())
            out["outside_bbox_uv"] = [int(us[outside].min()), int(vs[outside].min()),
                                      int(us[outside].max()), int(vs[outside].max())]
    label = ins.objects[0] if ins.objects else {}
    out.update(visible_fraction_placement=round(float(p.visible_fraction), 4),
               visible_fraction_rendered=label.get("visible_fraction"))
    gap, n_pts = lidar_ground_gap(sample, p)
    out.update(lidar_ground_gap_m=round(gap, 3), lidar_ground_points=n_pts)
    out["crop"] = crop_of(ins.image, uv if hull is not None else None, alpha)
    return out


def crop_of(image: np.ndarray, uv, alpha: np.ndarray, pad: float = 0.35, min_px: int = 40) -> np.ndarray | None:
    """A padded crop (RGB uint8) around the projected box (or the alpha's extent), or None."""
    H, W = alpha.shape
    if uv is not None:
        x0, y0 = uv.min(axis=0)
        x1, y1 = uv.max(axis=0)
    else:
        vs, us = np.nonzero(alpha > 0.5)
        if len(us) == 0:
            return None
        x0, y0, x1, y1 = us.min(), vs.min(), us.max(), vs.max()
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    half = max((x1 - x0), (y1 - y0), min_px) * (0.5 + pad)
    hx = max(half, (x1 - x0) / 2 * (1 + 2 * pad))
    X0, X1 = int(np.clip(cx - hx, 0, W - 1)), int(np.clip(cx + hx, 1, W))
    Y0, Y1 = int(np.clip(cy - half, 0, H - 1)), int(np.clip(cy + half, 1, H))
    if X1 - X0 < 4 or Y1 - Y0 < 4:
        return None
    return np.ascontiguousarray(image[Y0:Y1, X0:X1])


def contact_sheet(crops_by_class: dict[str, list[np.ndarray]], height: int, per_row: int, label_w: int = 150):
    """Rows of crops (each resized to ``height`` px tall, at most 2.2 x as wide), a class label on the left."""
    rows = []
    for cls in DETECTION_CLASSES:
        tiles = []
        for c in crops_by_class.get(cls, [])[:per_row]:
            w = int(round(c.shape[1] * height / c.shape[0]))
            t = cv2.resize(c, (w, height), interpolation=cv2.INTER_AREA)
            maxw = int(2.2 * height)
            if w > maxw:
                t = t[:, (w - maxw) // 2:(w - maxw) // 2 + maxw]
            tiles.append(t)
            tiles.append(np.full((height, 4, 3), 255, np.uint8))
        label = np.full((height, label_w, 3), 255, np.uint8)
        cv2.putText(label, cls.replace("_", " "), (6, height // 2 + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.48,
                    (0, 0, 0), 1, cv2.LINE_AA)
        if not tiles:
            cv2.putText(label, "(none placed)", (6, height // 2 + 22), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        (120, 0, 0), 1, cv2.LINE_AA)
        rows.append(np.concatenate([label, *tiles], axis=1))
        rows.append(np.full((4, 1, 3), 255, np.uint8))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    return np.concatenate(rows, axis=0)


def write_sheet(path: Path, sheet: np.ndarray, palette: bool) -> None:
    """PNG of an (H, W, 3) uint8 RGB sheet; ``palette``: 256 colours (median cut), to keep a committed file small."""
    image = Image.fromarray(sheet)
    if palette:
        image = image.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    image.save(path, optimize=True)


def _f(x, spec: str = ".4f") -> str:
    return "n/a" if x is None or not np.isfinite(x) else format(x, spec)


def measure_rendering(placed: list[dict], n_real: int, n_bundled: int) -> tuple[dict, list[dict]]:
    renders = []
    for cls in DETECTION_CLASSES:
        real = [it for it in placed if it["cls"] == cls and it["ref"].dataset != "bundled"]
        bund = [it for it in placed if it["cls"] == cls and it["ref"].dataset == "bundled"]
        for it in pick_spread(real, n_real) + pick_spread(bund, n_bundled):
            r = render_one(it)
            renders.append(r)
            print(f"[render] {cls:20s} {r['dataset']:8s} {r['channel']:10s} d={r['distance_m']:5.1f} m "
                  f"zone={r['zone']:9s} ground={r['ground_source']:11s} contained={_f(r['contained'])} grown={_f(r['contained_grown'])} "
                  f"gap={_f(r['lidar_ground_gap_m'], '+.2f')} m vis={_f(r['visible_fraction_placement'], '.2f')}/"
                  f"{_f(r['visible_fraction_rendered'], '.2f')} "
                  f"render={r['render_s']:.2f} s total={r['view_total_s']:.2f} s")
    out = {}
    for cls in DETECTION_CLASSES:
        row = {}
        for group, pred in (("real", lambda r: r["dataset"] != "bundled"), ("bundled", lambda r: r["dataset"] == "bundled")):
            rs = [r for r in renders if r["class"] == cls and pred(r)]
            row[group] = {"rendered": len(rs),
                          "contained": stats([r["contained"] for r in rs]),
                          "contained_grown_half_px": stats([r["contained_grown"] for r in rs]),
                          "share_at_least_99_5pct": (float(np.mean([r["contained_grown"] >= 0.995 for r in rs
                                                                    if r["contained_grown"] is not None]))
                                                     if any(r["contained_grown"] is not None for r in rs) else None),
                          "visible_fraction_rendered": stats([r["visible_fraction_rendered"] for r in rs]),
                          "rendered_visible_below_min": sum((r["visible_fraction_rendered"] or 0) < 0.5 for r in rs),
                          "lidar_ground_gap_m": stats([r["lidar_ground_gap_m"] for r in rs], (0, 50, 100)),
                          "render_s": stats([r["render_s"] for r in rs], (50,)),
                          "view_total_s": stats([r["view_total_s"] for r in rs], (50,)),
                          "sample_total_s": stats([r["sample_total_s"] for r in rs], (50,))}
        rs = [r for r in renders if r["class"] == cls]
        row["render_s_median_all"] = stats([r["render_s"] for r in rs], (50,)).get("p50")
        row["view_total_s_median_all"] = stats([r["view_total_s"] for r in rs], (50,)).get("p50")
        out[cls] = row
    return out, renders


def measure_sizes(n_seeds: int) -> dict:
    table = read_class_sizes()
    out = {}
    for ci, cls in enumerate(DETECTION_CLASSES):
        wlh_by_cat: dict = defaultdict(list)
        variants = Counter()
        times = []
        for s in range(max(n_seeds, GEN_TIME_SEEDS)):
            t0 = time.perf_counter()
            a = procedural_object(cls, 50_000 + s)
            dt = time.perf_counter() - t0
            if s < GEN_TIME_SEEDS:
                times.append(dt)
            if s < n_seeds:
                wlh_by_cat[a.category].append(np.asarray(a.wlh, dtype=float))
                variants[f"{a.category}|{a.attribute}"] += 1
        cats = {}
        for cat, ws in wlh_by_cat.items():
            w = np.array(ws)
            entry = {"n": len(ws), "generated_mean_wlh": np.round(w.mean(axis=0), 3).tolist(),
                     "generated_std_wlh": np.round(w.std(axis=0), 3).tolist()}
            t = table.get(cat)
            if t is not None:
                inside = np.all((w >= t.min_wlh - 1e-6) & (w <= t.max_wlh + 1e-6), axis=1)
                entry.update(table_mean_wlh=np.round(t.mean_wlh, 3).tolist(),
                             table_std_wlh=np.round(t.std_wlh, 3).tolist(),
                             table_min_wlh=np.round(t.min_wlh, 3).tolist(),
                             table_max_wlh=np.round(t.max_wlh, 3).tolist(),
                             table_n_instances=t.n_instances, table_source=t.source,
                             share_inside_table_range=round(float(inside.mean()), 4),
                             share_inside_range_per_dim_wlh=np.round(np.mean((w >= t.min_wlh - 1e-6)
                                                                             & (w <= t.max_wlh + 1e-6), axis=0),
                                                                     4).tolist(),
                             generated_min_wlh=np.round(w.min(axis=0), 3).tolist(),
                             generated_max_wlh=np.round(w.max(axis=0), 3).tolist(),
                             mean_diff_in_table_std=np.round((w.mean(axis=0) - t.mean_wlh)
                                                             / np.maximum(t.std_wlh, 1e-9), 2).tolist())
            cats[cat] = entry
        out[cls] = {"generation_s_median": round(float(np.median(times)), 5), "generation_seeds": len(times),
                    "categories": cats, "category_attribute_counts": dict(variants)}
        print(f"[sizes] {cls:20s} gen {np.median(times) * 1e3:6.1f} ms  " + "  ".join(
            f"{c}: gen {e['generated_mean_wlh']} vs table {e.get('table_mean_wlh')}" for c, e in cats.items()))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=2, help="attempts per class and view on real-seq")
    ap.add_argument("--seeds-small", type=int, default=6, help="attempts per class and view on real / bundled")
    ap.add_argument("--seq-stride", type=int, default=4, help="every N-th keyframe of scene-0916")
    ap.add_argument("--render-real", type=int, default=6, help="objects rendered per class on real data")
    ap.add_argument("--render-bundled", type=int, default=4, help="objects rendered per class on bundled scenes")
    ap.add_argument("--size-seeds", type=int, default=200, help="assets per class for the size distribution")
    ap.add_argument("--sheets", action="store_true", help="write the contact sheets")
    ap.add_argument("--real-sheet", type=Path, default=Path("/tmp/classes_contact_sheet_real.png"))
    ap.add_argument("--bundled-sheet", type=Path, default=ROOT / "docs" / "classes_contact_sheet.png")
    ap.add_argument("--crops-dir", type=Path, default=Path("/tmp/streetaug-bench-classes"),
                    help="every rendered crop alone (real pictures: keep outside the repository)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "classes.json")
    args = ap.parse_args()
    if args.real_sheet.resolve().is_relative_to(ROOT) or args.crops_dir.resolve().is_relative_to(ROOT):
        sys.exit("--real-sheet and --crops-dir must be outside the repository (real nuScenes pictures are not committed)")
    t_start = time.perf_counter()
    config = PlacementConfig()
    results: dict = {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"python": sys.version.split()[0], "platform": platform.platform(), "cpu_count": os.cpu_count(),
                    "threads_env": {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                                   "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")},
                    "load_avg_at_start": os.getloadavg()},
        "options": {"insert": dataclasses.asdict(OPTIONS), "seeds_real_seq": args.seeds,
                    "seeds_small": args.seeds_small, "seq_stride": args.seq_stride,
                    "render_real_per_class": args.render_real, "render_bundled_per_class": args.render_bundled,
                    "size_seeds": args.size_seeds, "generation_time_seeds": GEN_TIME_SEEDS,
                    "attempt": "one procedural_object(class, seed) per place_objects call (size drawn from the "
                               "class-sizes table), scene depth computed once per view",
                    "placement_config": dataclasses.asdict(config)},
        "class_categories": {c: [list(o) for o in v] for c, v in CLASS_CATEGORIES.items()},
    }
    datasets = dataset_views(args.seq_stride)
    results["datasets"] = {name: {"views": len(refs), "scenes": sorted({r.scene for r in refs}),
                                  "channels": sorted({r.channel for r in refs})} for name, refs in datasets}
    results["sizes"] = measure_sizes(args.size_seeds)
    results["placement"], placed = measure_placement(datasets, args.seeds, args.seeds_small, config)
    results["containment_and_time"], renders = measure_rendering(placed, args.render_real, args.render_bundled)
    results["renders"] = [{k: v for k, v in r.items() if k != "crop"} for r in renders]
    if args.sheets:
        for path, pred in ((args.real_sheet, lambda r: r["dataset"] != "bundled"),
                           (args.bundled_sheet, lambda r: r["dataset"] == "bundled")):
            crops: dict = defaultdict(list)
            for r in renders:
                if pred(r) and r["crop"] is not None:
                    crops[r["class"]].append(r["crop"])
            bundled = path == args.bundled_sheet
            sheet = contact_sheet(crops, 120 if bundled else 160, 4)
            path.parent.mkdir(parents=True, exist_ok=True)
            write_sheet(path, sheet, palette=bundled)
            print(f"wrote {path} ({sheet.shape[1]}x{sheet.shape[0]}, {path.stat().st_size // 1024} KB)")
        args.crops_dir.mkdir(parents=True, exist_ok=True)
        for i, r in enumerate(renders):
            if r["crop"] is not None:
                name = f"{i:03d}_{r['class']}_{r['dataset']}_{r['channel']}_{r['zone']}.png"
                cv2.imwrite(str(args.crops_dir / name), cv2.cvtColor(r["crop"], cv2.COLOR_RGB2BGR))
        print(f"wrote the single crops to {args.crops_dir}")
    results["load_avg_at_end"] = os.getloadavg()
    results["wall_s"] = round(time.perf_counter() - t_start, 1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1, default=float) + "\n")
    print_table(results)
    print("wrote", args.out)


def print_table(results: dict) -> None:
    pl, ct, sz = results["placement"], results["containment_and_time"], results["sizes"]
    names = list(pl)
    print("placement rate per dataset; viol = placements failing the audit; containment = alpha share inside the "
          "projected box grown by 1/2 px (strict pixel-centre min in brackets)")
    print(f"{'class':20s} " + " ".join(f"{n[:8]:>8s}" for n in names)
          + "  viol  cont.min/med(real) [strict]  cont.min(bund)  render/total s  gen ms  size gen vs table (first category)")
    for cls in DETECTION_CLASSES:
        rates = " ".join(f"{(pl[n][cls]['placement_rate'] or 0):8.2f}" for n in names)
        viol = sum(pl[n][cls]["audit_not_ok"] for n in names)
        c = ct[cls]
        real, bund = c["real"]["contained_grown_half_px"], c["bundled"]["contained_grown_half_px"]
        cat, e = next(iter(sz[cls]["categories"].items()))
        print(f"{cls:20s} {rates}  {viol:4d}  {real.get('p0', float('nan')):.4f}/{real.get('p50', float('nan')):.4f}"
              f" [{c['real']['contained'].get('p0', float('nan')):.4f}]"
              f"     {bund.get('p0', float('nan')):.4f}       {c['render_s_median_all'] or float('nan'):.2f}/"
              f"{c['view_total_s_median_all'] or float('nan'):.2f}     {sz[cls]['generation_s_median'] * 1e3:5.1f}  "
              f"{cat.split('.')[-1]} {e['generated_mean_wlh']} vs {e.get('table_mean_wlh')}")


if __name__ == "__main__":
    main()
