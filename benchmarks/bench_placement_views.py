"""How placed cars are seen against how the real annotated cars are: which end faces the camera, how they stand to
their parked neighbours, and how much of their image nearer boxes hide.

Usage: ``python benchmarks/bench_placement_views.py [--dataroot ../shared/data/nuscenes-seq] [--every 2]
[--seeds 3] [--out benchmarks/results/placement_views.json]``

Per car (a real annotated ``vehicle.car`` 10-40 m from the camera, wholly in front of it and at least half in the
image, as in ``bench_placement_truncation.py``; or the car ``insert`` would place in each camera of every
``--every``-th keyframe, seeds 0..``--seeds``-1, seeded as the pipeline seeds it):

* ``facing_deg``: the angle between the box heading and the direction from the box to the camera, in the ground
  plane (0 = its front faces the camera, 180 = its rear does); binned front (< 60) / side / rear (> 120);
* ``neighbour_deg``: the angle (0..180, the full direction) between its heading and that of the nearest *other*
  annotated parked vehicle whose centre is within ``NEIGHBOUR_M``, for cars that are parked (real ones labelled
  ``vehicle.parked``, placed ones with that attribute); None without such a neighbour;
* ``covered_share``: the share of its image hull (convex hull of the projected corners, clipped to the image)
  covered by the hulls of the annotated boxes (any class) nearer to the camera (centre distance); ``overlap_share``
  the same for every other annotated box, nearer or farther (the HOG diagnosis's "other box share": an inserted car
  in front of a parked row overlaps the boxes it hides). Real cars are also summarised with the annotation's
  visibility >= 60 % (tokens 3, 4: placement keeps at least half of a car visible) and >= 80 % (token 4, against the
  placed cars whose visible fraction, by the scene depth, is >= 0.8: the sets ``bench_realism.py`` compares).

Runs on the code on ``PYTHONPATH`` (for a before / after comparison run it on both).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import shapely  # noqa: E402

from streetaug.augment.core import PinholeCamera, transform_points  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402
from streetaug.datasets.nuscenes_format import VEHICLE_PARKED  # noqa: E402
from streetaug.placement.config import PlacementConfig  # noqa: E402

# The same placements as the truncation benchmark, seeded as insert seeds them.
from bench_placement_truncation import (cars_in_range, code_provenance, open_real_scene,  # noqa: E402
                                        placement_attempts, placement_bench_parser)

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
NEIGHBOUR_M = 8.0
END_BINS_DEG = (0.0, 60.0, 120.0, 180.01)


def yaw_of(R: np.ndarray) -> float:
    return float(np.arctan2(R[1, 0], R[0, 0]))


def facing_deg(T_cam_from_box: np.ndarray) -> float:
    up = T_cam_from_box[:3, 2]
    heading, to_cam = T_cam_from_box[:3, 0], -T_cam_from_box[:3, 3]
    h, r = heading - (heading @ up) * up, to_cam - (to_cam @ up) * up
    c = h @ r / max(np.linalg.norm(h) * np.linalg.norm(r), 1e-12)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def hull_image(corners_cam: np.ndarray, camera: PinholeCamera, near_m: float):
    """The image hull (shapely polygon, clipped to the image) of corners (8, 3), None unless all are in front."""
    if np.any(corners_cam[:, 2] < near_m):
        return None
    uv = corners_cam[:, :2] / corners_cam[:, 2:3] * np.array([camera.K[0, 0], camera.K[1, 1]]) + camera.K[:2, 2]
    hull = shapely.convex_hull(shapely.multipoints(uv))
    return shapely.intersection(hull, shapely.box(-0.5, -0.5, camera.width - 0.5, camera.height - 0.5))


def view_context(sample, view, config):
    """Per annotated box: (centre distance to the camera, image hull or None); parked vehicles (xy, yaw)."""
    camera = PinholeCamera(view.K, view.width, view.height)
    cam_xy = view.T_global_from_cam[:2, 3]
    dist, hulls = [], []
    for b in sample.boxes:
        dist.append(float(np.linalg.norm(b.center - view.T_global_from_cam[:3, 3])))
        hulls.append(hull_image(transform_points(view.T_cam_from_global, b.corners()), camera, 0.1))
    parked = [(i, b.center[:2], yaw_of(b.T_global_from_box)) for i, b in enumerate(sample.boxes)
              if b.category.startswith("vehicle.") and VEHICLE_PARKED in b.attributes]
    return camera, cam_xy, np.array(dist), hulls, parked


def covered_share(hull, distance_m: float, ctx_dist: np.ndarray, ctx_hulls: list, skip: int = -1) -> float:
    """Share of ``hull`` covered by the hulls of the boxes nearer than ``distance_m`` (inf: by any other box)."""
    if hull is None or hull.area <= 0:
        return float("nan")
    nearer = [h for i, (d, h) in enumerate(zip(ctx_dist, ctx_hulls)) if i != skip and h is not None
              and (d < distance_m or distance_m == np.inf)]
    if not nearer:
        return 0.0
    return float(shapely.intersection(hull, shapely.union_all(nearer)).area / hull.area)


def neighbour_deg(xy: np.ndarray, yaw: float, parked: list, skip: int = -1) -> float | None:
    best, out = NEIGHBOUR_M, None
    for i, c, y in parked:
        d = float(np.linalg.norm(c - xy))
        if i != skip and d <= best:
            best, out = d, float(np.degrees(abs(np.angle(np.exp(1j * (yaw - y))))))
    return out


def summary(rows: list[dict]) -> dict:
    if not rows:
        return {"n": 0}
    f = np.array([r["facing_deg"] for r in rows])
    ends = np.histogram(f, bins=END_BINS_DEG)[0]
    cov = np.array([r["covered_share"] for r in rows], float)
    cov = cov[np.isfinite(cov)]
    ov = np.array([r["overlap_share"] for r in rows], float)
    ov = ov[np.isfinite(ov)]
    parked = [r for r in rows if r["parked"]]
    nb = np.array([r["neighbour_deg"] for r in parked if r["neighbour_deg"] is not None], float)
    return {
        "n": len(rows),
        "ends_front_side_rear": ends.tolist(),
        "ends_share": (ends / len(rows)).round(3).tolist(),
        "covered_share": {"median": float(np.median(cov)), "mean": float(cov.mean()),
                          "share_over_0.5": float((cov > 0.5).mean()), "share_over_0.8": float((cov > 0.8).mean()),
                          "share_zero": float((cov <= 1e-6).mean()),
                          "quartiles": np.percentile(cov, [25, 50, 75]).round(3).tolist()} if len(cov) else None,
        "overlap_share": {"median": float(np.median(ov)), "mean": float(ov.mean()),
                          "quartiles": np.percentile(ov, [25, 50, 75]).round(3).tolist()} if len(ov) else None,
        "parked": {"n": len(parked), "with_neighbour": int(len(nb)),
                   "neighbour_deg_median": float(np.median(nb)) if len(nb) else None,
                   "neighbour_within_30deg": float((nb < 30).mean()) if len(nb) else None,
                   "neighbour_opposite_over_150deg": float((nb > 150).mean()) if len(nb) else None,
                   "ends_front_side_rear": np.histogram([r["facing_deg"] for r in parked],
                                                        bins=END_BINS_DEG)[0].tolist()},
    }


def real_cars(reader: NuScenesReader, config: PlacementConfig) -> list[dict]:
    rows, contexts = [], {}
    for token, sample, channel, view, i, box, d, inside in cars_in_range(reader, config):
        if inside < config.min_visible_fraction:
            continue
        if (token, channel) not in contexts:
            contexts[(token, channel)] = view_context(sample, view, config)
        _, _, dist, hulls, parked = contexts[(token, channel)]
        is_parked = VEHICLE_PARKED in box.attributes
        rows.append({"sample": token, "camera": channel, "distance_m": d, "parked": is_parked,
                     "facing_deg": facing_deg(view.T_cam_from_global @ box.T_global_from_box),
                     "neighbour_deg": neighbour_deg(box.center[:2], yaw_of(box.T_global_from_box), parked, i)
                     if is_parked else None,
                     "covered_share": covered_share(hulls[i], dist[i], dist, hulls, i),
                     "overlap_share": covered_share(hulls[i], np.inf, dist, hulls, i),
                     "visibility": reader.get("sample_annotation", box.token).get("visibility_token", "")
                     if box.token else ""})
    return rows


def placed_cars(reader: NuScenesReader, config: PlacementConfig, every: int, seeds: int) -> tuple[list[dict], int]:
    rows, attempts, contexts = [], 0, {}
    for a in placement_attempts(reader, config, every, seeds):
        attempts += 1
        if a.placement is None:
            continue
        p, view = a.placement, a.sample.cameras[a.channel]
        key = (a.sample.token, a.channel)
        if key not in contexts:
            contexts = {key: view_context(a.sample, view, config)}  # one view's context at a time
        camera, cam_xy, dist, hulls, parked = contexts[key]
        T = view.T_cam_from_global @ p.T_global_from_object
        d3 = float(np.linalg.norm(p.box.center - view.T_global_from_cam[:3, 3]))
        is_parked = p.attribute == VEHICLE_PARKED
        hull = hull_image(a.corners_cam, camera, 0.1)
        rows.append({"sample": a.sample.token, "camera": a.channel, "seed": a.seed, "distance_m": p.distance_m,
                     "zone": p.zone, "parked": is_parked, "yaw_source": p.yaw_source,
                     "visible_fraction": p.visible_fraction,
                     "facing_deg": facing_deg(T),
                     "neighbour_deg": neighbour_deg(p.box.center[:2], yaw_of(p.T_global_from_object[:3, :3]),
                                                    parked) if is_parked else None,
                     "covered_share": covered_share(hull, d3, dist, hulls),
                     "overlap_share": covered_share(hull, np.inf, dist, hulls)})
    return rows, attempts


def main() -> None:
    args = placement_bench_parser(__doc__.splitlines()[0], "placement_views.json").parse_args()
    reader = open_real_scene(args)
    config = PlacementConfig()
    t0 = time.perf_counter()
    real = real_cars(reader, config)
    placed, attempts = placed_cars(reader, config, args.every, args.seeds)
    result = {
        "command": f"python benchmarks/bench_placement_views.py --dataroot {args.dataroot} --every {args.every} "
                   f"--seeds {args.seeds}",
        "code": code_provenance(),
        "machine": {"python": platform.python_version(), "load_avg": os.getloadavg()},
        "definition": __doc__.split("\n\n")[2],
        "real": summary(real), "real_parked_only": summary([r for r in real if r["parked"]]),
        "real_visibility_over_60pct": summary([r for r in real if r["visibility"] in ("3", "4")]),
        "real_visibility_over_80pct": summary([r for r in real if r["visibility"] == "4"]),
        "placed_visible_over_80pct": summary([r for r in placed if r["visible_fraction"] >= 0.8]),
        "placed": {"attempts": attempts, **summary(placed)},
        "placed_by_zone": {z: summary([r for r in placed if r["zone"] == z]) for z in sorted({r["zone"] for r in placed})},
        "seconds": time.perf_counter() - t0,
        "placed_rows": placed,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    for name in ("real", "real_visibility_over_60pct", "real_visibility_over_80pct", "placed",
                 "placed_visible_over_80pct"):
        a = result[name]
        print(f"{name:6s} n {a['n']:4d} ends F/S/R {a['ends_front_side_rear']} covered {a['covered_share']} overlap {a['overlap_share']} "
              f"parked {a['parked']}")
    print("wrote", args.out, f"{result['seconds']:.0f} s")


if __name__ == "__main__":
    main()
