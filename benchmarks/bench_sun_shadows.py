"""Sun visibility and cloud decisions of L1 against the real shadows of annotated objects (issue 16, item 5).

Usage: ``python benchmarks/bench_sun_shadows.py [--out benchmarks/results] [--before BEFORE.json] [--quick] [--data DIR]``

Data: every keyframe x camera of ``../shared/data/nuscenes-seq`` (scene-0916, Singapore queenstown, 41 x 6) and
the one-north keyframe of ``../shared/data/nuscenes-real`` (3 cameras); skipped (exit 0, nothing written) when
the shared data are absent.

**Reference** (independent of the decision it checks: its own image resolution, its own pooling and
thresholds, fixed before looking at the decision's output). For every annotated box >= 1 m tall 4-40 m in
front of a camera, the road inside its ephemeris-predicted cast shadow against the ring of road around it
(:func:`..evidence.box_shadow_evidence`, on the image downscaled to ``REF_WIDTH`` = 800 px instead of L1's 480);
an object seen by several cameras of the sample counts once (its strongest contrast). Per sample (one instant):

* an object **shows a sun shadow** when its contrast is >= ``REF_HARD_CONTRAST`` = 2.5. Under a diffuse sky the
  road next to an object loses at most about half its sky light (ambient occlusion <= 2x, the limit at the foot
  of an endless wall), and two patches of road differ by ~25 % on their own: 2 x 1.25. A visible sun at the
  scene's elevations (48-59 deg) makes 1 + E_sun/E_sky ~ 5.5-6.4 under a clear sky.
* **sunny**: >= 2 objects show a sun shadow (one can be a coincidence: an object at the edge of a canopy's
  shade) and they are >= 20 % of the usable objects (in sunshine a good part of a street's objects stand in the
  sun); **overcast**: >= 5 usable objects and < 10 % of them show one; otherwise **no evidence**. The gap
  between 10 and 20 % is deliberate: a street deep in building shade on a sunny day is "no evidence", not
  "overcast".

Checked by eye (downscaled crops viewed in /tmp, never stored): scene-0916 keyframes 0, 10, 20, 30, 40, all six
cameras, are overcast (grey sky, wet road, no hard shadow anywhere; the strongest "shadows" are people under a
bus shelter and the dark road beside rows of parked cars); the one-north keyframe is sunny (blue sky with
clouds, hard shadows on the road and the grass). ``VISUAL_LABEL`` holds this per scene.

**Decision** (what a user gets, through the front door :mod:`..lighting.api`, level L1, with the sample's
LiDAR and boxes): per camera alone (``estimate_lighting``) and pooled (``estimate_sample_lighting`` with all the
sample's cameras). A view's call is "sun" if its sun visibility >= 0.3, "no sun" if < 0.1, else "weak".

**Measured**: confusion tables (reference verdict or visual label x call) per camera and pooled; over the
scene's keyframes per camera and pooled the spread (median, IQR, max - min) of the sun visibility and of the
sky level (the model's zenith luminance in image units, ``fit.scale`` x the sky model at the zenith); within a
sample the spread of the sun visibility (max - min) and of the sky level (max / min) across its cameras, each
estimated alone and pooled: the model's zenith (``zenith_level``, per camera on its own image's scale) and the
map's zenith (``map_zenith``, what a user renders with) divided by the camera's exposure ratio to the sample's
reference camera (``map_zenith_ref_units``; the ratios of the pooled estimate, also applied to the cameras
estimated alone): one sky for the instant makes the latter equal. With ``--before`` (a JSON written by this script on the previous decision rule) the
"before" numbers are copied next to the new ones.

Writes ``sun_shadows.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from streetaug.augment.core import (  # noqa: E402
    PinholeCamera,
    ldr_uint8_to_hdr,
    luminance,
    read_json,
    write_json_atomic,
)
from streetaug.augment.lighting.api import estimate_lighting, estimate_sample_lighting  # noqa: E402
from streetaug.augment.lighting.evidence import PreparedImage, box_shadow_evidence, downscale_image  # noqa: E402
from streetaug.augment.lighting.sky import rotation_up_from_frame, sky_radiance  # noqa: E402
from streetaug.augment.lighting.sun import sun_direction_global, up_direction_camera  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
SEQ_SCENE = "scene-0916"

REF_WIDTH = 800
REF_HARD_CONTRAST = 2.5
REF_SUNNY_MIN_OBJECTS = 2
REF_SUNNY_MIN_FRACTION = 0.2
REF_OVERCAST_MIN_OBJECTS = 5
REF_OVERCAST_MAX_FRACTION = 0.1
CALL_SUN_VIS = 0.3
CALL_NO_SUN_VIS = 0.1
VISUAL_LABEL = {SEQ_SCENE: "overcast", "one-north": "sunny"}
VERDICTS = ("sunny", "overcast", "no evidence")
CALLS = ("sun", "weak", "no sun")


def reference_objects(sample) -> dict[str, float]:
    """{box token: lit/shadow contrast} of the sample's usable objects over all its cameras (strongest view)."""
    objects: dict[str, float] = {}
    for ch in sorted(sample.cameras):
        view = sample.cameras[ch]
        small, Ks = downscale_image(np.asarray(view.image), np.asarray(view.K, dtype=np.float64), REF_WIDTH)
        h, w = small.shape[:2]
        rays = PinholeCamera(Ks, w, h).rays()
        up = up_direction_camera(view)
        work = PreparedImage(ldr_uint8_to_hdr(small).astype(np.float64), small / 255.0, rays,
                             np.arcsin(np.clip(rays @ up, -1.0, 1.0)), Ks)
        sun = sun_direction_global(sample.location, view.timestamp_us).direction_global
        ev = box_shadow_evidence(work, np.asarray(view.T_cam_from_global, dtype=np.float64), list(sample.boxes), sun)
        if ev is None:
            continue
        for i, (tok, c) in enumerate(zip(ev["per_object_token"], ev["per_object_contrast"])):
            key = tok or f"{ch}:{i}"
            objects[key] = max(objects.get(key, 0.0), float(c))
    return objects


