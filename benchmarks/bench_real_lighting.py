"""Lighting on real photographs: the paper's novel-view protocol on a real nuScenes scene, per level.

Usage: ``python benchmarks/bench_real_lighting.py [--stride 1] [--levels L0,L1,L2,L3,auto] [--out benchmarks/results]``

Data: ``../shared/data/nuscenes-seq`` (scene-0916, 41 keyframes x 6 cameras, LiDAR, boxes) and the one-north
keyframe ``../shared/data/nuscenes-real``. Metrics (:mod:`streetaug.augment.evaluation.novel_view`): a camera's
view rendered from the lighting (the map at that camera's centre, EV 0) against its real image at 320 px,
PSNR and si-PSNR (dB). Nothing of a target image is used to predict it.

For every keyframe *t* that has a *t* + 3 (1.5 s later; every ``--stride``-th):

* **monocular** (lighting from CAM_FRONT at *t*, with the sample's LiDAR and boxes), per level:
  ``forward`` = CAM_FRONT at *t* + 3 (the paper's protocol), ``self`` = CAM_FRONT at *t* (is the map on the
  image's scale? PSNR within 1 dB of si-PSNR when it is), ``others`` = the other 5 cameras at *t* (what no
  camera of the input saw);
* **six_view** (lighting from the 6 cameras of *t*, CAM_FRONT the reference), per level: ``forward`` as above,
  ``forward_every_camera`` = each camera at *t* + 3, ``self_every_camera`` = each camera at *t*;
* **every_camera** (default level): lighting from camera C alone at *t*, C at *t* + 3;
* **monocular_previous** / **six_view_previous** (default level, keyframes with a *t* - 1): as monocular /
  six_view, with the previous keyframe's same cameras (and LiDAR) as an extra input (``earlier``: their seen
  surfaces fill what the instant's leave open);
* the **constant-colour baseline** for every target: the source images' mean LDR colour everywhere.

Medians over keyframes (and over cameras where a row has several) are reported next to the paper's figures
(monocular 14.49 / 15.35, 6-view 17.96 / 18.45). A target that was not an input (another camera, a later time)
is predicted at its camera's auto-exposure (:mod:`streetaug.augment.lighting.predicted_view`: the inputs' mean
image value); ``psnr_reference_exposure`` is the same prediction at the reference camera's exposure. The one-north keyframe: the same monocular and six-view
scores at its single instant (no *t* + 3): self and other cameras. Also the time per estimate (wall, one
thread, decode excluded). Writes ``real_lighting.json`` (``--name``).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from streetaug.augment.core.io import write_json_atomic  # noqa: E402
from streetaug.augment.evaluation.novel_view import (  # noqa: E402
    constant_colour_scores,
    paper_pairs,
    real_view,
    view_scores,
)
from streetaug.augment.lighting.api import earlier_keyframe, estimate_views_lighting  # noqa: E402
from streetaug.augment.lighting.predicted_view import auto_exposed, predicted_radiance  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
REAL = (ROOT / ".." / "shared" / "data" / "nuscenes-real").resolve()
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
CAMERAS = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT")
DEFAULT_LEVEL = "auto"
PAPER = {"monocular": {"psnr": 14.49, "si_psnr": 15.35}, "six_view": {"psnr": 17.96, "si_psnr": 18.45}}
SCORES = ("psnr", "si_psnr")


def lighting(sample, cameras, level, previous=None):
    """(SampleLighting, seconds) from the given cameras of a sample (images decoded first), with the same
    cameras of the ``previous`` keyframe as the earlier input when given."""
    views = [sample.cameras[c] for c in cameras]
    earlier = None if previous is None else earlier_keyframe(previous, cameras)
    for v in views + ([] if earlier is None else list(earlier.views)):
        np.asarray(v.image)
    t0 = time.perf_counter()
    sl = estimate_views_lighting(views, sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                 earlier=earlier)
    return sl, time.perf_counter() - t0


def scored(sl, target, source_images) -> dict:
    """Scores of ``sl`` rendered into ``target`` (:func:`predicted_radiance`: a target that was not an input at
    its camera's auto-exposure) and of the constant-colour baseline, one flat row; ``psnr_reference_exposure``:
    the same prediction at the reference camera's exposure instead (what the auto-exposure model adds)."""
    truth = real_view(target)
    raw = predicted_radiance(replace(sl, input_mean_ldr={}), target)
    s = view_scores(raw if sl.is_input(target) else auto_exposed(sl, target, raw), truth)
    c = constant_colour_scores(source_images, truth)
    return {"psnr": s["psnr"], "si_psnr": s["si_psnr"], "const_psnr": c["psnr"], "const_si_psnr": c["si_psnr"],
            "psnr_reference_exposure": view_scores(raw, truth)["psnr"]}


def mean_row(rows: list[dict]) -> dict:
    """Mean of several targets' scores (one keyframe's cameras)."""
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


def keyframe_rows(sample, later, levels, previous=None) -> dict:
    """All scores of one source keyframe (``later`` = the sample 1.5 s later, or None: the instant only;
    ``previous`` = the sample before it, or None: no ``*_previous`` rows)."""
    out: dict = {"token": sample.token, "monocular": {}, "six_view": {}, "every_camera": {},
                 "monocular_previous": {}, "six_view_previous": {}}
    front_img = [np.asarray(sample.cameras["CAM_FRONT"].image)]
    all_img = [np.asarray(sample.cameras[c].image) for c in CAMERAS]
    for level in levels:
        sl, dt = lighting(sample, ["CAM_FRONT"], level)
        row = {"chosen": sl.level, "seconds": dt, "sun_visibility": float(sl.sun_visibility),
               "self": scored(sl, sample.cameras["CAM_FRONT"], front_img),
               "others": mean_row([scored(sl, sample.cameras[c], front_img) for c in CAMERAS[1:]])}
        if later is not None:
            row["forward"] = scored(sl, later.cameras["CAM_FRONT"], front_img)
        out["monocular"][level] = row
        sl, dt = lighting(sample, list(CAMERAS), level)
        row = {"chosen": sl.level, "seconds": dt, "sun_visibility": float(sl.sun_visibility),
               "self_every_camera": mean_row([scored(sl, sample.cameras[c], all_img) for c in CAMERAS])}
        if later is not None:
            row["forward"] = scored(sl, later.cameras["CAM_FRONT"], all_img)
            row["forward_every_camera"] = mean_row([scored(sl, later.cameras[c], all_img) for c in CAMERAS])
        out["six_view"][level] = row
    if previous is not None and later is not None:
        sl, dt = lighting(sample, ["CAM_FRONT"], DEFAULT_LEVEL, previous)
        out["monocular_previous"][DEFAULT_LEVEL] = {
            "chosen": sl.level, "seconds": dt, "sun_visibility": float(sl.sun_visibility),
            "self": scored(sl, sample.cameras["CAM_FRONT"], front_img),
            "others": mean_row([scored(sl, sample.cameras[c], front_img) for c in CAMERAS[1:]]),
            "forward": scored(sl, later.cameras["CAM_FRONT"], front_img)}
        sl, dt = lighting(sample, list(CAMERAS), DEFAULT_LEVEL, previous)
        out["six_view_previous"][DEFAULT_LEVEL] = {
            "chosen": sl.level, "seconds": dt, "sun_visibility": float(sl.sun_visibility),
            "self_every_camera": mean_row([scored(sl, sample.cameras[c], all_img) for c in CAMERAS]),
            "forward": scored(sl, later.cameras["CAM_FRONT"], all_img),
            "forward_every_camera": mean_row([scored(sl, later.cameras[c], all_img) for c in CAMERAS])}
    if later is not None:
        rows = []
        for c in CAMERAS:
            sl, _ = lighting(sample, [c], DEFAULT_LEVEL)
            rows.append(scored(sl, later.cameras[c], [np.asarray(sample.cameras[c].image)]))
        out["every_camera"][DEFAULT_LEVEL] = mean_row(rows)
    return out


def medians(keyframes: list[dict], levels) -> dict:
    """Median over keyframes of every (setup, level, target) score."""
    out: dict = {}
    for setup in ("monocular", "six_view", "every_camera", "monocular_previous", "six_view_previous"):
        for level in levels:
            rows = [k[setup][level] for k in keyframes if level in k[setup]]
            if not rows:
                continue
            entry: dict = {}
            if "chosen" in rows[0]:
                chosen = [r["chosen"] for r in rows]
                entry["chosen"] = {lv: chosen.count(lv) for lv in sorted(set(chosen))}
                entry["seconds_median"] = float(np.median([r["seconds"] for r in rows]))
                vis = [r["sun_visibility"] for r in rows]
                entry["sun_visibility"] = {"median": float(np.median(vis)), "min": float(np.min(vis)),
                                           "max": float(np.max(vis))}
            targets = [t for t in rows[0] if isinstance(rows[0][t], dict)] or [None]
            for t in targets:
                vals = [r[t] if t else r for r in rows if (t is None or t in r)]
                entry[t or "scores"] = {k: float(np.median([v[k] for v in vals])) for k in vals[0]} | {"n": len(vals)}
            out[f"{setup}/{level}"] = entry
    return out


def print_medians(name: str, med: dict) -> None:
    for key, entry in med.items():
        parts = []
        for t, v in entry.items():
            if isinstance(v, dict) and "psnr" in v:
                parts.append(f"{t} {v['psnr']:.2f}/{v['si_psnr']:.2f} (const {v['const_psnr']:.2f}/{v['const_si_psnr']:.2f})")
        chosen = entry.get("chosen")
        print(f"{name} {key}: " + "; ".join(parts) + (f"; chose {chosen}" if chosen else "")
              + (f"; {entry['seconds_median']:.2f} s" if "seconds_median" in entry else ""), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stride", type=int, default=1, help="every n-th source keyframe")
    ap.add_argument("--levels", default="L0,L1,L2,L3,auto")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    ap.add_argument("--name", default="real_lighting.json", help="result file name in --out")
    ap.add_argument("--keyframes", default=None, help="comma-separated source keyframes (default: every --stride-th)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    levels = tuple(args.levels.split(","))
    result: dict = {"machine": {"python": platform.python_version(), "threads": 1}, "paper": PAPER,
                    "levels": levels, "default_level": DEFAULT_LEVEL, "stride": args.stride}
    if SEQ.exists():
        reader = NuScenesReader(SEQ, "v1.0-mini")
        tokens = reader.sample_tokens("scene-0916")
        pairs = paper_pairs(len(tokens))[:: args.stride]
        if args.keyframes:
            wanted = {int(k) for k in args.keyframes.split(",")}
            pairs = [p for p in paper_pairs(len(tokens)) if p[0] in wanted]
        rows = []
        for t, t3 in pairs:
            t0 = time.perf_counter()
            previous = reader.sample(tokens[t - 1]) if t > 0 else None
            rows.append({"t": t} | keyframe_rows(reader.sample(tokens[t]), reader.sample(tokens[t3]), levels, previous))
            m, s = rows[-1]["monocular"], rows[-1]["six_view"]
            print(f"keyframe {t} -> {t3} ({time.perf_counter() - t0:.0f} s): " + ", ".join(
                f"{lv} mono {m[lv]['forward']['psnr']:.2f}/{m[lv]['forward']['si_psnr']:.2f} "
                f"6v {s[lv]['forward']['psnr']:.2f}/{s[lv]['forward']['si_psnr']:.2f}" for lv in levels)
                + "".join(f", {k} {r[DEFAULT_LEVEL]['forward']['psnr']:.2f}" for k in ("monocular_previous", "six_view_previous")
                          if DEFAULT_LEVEL in (r := rows[-1][k])), flush=True)
        med = medians(rows, levels)
        print_medians("scene-0916 median", med)
        result["scene_0916"] = {"pairs": len(rows), "median": med, "per_keyframe": rows}
    else:
        result["scene_0916"] = {"skipped": f"{SEQ} not found"}
    if REAL.exists():
        sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
        cams = [c for c in CAMERAS if c in sample.cameras]
        rows = []
        for level in levels:
            sl, dt = lighting(sample, ["CAM_FRONT"], level)
            img = [np.asarray(sample.cameras["CAM_FRONT"].image)]
            six, dt6 = lighting(sample, cams, level)
            all_img = [np.asarray(sample.cameras[c].image) for c in cams]
            rows.append({"level": level, "chosen": sl.level, "seconds": dt,
                         "self": scored(sl, sample.cameras["CAM_FRONT"], img),
                         "others": mean_row([scored(sl, sample.cameras[c], img) for c in cams[1:]]),
                         "all_cameras_self": mean_row([scored(six, sample.cameras[c], all_img) for c in cams]),
                         "all_cameras_chosen": six.level})
            r = rows[-1]
            print(f"one-north {level} (chose {r['chosen']}): self {r['self']['psnr']:.2f}/{r['self']['si_psnr']:.2f}, "
                  f"others {r['others']['psnr']:.2f}/{r['others']['si_psnr']:.2f} (const {r['others']['const_psnr']:.2f}), "
                  f"all-camera self {r['all_cameras_self']['psnr']:.2f}/{r['all_cameras_self']['si_psnr']:.2f}", flush=True)
        result["one_north"] = {"cameras": cams, "rows": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / args.name
    write_json_atomic(path, result)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
