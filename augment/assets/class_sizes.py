"""The box sizes procedural assets are built to, per nuScenes category, and how a size is drawn.

The shipped table ``class_sizes.json`` (beside this module) was measured from nuScenes annotations
(:func:`streetaug.datasets.box_statistics.measure_box_sizes`, over instances) and merged with a typical-size
prior per category (:data:`PRIOR_SIZES`, real-world dimensions) by :func:`merge_with_prior`:

* a category with at least ``MIN_INSTANCES_FOR_SPREAD`` measured instances takes its measured mean, spread
  and range (the spread at least half the prior's and the range at least mean +- 2 std inside the prior's:
  one city's instances under-sample a class's variety);
* a category with fewer takes its measured mean where there is one, and the prior's spread and range
  (widened to include what was measured);
* a category with none keeps the prior (``source: "prior"``).

Each entry states how many boxes and instances its numbers come from. Sizes are [w, l, h] in metres
(nuScenes ``size``). A user regenerates the table from their own dataset with ``streetaug class-sizes``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..core import InputError

CLASS_SIZES_PATH = Path(__file__).with_name("class_sizes.json")
SCHEMA = "streetaug.class_sizes/1"
MIN_INSTANCES_FOR_SPREAD = 5

# Typical real-world sizes [w, l, h] (m): mean, spread (1 std) and a plausible range, from manufacturers'
# dimensions and traffic-equipment standards (our own summary; not taken from any dataset).
PRIOR_SIZES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float],
                             tuple[float, float, float], tuple[float, float, float]]] = {
    # category: (mean, std, min, max)
    "vehicle.car": ((1.95, 4.60, 1.70), (0.15, 0.40, 0.20), (1.55, 3.40, 1.35), (2.30, 5.60, 2.30)),
    "vehicle.truck": ((2.50, 6.90, 2.90), (0.35, 2.20, 0.70), (1.80, 4.50, 1.80), (3.00, 12.0, 4.20)),
    "vehicle.bus.rigid": ((2.95, 11.2, 3.45), (0.20, 1.50, 0.35), (2.40, 7.50, 2.70), (3.20, 15.0, 4.40)),
    "vehicle.bus.bendy": ((2.90, 17.5, 3.30), (0.15, 1.20, 0.20), (2.50, 15.0, 2.90), (3.10, 21.0, 3.60)),
    "vehicle.trailer": ((2.80, 10.5, 3.60), (0.30, 3.00, 0.60), (1.80, 3.00, 1.50), (3.10, 16.0, 4.30)),
    "vehicle.construction": ((2.80, 6.40, 3.20), (0.50, 1.80, 0.70), (1.50, 2.60, 2.00), (3.60, 11.0, 4.50)),
    "vehicle.motorcycle": ((0.80, 2.10, 1.45), (0.12, 0.22, 0.18), (0.55, 1.60, 1.00), (1.20, 2.70, 1.90)),
    "vehicle.bicycle": ((0.62, 1.72, 1.30), (0.12, 0.18, 0.25), (0.40, 1.40, 0.90), (1.00, 2.10, 1.95)),
    "human.pedestrian.adult": ((0.68, 0.73, 1.75), (0.12, 0.20, 0.10), (0.40, 0.35, 1.45), (1.10, 1.30, 2.05)),
    "human.pedestrian.child": ((0.52, 0.52, 1.25), (0.08, 0.12, 0.15), (0.35, 0.30, 0.90), (0.80, 0.90, 1.55)),
    "movable_object.trafficcone": ((0.42, 0.42, 0.95), (0.08, 0.08, 0.20), (0.25, 0.25, 0.45), (0.65, 0.65, 1.30)),
    "movable_object.barrier": ((2.20, 0.55, 1.00), (0.60, 0.15, 0.12), (0.90, 0.30, 0.75), (3.60, 0.90, 1.30)),
}


@dataclass(frozen=True)
class CategorySize:
    """The size statistics of one category ([w, l, h] metres, (3,) float64 arrays).

    Attributes:
        category: nuScenes category name.
        mean_wlh, std_wlh, min_wlh, max_wlh: the distribution a size is drawn from (:func:`draw_wlh`).
        n_instances, n_boxes: how many annotated instances / boxes the numbers come from (0 = the prior).
        source: ``"nuscenes"`` (all measured), ``"nuscenes+prior"`` (mean measured, spread from the prior)
            or ``"prior"``.
    """

    category: str
    mean_wlh: np.ndarray
    std_wlh: np.ndarray
    min_wlh: np.ndarray
    max_wlh: np.ndarray
    n_instances: int
    n_boxes: int
    source: str


def merge_with_prior(measured: dict[str, dict]) -> dict[str, dict]:
    """The table entries (JSON-ready) of every prior category, merged with ``measured`` as the module says.

    ``measured`` is :func:`streetaug.datasets.box_statistics.measure_box_sizes`'s result; categories
    without a prior are kept only when they have enough instances.
    """
    out = {}
    for category in sorted(set(PRIOR_SIZES) | set(measured)):
        m = measured.get(category)
        prior = PRIOR_SIZES.get(category)
        if prior is None and (m is None or m["n_instances"] < MIN_INSTANCES_FOR_SPREAD):
            continue
        if m is not None and prior is None:
            entry = {k: m[k] for k in ("mean_wlh", "std_wlh", "min_wlh", "max_wlh")}
            source = "nuscenes"
        elif m is not None and m["n_instances"] >= MIN_INSTANCES_FOR_SPREAD:
            # a few sites' instances under-sample a class's variety: keep at least half the prior's spread,
            # and a range of at least mean +- 2 std within the prior's plausible one
            mean = np.asarray(m["mean_wlh"])
            std = np.maximum(m["std_wlh"], 0.5 * np.asarray(prior[1]))
            lo = np.minimum(m["min_wlh"], np.maximum(prior[2], mean - 2 * std))
            hi = np.maximum(m["max_wlh"], np.minimum(prior[3], mean + 2 * std))
            entry = {"mean_wlh": m["mean_wlh"], "std_wlh": np.round(std, 3).tolist(),
                     "min_wlh": np.round(lo, 3).tolist(), "max_wlh": np.round(hi, 3).tolist()}
            source = "nuscenes"
        elif m is not None:
            entry = {"mean_wlh": m["mean_wlh"], "std_wlh": list(prior[1]),
                     "min_wlh": np.minimum(prior[2], m["min_wlh"]).tolist(),
                     "max_wlh": np.maximum(prior[3], m["max_wlh"]).tolist()}
            source = "nuscenes+prior"
        else:
            entry = dict(zip(("mean_wlh", "std_wlh", "min_wlh", "max_wlh"), map(list, prior)))
            source = "prior"
        entry.update(n_instances=int(m["n_instances"]) if m else 0, n_boxes=int(m["n_boxes"]) if m else 0,
                     source=source)
        out[category] = entry
    return out


def class_sizes_document(measured: dict[str, dict], sources: list[str]) -> dict:
    """The JSON document of a class-sizes table (``schema``, where it was measured, ``categories``)."""
    return {"schema": SCHEMA, "measured_from": sources, "categories": merge_with_prior(measured)}


def _vec3(value, where: str, positive: bool) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64) if isinstance(value, list) else np.zeros(0)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or (np.any(a <= 0) if positive else np.any(a < 0)):
        raise InputError(f"{where}: expected [w, l, h], 3 {'positive' if positive else 'non-negative'} "
                         f"numbers in metres, got {value!r}")
    return a


@lru_cache(maxsize=8)
def _read(path: str, mtime_ns: int) -> dict[str, CategorySize]:
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the class sizes table ({e})") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA or not isinstance(doc.get("categories"), dict):
        raise InputError(f"{path}: expected a JSON object with 'schema': {SCHEMA!r} and 'categories': "
                         f"{{category: {{mean_wlh, std_wlh, min_wlh, max_wlh, ...}}}}")
    table = {}
    for category, e in doc["categories"].items():
        where = f"{path}: categories.{category}"
        if not isinstance(e, dict):
            raise InputError(f"{where}: expected an object, got {e!r}")
        lo, hi = _vec3(e.get("min_wlh"), f"{where}.min_wlh", True), _vec3(e.get("max_wlh"), f"{where}.max_wlh", True)
        mean = _vec3(e.get("mean_wlh"), f"{where}.mean_wlh", True)
        if np.any(lo > mean) or np.any(mean > hi):
            raise InputError(f"{where}: need min_wlh <= mean_wlh <= max_wlh, got {lo.tolist()}, {mean.tolist()}, "
                             f"{hi.tolist()}")
        table[category] = CategorySize(category, mean, _vec3(e.get("std_wlh"), f"{where}.std_wlh", False), lo, hi,
                                       int(e.get("n_instances", 0)), int(e.get("n_boxes", 0)),
                                       str(e.get("source", "")))
    return table


def read_class_sizes(path: str | Path | None = None) -> dict[str, CategorySize]:
    """The class sizes table at ``path`` (default: the shipped one), category -> :class:`CategorySize`.

    Raises:
        InputError: unreadable file, wrong schema, or an entry without valid [w, l, h] fields.
    """
    p = Path(path) if path is not None else CLASS_SIZES_PATH
    if not p.is_file():
        raise InputError(f"{p}: class sizes table not found")
    return _read(str(p), p.stat().st_mtime_ns)


def draw_wlh(size: CategorySize, rng: np.random.Generator) -> np.ndarray:
    """A size (3,) [w, l, h] drawn from ``size``: mean + std * (0.8 z + 0.6 z_i), clipped to [min, max].

    One shared z ~ N(0, 1) makes big objects big in every direction (a long truck is also tall); the
    independent z_i ~ N(0, 1) vary the proportions. Draws 4 normals from ``rng``.
    """
    z = rng.standard_normal(4)
    wlh = size.mean_wlh + size.std_wlh * (0.8 * z[0] + 0.6 * z[1:])
    return np.clip(wlh, size.min_wlh, size.max_wlh)


__all__ = ["CLASS_SIZES_PATH", "CategorySize", "MIN_INSTANCES_FOR_SPREAD", "PRIOR_SIZES", "class_sizes_document",
           "draw_wlh", "merge_with_prior", "read_class_sizes"]