def reference_verdict(contrasts: list[float]) -> tuple[str, int, int]:
    """("sunny" | "overcast" | "no evidence", usable objects, objects showing a sun shadow) (see module doc)."""
    c = np.asarray(contrasts, dtype=np.float64)
    n, k = len(c), int((c >= REF_HARD_CONTRAST).sum())
    if k >= REF_SUNNY_MIN_OBJECTS and k >= REF_SUNNY_MIN_FRACTION * n:
        return "sunny", n, k
    if n >= REF_OVERCAST_MIN_OBJECTS and k < REF_OVERCAST_MAX_FRACTION * n:
        return "overcast", n, k
    return "no evidence", n, k


def call(vis: float) -> str:
    """The decision's call from its sun visibility (see module doc)."""
    return "sun" if vis >= CALL_SUN_VIS else ("no sun" if vis < CALL_NO_SUN_VIS else "weak")


def zenith_level(est) -> float | None:
    """The L1 sky model's zenith luminance in image units (``fit.scale`` x the model at the zenith), or None."""
    fit = est.fit
    if fit is None:
        return None
    R_up = rotation_up_from_frame(np.asarray(fit.up_cam, dtype=np.float64), np.array([0.0, 0.0, 1.0]))
    sun_up = R_up @ np.asarray(fit.sky_sun_dir_cam, dtype=np.float64)
    z = sky_radiance(np.array([[0.0, 0.0, 1.0]]), sun_up, fit.turbidity, fit.cloud_cover, fit.ground_albedo)
    return float(fit.scale * luminance(z[0]))


def light_zenith(est) -> float | None:
    """Luminance of the estimate's map (what a user renders with) straight up, in its camera's image units."""
    if est.fit is None:
        return None
    up = np.asarray(est.fit.up_cam, dtype=np.float64)[None]
    return float(luminance(np.asarray(est.light_cam.radiance(np.zeros((1, 3)), up), dtype=np.float64)[0]))


def view_record(est, exposure_ratio: float) -> dict:
    """Sun visibility, cloud cover, scale, the model's and the map's zenith level (the map's also divided by
    the camera's exposure ratio to the sample's reference camera), call and cloud note of one L1 estimate."""
    vis = float(est.sun_visibility)
    zen = light_zenith(est)
    return {"sun_visibility": vis, "cloud_cover": None if est.fit is None else float(est.fit.cloud_cover),
            "scale": None if est.fit is None else float(est.fit.scale), "zenith_level": zenith_level(est),
            "map_zenith": zen, "map_zenith_ref_units": None if zen is None else zen / exposure_ratio,
            "call": call(vis), "reason": est.reason}


