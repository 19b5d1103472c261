"""Placement, measured: rule pass rate, label accuracy, ground contact, time per placement, success rate.

Usage: ``python benchmarks/bench_placement.py [--seeds 10] [--render-seeds 3] [--objects 2]
[--out benchmarks/results/placement_metrics.json]``

Datasets (each sample x camera x seed is one attempt, seeded like the pipeline: ``item_seed(seed,
sample, camera)``):

* ``bundled``: the generated scenes in ``examples/nuscenes-samples`` (v1.0-samples) with their map;
* ``bundled-lidarseg``: the same without the map (road from lidarseg, medium confidence);
* ``real``: ``../shared/data/nuscenes-real`` (v1.0-mini, one keyframe) with its map expansion;
* ``real-lidar-ground``: the same without the map (LiDAR ground in the ego corridor, low confidence).

Objects: procedural cars and, when ``../shared/data/cars`` is present, the Kenney models (categories from
the asset mapping file, rescaled to a length per category).

Measured:

* rule pass rate: every final placement re-checked against every rule by :mod:`streetaug.placement.audit`
  (independent code, on the labelled box); must be 100 %.
* label accuracy (first ``--render-seeds`` seeds): each object rendered with ``render_insertion`` (draft);
  the share of its pixels (coverage > 0.5) whose pixel square overlaps the projection of the 3D label box
  rebuilt from ``labels.json``'s ``box_global`` (also: pixel centres strictly inside; every pixel with
  coverage > 0); and 3D tightness of that box: every mesh vertex inside (1 mm), each face within 2 cm of
  the mesh.
* ground contact: per wheel (the lowest vertex in each quadrant of the object's x/y) the height above the
  true road plane (generated scenes: global z = 0) and above an independent LiDAR ground estimate (median
  of the lowest points within 0.75-1.5 m, outside annotated boxes; wheels without LiDAR support are
  counted, not scored); reported per placement as the worst wheel.
* time per placement: wall and process CPU time of ``place_objects`` per image (and wall time per placed
  object), medians; the machine is shared, so the load average is recorded.
* success: sample x camera combinations with at least one valid placement (and per-attempt rate), with the
  reasons of the failures and, for combinations that never succeed, the drivable area inside the sampled
  region (camera field of view x [min, max] distance).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import shapely  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from streetaug.augment.assets.loader import load_asset  # noqa: E402
from streetaug.augment.assets.procedural import procedural_car  # noqa: E402
from streetaug.augment.core import PinholeCamera, quat_to_rotation, transform_points  # noqa: E402
from streetaug.augment.core import write_image_rgb  # noqa: E402
from streetaug.augment.lighting.light import DistantLight  # noqa: E402
from streetaug.augment.pipeline import item_seed, scene_depth_for_view  # noqa: E402
from streetaug.augment.render import render_insertion  # noqa: E402
from streetaug.datasets.bundled import bundled_dataroot  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402
from streetaug.datasets.sample import Box  # noqa: E402
from streetaug.placement.audit import AUDITED_RULES, audit_placements  # noqa: E402
from streetaug.placement.config import PlacementConfig  # noqa: E402
from streetaug.placement.explain import draw_placement_bev  # noqa: E402
from streetaug.placement.labels import object_label  # noqa: E402
from streetaug.placement.candidates import camera_azimuth_range  # noqa: E402
from streetaug.placement.place import place_objects  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
LENGTH_BY_CATEGORY_M = {"vehicle.car": 4.5, "vehicle.truck": 6.0}
DEFAULT_LENGTH_M = 5.5  # ambulances, police cars


def load_objects() -> list:
    objects = [procedural_car(seed) for seed in (0, 1, 2, 3)]
    cars = SHARED / "cars"
    if cars.is_dir():
        for path in sorted(cars.glob("*.glb")):
            probe = load_asset(path, front_axis="-z")
            objects.append(load_asset(path, front_axis="-z",
                                      length_m=LENGTH_BY_CATEGORY_M.get(probe.category, DEFAULT_LENGTH_M)))
    return objects


def datasets() -> list[tuple[str, NuScenesReader]]:
    out = [("bundled", NuScenesReader(bundled_dataroot(), "v1.0-samples")),
           ("bundled-lidarseg", NuScenesReader(bundled_dataroot(), "v1.0-samples", with_map=False))]
    real = SHARED / "nuscenes-real"
    if real.is_dir():
        out += [("real", NuScenesReader(real, "v1.0-mini")),
                ("real-lidar-ground", NuScenesReader(real, "v1.0-mini", with_map=False))]
    else:
        print(f"note: {real} not found; real-sample rows skipped")
    return out


def wheel_contacts_global(asset, T_global_from_object: np.ndarray) -> np.ndarray:
    """(4, 3) the lowest vertex of each x/y quadrant of the mesh (object frame), in the global frame."""
    V = asset.vertices
    out = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            q = V[(np.sign(V[:, 0]) == sx) & (np.sign(V[:, 1]) == sy)]
            out.append(q[np.argmin(q[:, 2])])
    return transform_points(T_global_from_object, np.array(out))


def ground_candidates(sample) -> np.ndarray:
    """LiDAR points (global) that may be ground: outside annotated boxes (+0.3 m), within 0.5 m + 5 % of the
    distance of the ego's ground plane (no canopies, roofs or pits)."""
    lidar = sample.lidar
    pts = lidar.points_global
    keep = ~_in_boxes(pts, sample.boxes, 0.3)
    T = lidar.T_global_from_ego
    rel = pts - T[:3, 3]
    height = rel @ T[:3, 2]
    dist = np.linalg.norm(rel[:, :2], axis=1)
    return pts[keep & (np.abs(height) < 0.5 + 0.05 * dist)]


