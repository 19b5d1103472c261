"""The prior of the sky's image/model ratio, measured on unclipped skies: what a clipped sky's level is likely to be.

Usage: ``python benchmarks/fit_sky_gain_prior.py [--name sky_gain_prior] [--cameras CAM_FRONT]``

Per image at EV 0 (the bundled samples and scene-0916's keyframes in ``../shared/data/nuscenes-seq``), the L1
fit (its model's scale set by the ground) and the image's sky pixels (:func:`.evidence.image_sky_mask`): per
channel the log ratio of the medians of the sky's radiance and of the model's there
(:func:`.image_dome.sky_log_gain`), kept where fewer than half of the channel is clipped (the median is then
exact), and where more than half is clipped as a lower bound (censored: the sky is at least that bright). The
prior is a normal per channel fitted by maximum likelihood to both (a Tobit fit: the exact gains' density times
the censored ones' probability of lying above their bound), since a clipped sky is a brighter sky than an
unclipped one (the unclipped skies alone are the darker part). Also the exact gains' mean and standard
deviation. Writes ``benchmarks/results/<name>.json``.
Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from streetaug.augment.core.io import write_json_atomic
from streetaug.augment.lighting.image_dome import map_cells, seen_pixels
from streetaug.augment.lighting.parametric import view_inputs
from streetaug.augment.lighting.api import _work, view_estimate
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
OUT = Path(__file__).resolve().parent / "results"


def image_gain(sample, channel: str) -> dict | None:
    """The sky's log gain (3,) of one camera at EV 0 and its clipped fraction per channel, or None (no sky)."""
    view = sample.cameras[channel]
    vi = view_inputs(view, sample.location, {}, sample.boxes, sample.lidar)
    if vi.sun_pos is None or vi.sun_pos.elevation_deg <= 0.0:
        return None
    est = view_estimate(vi, {})
    work = _work(vi)
    px = seen_pixels(work)
    if px.sky.sum() < 200:
        return None
    env = est.light_cam.envmap.astype(np.float64)
    H, W = env.shape[:2]
    model = env.reshape(-1, 3)[map_cells(px.rays[px.sky], H, W)]
    rad = px.radiance[px.sky]
    clipped = px.clipped_rgb[px.sky].mean(axis=0)
    gain = np.log(np.maximum(np.median(rad, axis=0), 1e-9) / np.maximum(np.median(model, axis=0), 1e-9))
    return {"sample": sample.token, "channel": channel, "sky_pixels": int(px.sky.sum()),
            "clipped_fraction_rgb": clipped.tolist(), "log_gain_rgb": gain.tolist(),
            "exact": bool((clipped < 0.5).all())}


def tobit_fit(values: np.ndarray, censored: np.ndarray) -> tuple[float, float]:
    """(mean, std) of a normal fitted by maximum likelihood to ``values`` (N,), of which ``censored`` (N,) bool are
    lower bounds."""
    from scipy.optimize import minimize
    from scipy.stats import norm

    def nll(p: np.ndarray) -> float:
        mu, log_s = p
        s = np.exp(log_s)
        return -(norm.logpdf(values[~censored], mu, s).sum() + norm.logsf(values[censored], mu, s).sum())

    r = minimize(nll, np.array([values.mean(), np.log(values.std() + 1e-3)]), method="Nelder-Mead")
    return float(r.x[0]), float(np.exp(r.x[1]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--name", default="sky_gain_prior")
    ap.add_argument("--cameras", default="CAM_FRONT")
    args = ap.parse_args()
    cams = args.cameras.split(",")
    rows = []
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    for tok in reader.sample_tokens():
        s = reader.sample(tok)
        rows += [r | {"set": "bundled"} for c in cams if c in s.cameras and (r := image_gain(s, c)) is not None]
    reader = NuScenesReader(SEQ, "v1.0-mini")
    for tok in reader.sample_tokens("scene-0916"):
        s = reader.sample(tok)
        rows += [r | {"set": "scene-0916"} for c in cams if c in s.cameras and (r := image_gain(s, c)) is not None]
    exact = np.array([r["log_gain_rgb"] for r in rows if r["exact"]])
    summary = {"images": len(rows), "exact": int(len(exact)),
               "mean_log_gain_rgb": exact.mean(axis=0).tolist() if len(exact) else None,
               "std_log_gain_rgb": exact.std(axis=0, ddof=1).tolist() if len(exact) > 1 else None,
               "median_log_gain_rgb": np.median(exact, axis=0).tolist() if len(exact) else None,
               "cameras": cams}
    gains = np.array([r["log_gain_rgb"] for r in rows])
    cens = np.array([r["clipped_fraction_rgb"] for r in rows]) >= 0.5
    fits = [tobit_fit(gains[:, c], cens[:, c]) for c in range(3)]
    summary["tobit_mean_rgb"] = [f[0] for f in fits]
    summary["tobit_std_rgb"] = [f[1] for f in fits]
    summary["censored_rgb"] = cens.sum(axis=0).tolist()
    for st in ("bundled", "scene-0916"):
        e = np.array([r["log_gain_rgb"] for r in rows if r["exact"] and r["set"] == st])
        summary[st] = {"exact": int(len(e)), "mean": e.mean(axis=0).tolist() if len(e) else None,
                       "std": e.std(axis=0, ddof=1).tolist() if len(e) > 1 else None}
    write_json_atomic(OUT / f"{args.name}.json", {"summary": summary, "rows": rows})
    import json
    print(json.dumps(summary, indent=1))
    for r in rows:
        print(r["set"], r["sample"][:12], r["channel"], np.round(r["log_gain_rgb"], 3), np.round(r["clipped_fraction_rgb"], 2))


if __name__ == "__main__":
    main()
