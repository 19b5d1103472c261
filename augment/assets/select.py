"""Choose the assets for an insertion from the CLI options: one file, a folder, or procedural objects.

Without a class mix (``--classes`` / ``--class-weights``) procedural objects are cars, as they always were;
with one, each object's class is drawn by weight and built by :func:`~.classes.procedural_object`, or drawn
from the folder's files of that class (their categories from :func:`~.categories.category_for_asset`).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from ..core import InputError
from .asset import Asset
from .car_paint import paint_region_for_location
from .categories import category_for_asset
from .class_sizes import read_class_sizes
from .classes import CLASS_CATEGORIES, ClassMix, procedural_object
from .loader import list_assets, load_asset
from .number_plates import plate_style_for_location
from .procedural import procedural_car

# Procedural seeds are drawn from [0, _SEED_RANGE); keeping it moderate lets the cache hit across a batch.
_SEED_RANGE = 4096


def load_asset_options(asset: str | Path, asset_front: str = "+z", asset_length: float | None = None) -> Asset:
    """Load one asset file with the CLI's ``--asset-front`` / ``--asset-length`` options (cached)."""
    return load_asset(asset, front_axis=asset_front, length_m=asset_length)


@lru_cache(maxsize=64)
def _procedural(seed: int, plate_style: str = "eu", paint_region: str = "global", anonymised_plates: bool = True,
                paint_weights: tuple[float, ...] | None = None) -> Asset:
    return procedural_car(seed, plate_style=plate_style, paint_region=paint_region, anonymised_plates=anonymised_plates,
                          paint_weights=paint_weights)


@lru_cache(maxsize=256)
def _procedural_of(detection_class: str, seed: int, still: bool = False, sizes_path: str | None = None,
                   plate_style: str = "eu", paint_region: str = "global", anonymised_plates: bool = True,
                   paint_weights: tuple[float, ...] | None = None) -> Asset:
    return procedural_object(detection_class, seed, read_class_sizes(sizes_path), still=still, plate_style=plate_style,
                             paint_region=paint_region, anonymised_plates=anonymised_plates,
                             paint_weights=paint_weights)


def forget_procedural_assets() -> None:
    """Empty the caches of procedural objects :func:`select_assets` built (each keeps its mesh, BVH and bounce
    data, ~3.5 MB): for callers whose next draws will not repeat them (a batch worker between samples)."""
    _procedural.cache_clear()
    _procedural_of.cache_clear()


CATEGORY_CLASS = {category: name for name, options in CLASS_CATEGORIES.items() for category, _, _ in options}


def _files_by_class(assets_dir: str | Path) -> dict[str, list[Path]]:
    out: dict[str, list[Path]] = {}
    for f in list_assets(assets_dir):
        name = CATEGORY_CLASS.get(category_for_asset(f))
        if name is not None:
            out.setdefault(name, []).append(f)
    return out


def select_assets(
    rng: np.random.Generator,
    n_objects: int,
    asset: str | Path | None = None,
    assets_dir: str | Path | None = None,
    asset_front: str = "+z",
    asset_length: float | None = None,
    class_mix: ClassMix | None = None,
    still: bool = False,
    class_sizes: str | Path | None = None,
    location: str | None = None,
    anonymised_plates: bool = True,
    paint_weights: tuple[float, ...] | None = None,
) -> list[Asset]:
    """``n_objects`` assets: the file ``asset`` repeated, random files of ``assets_dir``, or procedural objects.

    Args:
        rng: seeded generator (deterministic choice per item).
        n_objects: number of objects to insert (>= 1).
        asset: one asset file (wins over ``assets_dir``).
        assets_dir: a folder of asset files to sample from (uniformly, with replacement).
        asset_front, asset_length: loader options for files (see :func:`load_asset`).
        class_mix: the classes to draw from (None: procedural cars, or any file of the folder). With a folder,
            only classes that have files can be drawn (an error names the classes without any).
        still: procedural objects for a whole track (standing pedestrians, riderless two-wheelers).
        class_sizes: a class-sizes table (``streetaug class-sizes``) procedural objects are sized from (None:
            the shipped one).
        location: the scene's ``log.location`` (its map name): procedural cars get its country's number
            plates and driving side (:func:`~.number_plates.plate_style_for_location`; None: ``eu``) and
            its region's paint colours (:func:`~.car_paint.paint_region_for_location`; None: ``global``).
        anonymised_plates: procedural cars' plates without characters, in the plate's mean colour (the
            default: nuScenes' images blur every plate, so readable plates would give inserted cars away);
            False: readable characters.
        paint_weights: procedural cars' paint draw, a weight per shade of the location's palette (the scene's
            own cars: :func:`~.scene_paint.scene_paint_mix`); None: the region's table.
    """
    if n_objects < 1:
        raise ValueError(f"n_objects must be >= 1, got {n_objects}")
    plate_style = "eu" if location is None else plate_style_for_location(location)
    paint_region = paint_region_for_location(location)
    if asset is not None:
        return [load_asset_options(asset, asset_front, asset_length)] * n_objects
    if assets_dir is not None and class_mix is not None:
        by_class = _files_by_class(assets_dir)
        missing = [c for c, w in zip(class_mix.classes, class_mix.weights) if w > 0 and c not in by_class]
        if missing:
            raise InputError(f"{assets_dir}: no asset file of class(es) {', '.join(missing)} (file categories come "
                             f"from their names or the folder's categories.json); classes with files: "
                             f"{', '.join(sorted(by_class)) or 'none'}")
        out = []
        for name in class_mix.draw(rng, n_objects):
            files = by_class[name]
            out.append(load_asset_options(files[int(rng.integers(0, len(files)))], asset_front, asset_length))
        return out
    if assets_dir is not None:
        files = list_assets(assets_dir)
        picks = rng.integers(0, len(files), size=n_objects)
        return [load_asset_options(files[int(i)], asset_front, asset_length) for i in picks]
    if class_mix is not None:
        names = class_mix.draw(rng, n_objects)
        sizes_path = None if class_sizes is None else str(class_sizes)
        return [_procedural_of(name, int(s), still, sizes_path, plate_style, paint_region, anonymised_plates,
                               paint_weights)
                for name, s in zip(names, rng.integers(0, _SEED_RANGE, size=n_objects))]
    return [_procedural(int(s), plate_style, paint_region, anonymised_plates, paint_weights)
            for s in rng.integers(0, _SEED_RANGE, size=n_objects)]
