"""The shipped image predictor on real street photos it was not trained on (issue 16).

Needs the real dev scene ``../shared/data/nuscenes-seq`` (skips without it). Truth: the ephemeris sun of each
view rotated into its camera; the image is passed bare (no metadata, a level camera assumed), as the lighting
front door does.  The bound comes from ``benchmarks/bench_sky.py --real`` (see the model card) with a margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SHARED_DATA
from streetaug.augment.core import read_image_rgb
from streetaug.augment.lighting.skynet.dome import angle_deg
from streetaug.augment.lighting.skynet.weights import LIGHT_WEIGHTS, packaged_weights, read_weights
from streetaug.augment.training.real import (
    HELDOUT_PANORAMAS,
    TEST_KEYFRAMES,
    TRAIN_KEYFRAMES,
    bare_image_prediction,
    street_photos,
)

SEQ = SHARED_DATA / "nuscenes-seq"
needs_seq = pytest.mark.skipif(not (SEQ / "v1.0-mini").is_dir(),
                               reason=f"{SEQ} (the real dev scene scene-0916) not present")
SUBSET = TEST_KEYFRAMES[::4]  # keyframes 27, 31, 35, 39 of the 14 held out, x 6 cameras (time)
# Median sun error (deg) of the predictor's direction over SUBSET (bench_sky.py --real): the shipped v2 62.5; the
# v3 candidate fine-tuned on keyframes 0-23 (not shipped, see the model card) 54.1. The bound holds the shipped
# model with a margin.
SHIPPED_MEDIAN_DEG = 62.5
BOUND_DEG = 70.0


def test_shipped_weights_never_saw_the_held_out_sets():
    """The shipped weights record what they were trained on: no held-out keyframe, no held-out panorama."""
    meta = read_weights(packaged_weights(LIGHT_WEIGHTS), "light")["meta"]
    keyframes = meta["config"].get("real_keyframes", [])  # absent: trained on no real street photo (v2)
    assert max(TRAIN_KEYFRAMES) + 1 < min(TEST_KEYFRAMES)  # a gap between the blocks
    assert set(keyframes) <= set(TRAIN_KEYFRAMES)
    assert not set(meta["train_panoramas"]) & set(HELDOUT_PANORAMAS)
    assert meta.get("real_photos", 0) == 6 * len(keyframes)


@needs_seq
def test_sun_error_on_held_out_keyframes(models):
    photos = street_photos(SEQ, keyframes=SUBSET, shadows=False)
    assert len(photos) == 6 * len(SUBSET)
    errs = np.array([angle_deg(bare_image_prediction(read_image_rgb(p.image_path), p.K, models).direction_cam,
                               p.sun_dir_cam) for p in photos])
    assert np.all(np.isfinite(errs))
    assert float(np.median(errs)) <= BOUND_DEG, (float(np.median(errs)), np.round(errs).tolist())
