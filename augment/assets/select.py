"""Choose the assets for an insertion from the CLI options: one file, a folder, or procedural cars."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from .asset import Asset
from .loader import list_assets, load_asset
from .procedural import procedural_car

# Procedural seeds are drawn from [0, _SEED_RANGE); keeping it moderate lets the cache hit across a batch.
_SEED_RANGE = 4096


def load_asset_options(asset: str | Path, asset_front: str = "+z", asset_length: float | None = None) -> Asset:
    """Load one asset file with the CLI's ``--asset-front`` / ``--asset-length`` options (cached)."""
    return load_asset(asset, front_axis=asset_front, length_m=asset_length)


@lru_cache(maxsize=64)
def _procedural(seed: int) -> Asset:
    return procedural_car(seed)


def select_assets(
    rng: np.random.Generator,
    n_objects: int,
    asset: str | Path | None = None,
    assets_dir: str | Path | None = None,
    asset_front: str = "+z",
    asset_length: float | None = None,
) -> list[Asset]:
    """``n_objects`` assets: the file ``asset`` repeated, random files of ``assets_dir``, or procedural cars.

    Args:
        rng: seeded generator (deterministic choice per item).
        n_objects: number of objects to insert (>= 1).
        asset: one asset file (wins over ``assets_dir``).
        assets_dir: a folder of asset files to sample from (uniformly, with replacement).
        asset_front, asset_length: loader options for files (see :func:`load_asset`).
    """
    if n_objects < 1:
        raise ValueError(f"n_objects must be >= 1, got {n_objects}")
    if asset is not None:
        return [load_asset_options(asset, asset_front, asset_length)] * n_objects
    if assets_dir is not None:
        files = list_assets(assets_dir)
        picks = rng.integers(0, len(files), size=n_objects)
        return [load_asset_options(files[int(i)], asset_front, asset_length) for i in picks]
    return [_procedural(int(s)) for s in rng.integers(0, _SEED_RANGE, size=n_objects)]
