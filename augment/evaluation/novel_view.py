"""Novel-view radiance: how well a lighting estimate predicts what a camera sees (the paper's lighting metric).

A camera's view is *rendered from the lighting* (:func:`..lighting.predicted_view.predicted_radiance`: the light
field at the camera's centre along each pixel's ray, i.e. the local environment map there at full resolution),
passed through the contract's camera response at EV 0 and compared with the real image shrunk to ``width``
pixels (area filter). From a centre no input camera stood at, the rendered view is the *expected* view: each
pixel blurred by how uncertain the place of what it shows is (:func:`..lighting.predicted_view.uncertainty_blurred`),
which is what these squared-error scores reward; an input camera's own view is not blurred.

* **PSNR** of the LDR images in [0, 1];
* **si-PSNR**: the prediction scaled by its least-squares factor first (the paper's scale-invariant PSNR).

A *self view* (the lighting rendered into a camera it was built from) measures whether the map is on the
image's scale: its PSNR is within a dB of its si-PSNR when it is. The paper's protocol (:func:`paper_pairs`) is
the lighting from the front camera at keyframe *t* against the front camera's real view at *t* + 3 (1.5 s
later) through the map at the new camera centre.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ...datasets.sample import CameraView
from ..core import hdr_to_ldr
from ..lighting.predicted_view import PREDICTED_WIDTH_PX as NOVEL_WIDTH_PX
from ..lighting.predicted_view import observed_ldr as real_view
from ..lighting.predicted_view import predicted_radiance
from ..lighting.types import SampleLighting
from .metrics import psnr_db


def psnr(pred: np.ndarray, truth: np.ndarray) -> float:
    """PSNR (dB) of images in [0, 1]."""
    return psnr_db(pred, truth, peak=1.0)


def si_psnr(pred: np.ndarray, truth: np.ndarray) -> float:
    """PSNR after scaling ``pred`` by the least-squares factor onto ``truth`` (clipped to [0, 1])."""
    s = float((pred * truth).sum() / max(float((pred * pred).sum()), 1e-12))
    return psnr(np.clip(s * pred, 0.0, 1.0), truth)


def view_scores(radiance: np.ndarray, truth: np.ndarray) -> dict:
    """{"psnr", "si_psnr"} of a predicted view (linear radiance, EV 0) against the real one ([0, 1])."""
    pred = hdr_to_ldr(radiance)
    return {"psnr": psnr(pred, truth), "si_psnr": si_psnr(pred, truth)}


def constant_colour_scores(source_images: Sequence[np.ndarray], truth: np.ndarray) -> dict:
    """The baseline a prediction must beat: the sources' mean LDR colour everywhere (no structure)."""
    mean = np.mean([np.asarray(im, np.float64).reshape(-1, 3).mean(axis=0) / 255.0 for im in source_images], axis=0)
    pred = np.broadcast_to(mean, truth.shape)
    return {"psnr": psnr(pred, truth), "si_psnr": si_psnr(pred, truth)}


def score_lighting(lighting: SampleLighting, target: CameraView, width: int = NOVEL_WIDTH_PX) -> dict:
    """{"psnr", "si_psnr"} of ``lighting`` rendered into ``target`` against its real image."""
    return view_scores(predicted_radiance(lighting, target, width), real_view(target, width))


def paper_pairs(n_keyframes: int, offset: int = 3) -> list[tuple[int, int]]:
    """(source, target) keyframe indices of the paper's protocol: every keyframe t with t + offset."""
    return [(t, t + offset) for t in range(max(n_keyframes - offset, 0))]


def median_scores(rows: Sequence[dict], keys: Sequence[str] = ("psnr", "si_psnr")) -> dict:
    """Median and count of each score over rows (nan-free)."""
    out: dict = {"n": len(rows)}
    for k in keys:
        vals = [r[k] for r in rows if k in r and np.isfinite(r[k])]
        out[k] = float(np.median(vals)) if vals else None
    return out