def _in_boxes(points: np.ndarray, boxes, margin_m: float) -> np.ndarray:
    inside = np.zeros(len(points), dtype=bool)
    for b in boxes:
        local = (points - b.center) @ quat_to_rotation(b.rotation)
        inside |= np.all(np.abs(local) <= np.asarray(b.wlh)[[1, 0, 2]] / 2 + margin_m, axis=1)
    return inside


def lidar_ground_height(tree: cKDTree, points: np.ndarray, xy: np.ndarray) -> float:
    """Independent local ground height at x/y: median of the lowest ground-candidate LiDAR points within
    0.75 m (1.5 m where sparser); nan when fewer than 3 points lie within 1.5 m (no LiDAR support: far rings
    are metres apart)."""
    for r in (0.75, 1.5):
        idx = tree.query_ball_point(xy, r)
        if len(idx) >= 3:
            z = points[idx, 2]
            return float(np.median(z[z <= np.percentile(z, 10) + 0.10]))
    return float("nan")


def label_accuracy(view, asset, placement, light, depth_m, image, seed: int) -> dict:
    """Render one object and compare its pixels and mesh with the label box rebuilt from box_global."""
    T_co = view.T_cam_from_global @ placement.T_global_from_object
    normal_cam = view.T_cam_from_global[:3, :3] @ placement.ground_normal_global
    ins = render_insertion(image, view.K, depth_m, light, asset, T_co, normal_cam, quality="draft", seed=seed)
    label = object_label(T_co, asset.wlh, asset.category, PinholeCamera(view.K, view.width, view.height), ins.mask,
                         ins.coverage, T_global_from_cam=view.T_global_from_cam, attribute=placement.attribute)
    g = label["box_global"]
    box = Box(np.array(g["translation"]), np.array(g["size"]), np.array(g["rotation"]), label["category"])
    # 2D: pixels of the object vs the projected label box
    corners_cam = transform_points(view.T_cam_from_global, box.corners())
    uv = corners_cam @ view.K.T
    uv = uv[:, :2] / uv[:, 2:]
    hull = shapely.convex_hull(shapely.multipoints(uv))
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    grown = shapely.convex_hull(shapely.multipoints((uv[:, None, :] + square[None]).reshape(-1, 2)))
    on = ins.coverage > 0.5
    vs, us = np.nonzero(on)
    any_v, any_u = np.nonzero(ins.coverage > 0)
    n = len(us)
    overlap = float(shapely.contains_xy(grown, us, vs).mean()) if n else float("nan")
    centre_in = float(shapely.contains_xy(hull, us, vs).mean()) if n else float("nan")
    any_in = float(shapely.contains_xy(grown, any_u, any_v).mean()) if len(any_u) else float("nan")
    # 3D: mesh vertices in the label box frame
    local = (transform_points(placement.T_global_from_object, asset.vertices) - box.center) @ quat_to_rotation(box.rotation)
    half = np.asarray(box.wlh)[[1, 0, 2]] / 2
    outside_m = float(np.max(np.abs(local) - half))
    face_gap_m = float(max(np.max(half - local.max(axis=0)), np.max(half + local.min(axis=0))))
    # the camera-frame label agrees with the global one
    c_cam = transform_points(view.T_cam_from_global, box.center[None])[0]
    return {"object_pixels": n, "pixels_in_box_overlap": overlap, "pixels_in_box_centre": centre_in,
            "any_coverage_in_box": any_in, "max_vertex_outside_box_m": outside_m, "max_face_gap_m": face_gap_m,
            "box_camera_vs_global_m": float(np.linalg.norm(c_cam - label["box_camera"]["center"])),
            "visible_fraction": label["visible_fraction"], "category": label["category"]}


