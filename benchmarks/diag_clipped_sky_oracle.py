"""Diagnostic: how much of test_stability_kerb's L2 +1 EV gap is the clipped sky's level.

Usage: ``python benchmarks/diag_clipped_sky_oracle.py [--factors 1,1.13,1.26] [--name diag_clipped_sky_oracle]``

The bundled sunny CAM_FRONT, L2, draft, seed 0, the default placement (the kerb test's): the +1 EV run's sky
dome and sun are multiplied by a factor k (the dome after build_sky_dome; the sun so that it is k times what
it would be, whatever the dome's correction), the EV 0 run untouched; the stability report's lighting and
composite PSNR (dB) per k (k = EV 0's sky gain over +1 EV's, about 1.26, is the oracle; also the dome alone and
the sun alone at 1.26). Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import streetaug.augment.lighting.multiview as mv
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core.io import write_json_atomic
from streetaug.augment.evaluation.stability import FAMILIES, measure, run_once
from streetaug.augment.pipeline import InsertOptions
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

OUT = Path(__file__).resolve().parent / "results"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--factors", default="1,1.08,1.13,1.18,1.26,1.4")
    ap.add_argument("--name", default="diag_clipped_sky_oracle")
    args = ap.parse_args()
    orig_dome, orig_sun = mv.build_sky_dome, mv.sun_factor
    state = {"dome": 1.0, "sun": 1.0}

    def dome_fn(*a, **k):
        d, s = orig_dome(*a, **k)
        return (d * state["dome"]).astype(np.float32), s

    def sun_fn(dome, model):
        f, how = orig_sun(dome, model)
        return f / state["dome"] * state["sun"], how

    mv.build_sky_dome, mv.sun_factor = dome_fn, sun_fn
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
    view, car = sample.cameras["CAM_FRONT"], procedural_car(3)
    options = InsertOptions(quality="draft", seed=0, level="L2")
    base = run_once(sample, view, [car], options)
    cases = [(float(k), float(k)) for k in args.factors.split(",")] + [(1.26, 1.0), (1.0, 1.26)]
    rows = []
    for dome_k, sun_k in cases:
        state.update(dome=dome_k, sun=sun_k)
        row = measure(sample, view, [car], options, FAMILIES["exposure"], 1.0, base)
        rows.append({"dome_factor": dome_k, "sun_factor": sun_k, "lighting_psnr_db": row["lighting_psnr_db"],
                     "composite_psnr_db": row["composite_psnr_db"]})
        print(rows[-1])
    write_json_atomic(OUT / f"{args.name}.json", {"level": "L2", "ev": 1.0, "rows": rows})


if __name__ == "__main__":
    main()