def spread(values) -> dict:
    """Median, IQR, max - min and n of the finite values (None when there are none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return {"n": 0, "median": None, "iqr": None, "range": None}
    q1, q2, q3 = np.percentile(v, [25, 50, 75])
    return {"n": int(len(v)), "median": float(q2), "iqr": float(q3 - q1), "range": float(v.max() - v.min())}


def confusion(pairs) -> dict:
    """{truth: {call: count}} of (truth, call) pairs."""
    table = {}
    for truth, c in pairs:
        row = table.setdefault(truth, {k: 0 for k in CALLS})
        row[c] += 1
    return table


def error_rates(pairs) -> dict:
    """Fractions of sunny frames called "no sun" and of overcast frames called "sun" (and their counts)."""
    sunny = [c for t, c in pairs if t == "sunny"]
    over = [c for t, c in pairs if t == "overcast"]
    return {"sunny_called_no_sun": (sum(c == "no sun" for c in sunny) / len(sunny)) if sunny else None,
            "sunny_not_called_sun": (sum(c != "sun" for c in sunny) / len(sunny)) if sunny else None,
            "overcast_called_sun": (sum(c == "sun" for c in over) / len(over)) if over else None,
            "overcast_not_called_no_sun": (sum(c != "no sun" for c in over) / len(over)) if over else None,
            "n_sunny": len(sunny), "n_overcast": len(over)}


def run_sample(sample, scene: str, keyframe: int) -> dict:
    """Reference and decisions (each camera alone; all cameras pooled) of one sample."""
    objects = reference_objects(sample)
    verdict, n, k = reference_verdict(list(objects.values()))
    cams = sorted(sample.cameras)
    t0 = time.perf_counter()
    alone_est = {ch: estimate_lighting(sample.cameras[ch], sample.location, "L1", lidar=sample.lidar,
                                       boxes=sample.boxes) for ch in cams}
    t1 = time.perf_counter()
    pooled_l = estimate_sample_lighting(sample, cams, "L1")
    t2 = time.perf_counter()
    ratios = {ch: float(pooled_l.exposure_ratio.get(ch, 1.0)) for ch in cams}  # camera / reference camera
    alone = {ch: view_record(alone_est[ch], ratios[ch]) for ch in cams}
    pooled = {ch: view_record(pooled_l.per_view[ch], ratios[ch]) for ch in cams}
    return {"scene": scene, "keyframe": keyframe, "token": sample.token, "reference": verdict,
            "reference_objects": n, "reference_sun_shadows": k,
            "reference_contrasts": sorted(round(c, 3) for c in objects.values()),
            "visual_label": VISUAL_LABEL[scene], "reference_camera": pooled_l.reference,
            "exposure_ratio": ratios, "alone": alone, "pooled": pooled,
            "seconds_alone": t1 - t0, "seconds_pooled": t2 - t1}


def summarise(samples: list[dict]) -> dict:
    """Confusion tables, error rates, spreads over keyframes and within samples."""
    out: dict = {}
    for truth_key in ("reference", "visual_label"):
        for mode in ("alone", "pooled"):
            pairs = [(s[truth_key], r["call"]) for s in samples for r in s[mode].values()]
            out[f"confusion_{mode}_vs_{truth_key}"] = confusion(pairs)
            out[f"errors_{mode}_vs_{truth_key}"] = error_rates(pairs)
    seq = [s for s in samples if s["scene"] == SEQ_SCENE]
    if seq:
        cams = sorted(seq[0]["alone"])
        over_keyframes = {}
        for mode in ("alone", "pooled"):
            over_keyframes[mode] = {ch: {"sun_visibility": spread([s[mode][ch]["sun_visibility"] for s in seq]),
                                         "log10_zenith_level": spread([np.log10(s[mode][ch]["zenith_level"])
                                                                       for s in seq if s[mode][ch]["zenith_level"]]),
                                         "log10_map_zenith": spread([np.log10(s[mode][ch]["map_zenith"])
                                                                     for s in seq if s[mode][ch]["map_zenith"]])}
                                    for ch in cams}
        out["spread_over_keyframes"] = over_keyframes
    within = {}
    for mode in ("alone", "pooled"):
        vis_range, level_ratio, map_ratio = [], [], []
        for s in samples:
            vis = [r["sun_visibility"] for r in s[mode].values()]
            lev = [r["zenith_level"] for r in s[mode].values() if r["zenith_level"]]
            ref = [r["map_zenith_ref_units"] for r in s[mode].values() if r["map_zenith_ref_units"]]
            vis_range.append(max(vis) - min(vis))
            if lev:
                level_ratio.append(max(lev) / min(lev))
            if ref:
                map_ratio.append(max(ref) / min(ref))
        within[mode] = {"sun_visibility_range": spread(vis_range), "zenith_level_max_over_min": spread(level_ratio),
                        "map_zenith_ref_units_max_over_min": spread(map_ratio),
                        "samples_with_equal_sun_visibility": int(sum(r < 1e-9 for r in vis_range)),
                        "samples": len(vis_range)}
    out["within_sample"] = within
    out["reference_verdicts"] = {v: sum(s["reference"] == v for s in samples) for v in VERDICTS}
    return out


def git_head() -> str:
    """The repository's HEAD commit, or '' outside git."""
    try:
        return subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    ap.add_argument("--before", type=Path, default=None, help="a sun_shadows.json of the previous decision rule")
    ap.add_argument("--quick", action="store_true", help="every 8th keyframe only")
    ap.add_argument("--data", type=Path, default=SHARED, help="the shared data folder (nuscenes-seq, nuscenes-real)")
    args = ap.parse_args()
    SEQ, REAL = args.data / "nuscenes-seq", args.data / "nuscenes-real"
    if not (SEQ / "v1.0-mini").is_dir() or not (REAL / "v1.0-mini").is_dir():
        print(f"shared data not found under {args.data}: nothing measured")
        return 0
    t0 = time.perf_counter()
    samples = [run_sample(NuScenesReader(str(REAL), "v1.0-mini").sample(REAL_SAMPLE), "one-north", 0)]
    reader = NuScenesReader(str(SEQ), "v1.0-mini")
    tokens = reader.sample_tokens(SEQ_SCENE)
    for k in (range(0, len(tokens), 8) if args.quick else range(len(tokens))):
        s = run_sample(reader.sample(tokens[k]), SEQ_SCENE, k)
        samples.append(s)
        print(f"{SEQ_SCENE} keyframe {k:2d}: reference {s['reference']:11s} ({s['reference_sun_shadows']}/"
              f"{s['reference_objects']}), alone vis " + " ".join(f"{r['sun_visibility']:.2f}" for r in s['alone'].values())
              + f", pooled vis {next(iter(s['pooled'].values()))['sun_visibility']:.2f}", flush=True)
    summary = summarise(samples)
    result = {"what": "L1 sun visibility / cloud decisions against the shadows of annotated objects (issue 16.5)",
              "git_head": git_head(), "platform": platform.platform(), "seconds": time.perf_counter() - t0,
              "reference_rule": {"width_px": REF_WIDTH, "hard_contrast": REF_HARD_CONTRAST,
                                 "sunny": f">= {REF_SUNNY_MIN_OBJECTS} objects and >= {REF_SUNNY_MIN_FRACTION:.0%}",
                                 "overcast": f">= {REF_OVERCAST_MIN_OBJECTS} objects and < "
                                             f"{REF_OVERCAST_MAX_FRACTION:.0%}"},
              "call_rule": {"sun": f"visibility >= {CALL_SUN_VIS}", "no sun": f"visibility < {CALL_NO_SUN_VIS}"},
              "visual_label": VISUAL_LABEL, "summary": summary, "samples": samples}
    if args.before is not None:
        before = read_json(args.before)
        result["before"] = {"git_head": before.get("git_head"), "summary": before["summary"]}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "sun_shadows.json", result)
    for key in ("errors_alone_vs_visual_label", "errors_pooled_vs_visual_label", "errors_alone_vs_reference",
                "errors_pooled_vs_reference"):
        print(key, summary[key])
    print("within sample", summary["within_sample"])
    print("reference verdicts", summary["reference_verdicts"])
    print(f"wrote {args.out / 'sun_shadows.json'} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