def sampled_region_diagnosis(sample, view, drivable, config: PlacementConfig) -> dict:
    """Drivable area inside the sampled region (field of view x [min, max] distance), and nearer than min."""
    cam_xy = view.T_global_from_cam[:2, 3]
    fov = camera_azimuth_range(view)
    az = np.linspace(fov.heading_rad - fov.right_rad, fov.heading_rad + fov.left_rad, 64)
    ring = np.c_[np.cos(az), np.sin(az)]

    def wedge(r0, r1):
        return shapely.Polygon(np.concatenate([cam_xy + r0 * ring, cam_xy + r1 * ring[::-1]]))

    out = {"drivable_source": drivable.source if drivable is not None else None}
    if drivable is None:
        return out
    if drivable.region is not None:
        area = lambda poly: float(shapely.intersection(drivable.region, poly).area)  # noqa: E731
    else:
        res = drivable.resolution_m
        iy, ix = np.nonzero(drivable.grid)
        centres = drivable.grid_origin_xy + (np.c_[ix, iy] + 0.5) * res
        area = lambda poly: float(shapely.contains_xy(poly, centres[:, 0], centres[:, 1]).sum() * res * res)  # noqa: E731
    out["drivable_m2_in_sampled_region"] = area(wedge(config.min_distance_m, config.max_distance_m))
    out["drivable_m2_in_view_nearer_than_min"] = area(wedge(0.5, config.min_distance_m))
    out["sampled_region_m2"] = float(wedge(config.min_distance_m, config.max_distance_m).area)
    return out


