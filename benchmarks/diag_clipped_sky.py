"""Diagnostic: how the +1 EV estimate's scale is set on the bundled sunny CAM_FRONT (93 % of the sky clipped).

Usage: ``python benchmarks/diag_clipped_sky.py [--name diag_clipped_sky]``

At EV 0 and +1 EV (the image brightened through the contract's response, as
:func:`streetaug.augment.evaluation.stability.exposure`), levels L1 and L2 at the kerb placement of
tests/evaluation/test_stability_kerb.py: the L1 fit's scale (from the ground), the mean sky radiance of the map
(L1: camera-frame map's upper hemisphere; L2: the dome's), the sun's irradiance (luminance), the ground's lit /
median luminance and the sky's clipped fraction. A stable estimate has every radiance figure x2 at +1 EV.
Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from streetaug.augment.core import luminance
from streetaug.augment.core.io import write_json_atomic
from streetaug.augment.evaluation.stability import FAMILIES
from streetaug.augment.lighting.api import estimate_views_lighting
from streetaug.augment.lighting.multiview import sky_horizontal_irradiance_world
from streetaug.augment.lighting.volume import world_envmap_directions
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

KERB_POSITION_CAM = np.array([-8.22, 1.51, 34.25])
OUT = Path(__file__).resolve().parent / "results"


def upper_mean(envmap: np.ndarray, dirs_up: np.ndarray) -> float:
    """Mean luminance of an equirect map's cells whose direction's up component (dirs_up (H, W)) is > 0.05."""
    return float(luminance(envmap[dirs_up > 0.05].astype(np.float64)).mean())


def record(sample, view, level: str) -> dict:
    """The figures of one estimate (see module doc)."""
    sl = estimate_views_lighting([view], sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                 query_point_cam=KERB_POSITION_CAM)
    est = sl.per_view[sl.reference]
    out = {"level": sl.level}
    fit = est.fit
    out["fit_scale"] = None if fit is None else float(fit.scale)
    env = est.light_cam.envmap
    H, W = env.shape[:2]
    from streetaug.augment.core import camera_envmap_directions
    up = np.asarray(fit.up_cam if fit is not None else [0, -1, 0], np.float64)
    out["l1_map_sky_mean"] = upper_mean(env, camera_envmap_directions(H, W) @ up)
    sun = est.light_cam.sun
    out["l1_sun_lum"] = None if sun is None else float(luminance(np.asarray(sun.irradiance_rgb, np.float64)))
    g = find(est.params, "ground")
    out["ground"] = {k: g[k] for k in ("lit", "shadow", "median") if isinstance(g, dict) and k in g} if g else None
    s = find(est.params, "sky")
    out["sky"] = {k: s[k] for k in ("fraction", "saturated_fraction", "median_lum") if isinstance(s, dict) and k in s} if s else None
    if sl.hybrid is not None:
        dome = np.asarray(sl.hybrid.sky_world)
        Hd, Wd = dome.shape[:2]
        out["dome_sky_mean"] = upper_mean(dome, world_envmap_directions(Hd, Wd)[..., 2])
        out["dome_sky_horizontal_irradiance"] = float(luminance(sky_horizontal_irradiance_world(dome)))
        si = sl.hybrid.sun_irradiance
        out["l2_sun_lum"] = None if si is None else float(luminance(np.asarray(si, np.float64)))
        out["sun_irradiance_factor"] = sl.params.get("sun_irradiance_factor")
        out["sky_dome_stats"] = sl.params.get("sky_dome")
    return out


def find(d, key):
    """The first value under ``key`` in a nested dict (depth first), or None."""
    if isinstance(d, dict):
        if key in d and isinstance(d[key], dict):
            return d[key]
        for v in d.values():
            r = find(v, key)
            if r is not None:
                return r
    return None


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--name", default="diag_clipped_sky")
    args = ap.parse_args()
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    view0 = sample.cameras["CAM_FRONT"]
    res = {}
    for ev in (0.0, 1.0):
        s, v, _ = FAMILIES["exposure"].apply(sample, view0, ev, None) if ev else (sample, view0, None)
        for level in ("L1", "L2"):
            res[f"{level}_ev{ev:+g}"] = record(s, v, level)
    ratios = {}
    for level in ("L1", "L2"):
        a, b = res[f"{level}_ev+0"], res[f"{level}_ev+1"]
        ratios[level] = {k: (b[k] / a[k] if isinstance(a.get(k), float) and a[k] else None)
                         for k in ("fit_scale", "l1_map_sky_mean", "l1_sun_lum", "dome_sky_mean",
                                   "dome_sky_horizontal_irradiance", "l2_sun_lum")}
        for grp in ("ground", "sky"):
            if a.get(grp) and b.get(grp):
                for k in a[grp]:
                    if k in b[grp] and a[grp][k]:
                        ratios[level][f"{grp}_{k}"] = b[grp][k] / a[grp][k]
    res["ratio_plus1_over_ev0"] = ratios
    write_json_atomic(OUT / f"{args.name}.json", res)
    import json
    print(json.dumps(res, indent=1, default=str))


if __name__ == "__main__":
    main()
