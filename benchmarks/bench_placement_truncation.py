"""How often placement puts the car cut by the image frame, against how often the real annotated cars are.

Usage: ``python benchmarks/bench_placement_truncation.py [--dataroot ../shared/data/nuscenes-seq] [--every 2]
[--seeds 3] [--track-seeds 0] [--out benchmarks/results/placement_truncation.json]``

Truncation of a box in a camera = the fraction of its projected 3D box (convex hull of the corners) outside the
image (:func:`~streetaug.placement.rules.projected_inside_fraction`, as the labels' ``truncation``).

* **real**: every annotated ``vehicle.car`` of every keyframe, in every camera, whose centre is 10-40 m
  (horizontally) from the camera, wholly in front of it (every corner at z >= ``near_plane_m``) and at least
  ``min_visible_fraction`` inside the image: the cars placement could have produced there. (Cars less than half
  in the image are counted separately: placement never makes those.)
* **placed**: the car ``insert`` would insert (the size of the procedural car it selects) placed with the default
  ``PlacementConfig`` in each camera of every ``--every``-th keyframe, for seeds 0..``--seeds``-1, seeded as the
  pipeline seeds it (``item_seed(seed, sample, camera)``), on the scene depth the pipeline passes.

Reported for both: the truncated share (truncation above 1 - ``FULL_VIEW_FRACTION``, 0.001) with its binomial
standard error, a histogram of the truncation, its mean among the truncated, the same per camera, and the
distances; for the placed cars also per zone (lane / kerb). Runs on the code on ``PYTHONPATH`` (for a before /
after comparison run it on both).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.assets.select import select_assets  # noqa: E402
from streetaug.augment.core import PinholeCamera, transform_points  # noqa: E402
from streetaug.augment.pipeline import item_seed, scene_depth_for_view  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402
from streetaug.datasets.sample import Sample  # noqa: E402
from streetaug.placement.config import PlacementConfig  # noqa: E402
from streetaug.placement.place import ObjectBox, Placement, place_objects  # noqa: E402
from streetaug.placement.rules import box_corners_object, projected_inside_fraction  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
FULL = 0.999  # inside fraction of a box wholly in view (placement.place.FULL_VIEW_FRACTION)
BINS = [0.0, 0.001, 0.1, 0.2, 0.3, 0.4, 0.5 + 1e-9]


def summary(trunc: list[float], dist: list[float] | None = None) -> dict:
    t = np.asarray(trunc, float)
    n = len(t)
    if n == 0:
        return {"n": 0}
    cut = t > 1.0 - FULL
    p = float(cut.mean())
    out = {"n": n, "truncated_share": p, "truncated_share_se": float(np.sqrt(p * (1 - p) / n)),
           "mean_truncation_of_truncated": float(t[cut].mean()) if cut.any() else None,
           "histogram": {"bins": BINS, "counts": np.histogram(t, bins=BINS)[0].tolist()}}
    if dist is not None:
        d = np.asarray(dist, float)
        out["distance_m"] = {"median": float(np.median(d)), "p10": float(np.percentile(d, 10)),
                             "p90": float(np.percentile(d, 90))}
        out["truncated_share_by_distance"] = {
            f"{lo}-{hi} m": (float(cut[(d >= lo) & (d < hi)].mean()) if ((d >= lo) & (d < hi)).any() else None,
                             int(((d >= lo) & (d < hi)).sum()))
            for lo, hi in ((10, 15), (15, 20), (20, 30), (30, 40.001))}
    return out


def grouped(rows: list[dict], key: str) -> dict:
    groups = defaultdict(list)
    for r in rows:
        groups[r[key]].append(r)
    return {k: summary([r["truncation"] for r in v], [r["distance_m"] for r in v]) for k, v in sorted(groups.items())}


def cars_in_range(reader: NuScenesReader, config: PlacementConfig):
    """Every annotated ``vehicle.car`` 10-40 m (the config's range) from a camera, wholly in front of it and
    partly in its image: yields ``(sample_token, sample, channel, view, box_index, box, distance_m,
    inside_fraction)``, per sample and camera in order."""
    for token in reader.sample_tokens():
        sample = reader.sample(token)
        for channel, view in sample.cameras.items():
            camera = PinholeCamera(view.K, view.width, view.height)
            cam_xy = view.T_global_from_cam[:2, 3]
            for i, box in enumerate(sample.boxes):
                if box.category != "vehicle.car":
                    continue
                d = float(np.hypot(*(box.center[:2] - cam_xy)))
                if not config.min_distance_m <= d <= config.max_distance_m:
                    continue
                corners = transform_points(view.T_cam_from_global, box.corners())
                if np.any(corners[:, 2] < config.near_plane_m):
                    continue
                inside = float(projected_inside_fraction(corners[None], camera, config.near_plane_m)[0])
                if inside > 0.0:
                    yield token, sample, channel, view, i, box, d, inside


def real_cars(reader: NuScenesReader, config: PlacementConfig) -> tuple[list[dict], int]:
    """(the eligible annotated cars per camera, the count of cars in range but less than half in the image)."""
    rows, less_than_half = [], 0
    for token, _, channel, _, _, box, d, inside in cars_in_range(reader, config):
        if inside < config.min_visible_fraction:
            less_than_half += 1
            continue
        rows.append({"sample": token, "camera": channel, "distance_m": d, "truncation": 1.0 - inside,
                     "attribute": ",".join(box.attributes)})
    return rows, less_than_half


@dataclass(frozen=True)
class PlacementAttempt:
    """One car ``insert`` would place in one camera of a keyframe, seeded as the pipeline seeds it."""

    sample: Sample
    channel: str
    seed: int
    camera: PinholeCamera
    placement: Placement | None  # None: no spot passed the rules
    corners_cam: np.ndarray | None  # (8, 3) box corners in the camera frame, metres


def placement_attempts(reader: NuScenesReader, config: PlacementConfig, every: int,
                       seeds: int) -> Iterator[PlacementAttempt]:
    """A car placement in each camera of every ``every``-th keyframe for seeds 0..``seeds``-1."""
    for token in reader.sample_tokens()[::every]:
        sample = reader.sample(token)
        for channel, view in sample.cameras.items():
            camera = PinholeCamera(view.K, view.width, view.height)
            depth = scene_depth_for_view(sample, view)
            for seed in range(seeds):
                asset = select_assets(item_seed(seed, "asset", sample.token, channel), 1,
                                      location=sample.location)[0]
                obj = ObjectBox(np.asarray(asset.wlh, float), asset.category)
                res = place_objects(sample, view, [obj], item_seed(seed, sample.token, channel), config, depth_m=depth)
                p = res.placements[0] if res.placements else None
                corners = None
                if p is not None:
                    T = view.T_cam_from_global @ p.T_global_from_object
                    corners = box_corners_object(p.wlh) @ T[:3, :3].T + T[:3, 3]
                yield PlacementAttempt(sample, channel, seed, camera, p, corners)


def placed_cars(reader: NuScenesReader, config: PlacementConfig, every: int, seeds: int) -> tuple[list[dict], int]:
    rows, attempts = [], 0
    for a in placement_attempts(reader, config, every, seeds):
        attempts += 1
        if a.placement is None:
            continue
        p = a.placement
        inside = float(projected_inside_fraction(a.corners_cam[None], a.camera, config.near_plane_m)[0])
        rows.append({"sample": a.sample.token, "camera": a.channel, "seed": a.seed, "distance_m": p.distance_m,
                     "truncation": 1.0 - inside, "zone": p.zone, "attribute": p.attribute,
                     "visible_fraction": p.visible_fraction})
    return rows, attempts


def track_cars(reader: NuScenesReader, config: PlacementConfig, seeds: int, n_tracks: int = 4) -> dict:
    """Tracks (``plan_tracks``, ``n_tracks`` cars per seed 0..``seeds``-1): the share cut by the frame of their
    anchor camera at the anchor keyframe (where each was sampled), and over every (keyframe, camera) sighting of
    them (at least ``min_visible_fraction`` inside) the truncated share, as for the annotated cars."""
    from streetaug.placement.track import TrackConfig, plan_tracks, track_frames

    samples = [reader.sample(t) for t in reader.sample_tokens()]
    frames = track_frames(samples)
    by_token = {s.token: s for s in samples}
    anchor, sightings, n = [], [], 0
    for seed in range(seeds):
        asset = select_assets(item_seed(seed, "asset", "tracks"), 1, location=samples[0].location)[0]
        obj = ObjectBox(np.asarray(asset.wlh, float), asset.category)
        plan = plan_tracks(frames, [obj] * n_tracks, np.random.default_rng(seed), TrackConfig(), samples[0].location)
        for t in plan.tracks:
            n += 1
            for q, token in enumerate(t.sample_tokens):
                seen = []
                for channel, view in by_token[token].cameras.items():
                    camera = PinholeCamera(view.K, view.width, view.height)
                    T = view.T_cam_from_global @ t.T_global_from_object[q]
                    corners = box_corners_object(t.wlh) @ T[:3, :3].T + T[:3, 3]
                    if np.any(corners[:, 2] < config.near_plane_m):
                        continue
                    inside = float(projected_inside_fraction(corners[None], camera, config.near_plane_m)[0])
                    if inside >= config.min_visible_fraction:
                        seen.append(1.0 - inside)
                    if token == t.anchor_sample_token and channel == t.anchor_camera:
                        anchor.append(inside < FULL)
                sightings += seen
    f = np.asarray(anchor, float)
    return {"seeds": seeds, "tracks": n, "anchor_view": {"n": len(f), "truncated_share": float(f.mean()) if len(f) else None},
            "sightings": summary(sightings)}


def placement_bench_parser(description: str, out_name: str) -> argparse.ArgumentParser:
    """The placement benchmarks' common options (the real scene, keyframe stride, seeds, output JSON)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--dataroot", type=Path, default=SHARED / "nuscenes-seq")
    ap.add_argument("--version", default="v1.0-mini")
    ap.add_argument("--every", type=int, default=2, help="place in every N-th keyframe")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / out_name)
    return ap