def summarise(values, q=(50, 95, 100)) -> dict:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if len(v) == 0:
        return {"n": 0}
    return {"n": int(len(v)), **{f"p{p}": float(np.percentile(v, p)) for p in q}, "mean": float(v.mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10, help="attempts per sample x camera")
    ap.add_argument("--render-seeds", type=int, default=3, help="the first N seeds are also rendered (label accuracy)")
    ap.add_argument("--objects", type=int, default=2, help="objects per image")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "placement_metrics.json")
    ap.add_argument("--png-dir", type=Path, default=Path("/tmp/streetaug-bench-placement"),
                    help="explain PNGs of failing combinations (real data stays out of the repository)")
    args = ap.parse_args()
    config = PlacementConfig()
    objects = load_objects()
    light = DistantLight(envmap=np.full((32, 64, 3), 0.5, np.float32))
    load_start = os.getloadavg()
    args.png_dir.mkdir(parents=True, exist_ok=True)

    results: dict = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                                 "cpu_count": os.cpu_count(), "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
                                 "load_avg_at_start": load_start},
                     "config": dataclasses.asdict(config), "seeds": args.seeds, "render_seeds": args.render_seeds,
                     "objects_per_image": args.objects, "assets": [a.name for a in objects], "datasets": {}}
    for ds_name, reader in datasets():
        rows, audits, labels, contacts = [], [], [], []
        n_combos = 0
        t_image, t_object, cpu_image = [], [], []
        for token in reader.sample_tokens():
            sample = reader.sample(token)
            pts = ground_candidates(sample)
            tree = cKDTree(pts[:, :2])
            true_ground = ds_name.startswith("bundled")  # generated scenes: the road is the plane z = 0
            for channel, view in sample.cameras.items():
                ok_seeds, reasons, last = 0, Counter(), None
                depth_m = image = None
                for seed in range(args.seeds):
                    rng = item_seed(seed, sample.token, channel)
                    first = seed * args.objects + 5 * n_combos  # vary the assets across combinations
                    assets = [objects[(first + k) % len(objects)] for k in range(args.objects)]
                    t0, c0 = time.perf_counter(), time.process_time()
                    res = place_objects(sample, view, assets, rng, config)
                    dt = time.perf_counter() - t0
                    t_image.append(dt)
                    cpu_image.append(time.process_time() - c0)
                    if res.placements:
                        t_object.append(dt / len(res.placements))
                        ok_seeds += 1
                    if res.reason:
                        reasons[res.reason.split(" (")[0] if "no candidate" in res.reason else res.reason] += 1
                    last = res
                    placed_assets = [assets[p.asset_index] for p in res.placements]
                    for p, a, aud in zip(res.placements, placed_assets,
                                         audit_placements(sample, view, res.placements, res.drivable, config)):
                        audits.append(aud.passed)
                        wheels = wheel_contacts_global(a, p.T_global_from_object)
                        lidar_err = [w[2] - lidar_ground_height(tree, pts, w[:2]) for w in wheels]
                        contacts.append({
                            "true_err_m": float(np.max(np.abs(wheels[:, 2]))) if true_ground else None,
                            "lidar_err_m": float(np.nanmax(np.abs(lidar_err))) if np.isfinite(lidar_err).any() else None,
                            "wheels_with_lidar_support": int(np.isfinite(lidar_err).sum()),
                            "ground_source": p.ground_source, "distance_m": p.distance_m,
                            "lowest_vertex_above_plane_m": float(a.vertices[:, 2].min()),
                        })
                        if seed < args.render_seeds:
                            if depth_m is None:
                                image, depth_m = view.image, scene_depth_for_view(sample, view)
                            labels.append(label_accuracy(view, a, p, light, depth_m, image, seed))
                combo = {"sample": sample.scene_name, "camera": channel, "ok_seeds": ok_seeds,
                         "attempts": args.seeds, "reasons": dict(reasons),
                         "drivable_source": last.drivable.source if last.drivable is not None else None}
                if ok_seeds == 0:
                    combo["diagnosis"] = sampled_region_diagnosis(sample, view, last.drivable, config)
                    near = dataclasses.replace(config, min_distance_m=5.0)
                    combo["diagnosis"]["succeeds_with_min_distance_5m"] = bool(place_objects(
                        sample, view, [objects[0]], item_seed(0, sample.token, channel), near).placements)
                    png = args.png_dir / f"placement_bev_{ds_name}_{sample.scene_name}_{channel}.png"
                    write_image_rgb(png, draw_placement_bev(sample, view, last))
                    combo["explain_png"] = str(png)
                rows.append(combo)
                n_combos += 1
                print(f"{ds_name:18s} {sample.scene_name:16s} {channel:15s} ok {ok_seeds}/{args.seeds} "
                      f"road={combo['drivable_source']} {dict(reasons) if reasons else ''}"
                      + (f" diag={combo['diagnosis']}" if 'diagnosis' in combo else ""))
        n_pl = len(audits)
        per_rule = {r: float(np.mean([a[r] for a in audits if r in a])) if any(r in a for a in audits) else None
                    for r in AUDITED_RULES}
        ds = {
            "combinations": rows,
            "success": {"combos_with_placement": sum(r["ok_seeds"] > 0 for r in rows), "combos": len(rows),
                        "attempts_with_placement": sum(r["ok_seeds"] for r in rows),
                        "attempts": sum(r["attempts"] for r in rows)},
            "placements": n_pl,
            "rule_pass_rate": float(np.mean([all(a.values()) for a in audits])) if n_pl else None,
            "rule_pass_rate_per_rule": per_rule,
            "time_per_image_s": summarise(t_image), "time_per_placed_object_s": summarise(t_object),
            "cpu_time_per_image_s": summarise(cpu_image),
            "ground_contact": {
                "true_ground_worst_wheel_m": summarise([c["true_err_m"] for c in contacts if c["true_err_m"] is not None]),
                "lidar_ground_worst_wheel_m": summarise([c["lidar_err_m"] for c in contacts if c["lidar_err_m"] is not None]),
                "share_within_10cm_true": (float(np.mean([c["true_err_m"] <= 0.10 for c in contacts]))
                                           if contacts and contacts[0]["true_err_m"] is not None else None),
                "share_within_10cm_lidar": float(np.mean([c["lidar_err_m"] <= 0.10 for c in contacts
                                                          if c["lidar_err_m"] is not None])) if contacts else None,
                "ground_sources": dict(Counter(c["ground_source"] for c in contacts)),
                "share_wheels_with_lidar_support": (float(np.mean([c["wheels_with_lidar_support"] / 4 for c in contacts]))
                                                    if contacts else None),
                "max_lowest_vertex_above_plane_m": max((c["lowest_vertex_above_plane_m"] for c in contacts), default=None),
            },
            "label_accuracy": {
                "rendered_objects": len(labels),
                "pixels_in_box_overlap": summarise([x["pixels_in_box_overlap"] for x in labels], q=(0, 5, 50)),
                "pixels_in_box_centre": summarise([x["pixels_in_box_centre"] for x in labels], q=(0, 5, 50)),
                "any_coverage_in_box": summarise([x["any_coverage_in_box"] for x in labels], q=(0, 5, 50)),
                "objects_with_99_5pct_pixels_in_box": (float(np.mean([x["pixels_in_box_overlap"] >= 0.995
                                                                      for x in labels])) if labels else None),
                "max_vertex_outside_box_m": max((x["max_vertex_outside_box_m"] for x in labels), default=None),
                "max_face_gap_m": max((x["max_face_gap_m"] for x in labels), default=None),
                "max_box_camera_vs_global_m": max((x["box_camera_vs_global_m"] for x in labels), default=None),
                "categories": dict(Counter(x["category"] for x in labels)),
                # the renderer's own depth test (densified LiDAR): an independent check of the in_view rule's
                # occlusion-aware visible fraction (>= min_visible_fraction at placement time)
                "rendered_visible_fraction": summarise([x["visible_fraction"] for x in labels], q=(0, 5, 50)),
                "share_rendered_visible_at_least_min": (float(np.mean(
                    [x["visible_fraction"] >= config.min_visible_fraction for x in labels])) if labels else None),
            },
        }
        results["datasets"][ds_name] = ds
        la, gc = ds["label_accuracy"], ds["ground_contact"]
        print(f"== {ds_name}: success {ds['success']['combos_with_placement']}/{ds['success']['combos']} combos, "
              f"{ds['success']['attempts_with_placement']}/{ds['success']['attempts']} attempts | placements {n_pl}, "
              f"rule pass {ds['rule_pass_rate']} | time/image median {ds['time_per_image_s'].get('p50', float('nan'))*1e3:.0f} ms"
              f" (CPU {ds['cpu_time_per_image_s'].get('p50', float('nan'))*1e3:.0f} ms) | pixels in box (min over objects) {la['pixels_in_box_overlap'].get('p0')} | vertex outside "
              f"{la['max_vertex_outside_box_m']} m, face gap {la['max_face_gap_m']} m | ground true p50/max "
              f"{gc['true_ground_worst_wheel_m'].get('p50')}/{gc['true_ground_worst_wheel_m'].get('p100')} lidar "
              f"p50/p95 {gc['lidar_ground_worst_wheel_m'].get('p50')}/{gc['lidar_ground_worst_wheel_m'].get('p95')}")
    results["load_avg_at_end"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2, default=float) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
