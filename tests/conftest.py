"""Shared test helpers.

``devkit()`` imports the official nuScenes devkit for parity tests. ``make test`` (and so CI) installs
it and sets ``STREETAUG_REQUIRE_DEVKIT=1``: there a missing devkit is a failure, not a skip.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"  # real data for development (never copied into the repository)
HDRI = SHARED_DATA / "hdri"
needs_hdri = pytest.mark.skipif(not (HDRI / "index.json").is_file(), reason=f"{HDRI} (real HDR panoramas) not present")


def devkit():
    """The ``nuscenes.nuscenes`` module, or skip (fail when STREETAUG_REQUIRE_DEVKIT=1)."""
    try:
        return importlib.import_module("nuscenes.nuscenes")
    except ImportError as e:
        if os.environ.get("STREETAUG_REQUIRE_DEVKIT") == "1":
            pytest.fail(f"nuscenes-devkit is required here (STREETAUG_REQUIRE_DEVKIT=1) but not importable: {e}")
        pytest.skip("nuscenes-devkit not installed (make test installs it)")


def unit(v):
    """``v`` as a float64 unit vector."""
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


@pytest.fixture(scope="session")
def models():
    """The shipped learned-sky networks, on one torch thread (as the benchmarks time them)."""
    import torch  # deferred: only the learned-sky tests need it

    from streetaug.augment.lighting.skynet.predict import get_models

    torch.set_num_threads(1)
    return get_models()