def open_real_scene(args: argparse.Namespace) -> NuScenesReader:
    """The reader of ``--dataroot``, or exit with what is missing."""
    if not args.dataroot.is_dir():
        raise SystemExit(f"{args.dataroot} not found (the real scene; see ../shared/data/README.md)")
    return NuScenesReader(args.dataroot, args.version)


def code_provenance() -> dict:
    """Which code ran: this tree's commit and where the imported placement package lives."""
    import streetaug.placement as placement_pkg
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    return {"worktree_commit": commit, "placement_package": str(Path(placement_pkg.__path__[0]).resolve())}


def main() -> None:
    ap = placement_bench_parser(__doc__.splitlines()[0], "placement_truncation.json")
    ap.add_argument("--track-seeds", type=int, default=0, help="also plan 4 car tracks per seed (0: no tracks)")
    ap.add_argument("--truncated-share", type=float, help="PlacementConfig.truncated_share (default: its default)")
    args = ap.parse_args()
    reader = open_real_scene(args)
    config = PlacementConfig() if args.truncated_share is None else PlacementConfig(truncated_share=args.truncated_share)
    t0 = time.perf_counter()
    real, real_less_than_half = real_cars(reader, config)
    placed, attempts = placed_cars(reader, config, args.every, args.seeds) if args.seeds else ([], 0)
    tracks = track_cars(reader, config, args.track_seeds) if args.track_seeds else None
    result = {
        "command": f"python benchmarks/bench_placement_truncation.py --every {args.every} --seeds {args.seeds}"
                   + (f" --track-seeds {args.track_seeds}" if args.track_seeds else "")
                   + (f" --truncated-share {args.truncated_share}" if args.truncated_share is not None else ""),
        "code": {**code_provenance(), "truncated_share": getattr(config, "truncated_share", None)},
        "machine": {"python": platform.python_version(), "load_avg": os.getloadavg()},
        "dataroot": str(args.dataroot),
        "definition": "truncation = fraction of the projected 3D box outside the image; truncated = truncation > 0.001",
        "real": {"all": summary([r["truncation"] for r in real], [r["distance_m"] for r in real]),
                 "by_camera": grouped(real, "camera"),
                 "in_range_less_than_half_in_image": real_less_than_half},
        "placed": {"attempts": attempts, "all": summary([r["truncation"] for r in placed],
                                                       [r["distance_m"] for r in placed]),
                   "by_camera": grouped(placed, "camera"), "by_zone": grouped(placed, "zone")},
        "tracks": tracks,
        "seconds": time.perf_counter() - t0,
        "placed_rows": placed,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    if tracks:
        print("tracks", json.dumps({k: v for k, v in tracks.items() if k != "sightings"}),
              "sightings truncated", tracks["sightings"].get("truncated_share"), "n", tracks["sightings"]["n"])
    for name in ("real", "placed"):
        a = result[name]["all"]
        if not a["n"]:
            continue
        print(f"{name:6s} n {a['n']:5d} truncated {a['truncated_share']:.3f} +- {a['truncated_share_se']:.3f} "
              f"hist {a['histogram']['counts']}")
        for cam, s in result[name]["by_camera"].items():
            print(f"   {cam:16s} n {s['n']:5d} truncated {s['truncated_share']:.3f}")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
