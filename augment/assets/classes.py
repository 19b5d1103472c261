"""Procedural assets of every nuScenes detection class, and the class mix an insertion draws from.

:func:`procedural_object` builds one object of a detection class (``car``, ``truck``, ``bus``, ``trailer``,
``construction_vehicle``, ``pedestrian``, ``motorcycle``, ``bicycle``, ``traffic_cone``, ``barrier``): it draws
the nuScenes category within the class (:data:`CLASS_CATEGORIES`), the variant, and a box size from the
class-sizes table (:mod:`.class_sizes`), then calls the class's generator, which builds to that size.
Cars keep their own body specs (:func:`~.procedural.procedural_car`). Everything is deterministic in the seed.

A :class:`ClassMix` is what ``--classes`` / ``--class-weights`` give: the classes to draw from and their weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core import InputError
from .asset import Asset
from .barrier import procedural_barrier
from .bus import procedural_bus
from .categories import DETECTION_CLASSES
from .class_sizes import CategorySize, draw_wlh, read_class_sizes
from .construction_vehicle import procedural_construction_vehicle
from .pedestrian import procedural_pedestrian
from .procedural import procedural_car
from .traffic_cone import procedural_traffic_cone
from .trailer import procedural_trailer
from .truck import procedural_truck
from .two_wheeler import procedural_bicycle, procedural_motorcycle

# detection class -> (nuScenes category, generator variant or None, weight): the categories a class is drawn as.
CLASS_CATEGORIES: dict[str, tuple[tuple[str, str | None, float], ...]] = {
    "car": (("vehicle.car", None, 1.0),),
    "truck": (("vehicle.truck", None, 1.0),),
    "bus": (("vehicle.bus.rigid", "rigid", 0.85), ("vehicle.bus.bendy", "bendy", 0.15)),
    "trailer": (("vehicle.trailer", None, 1.0),),
    "construction_vehicle": (("vehicle.construction", None, 1.0),),
    "pedestrian": (("human.pedestrian.adult", "adult", 0.88), ("human.pedestrian.child", "child", 0.12)),
    "motorcycle": (("vehicle.motorcycle", "with_rider", 0.45), ("vehicle.motorcycle", "without_rider", 0.55)),
    "bicycle": (("vehicle.bicycle", "with_rider", 0.4), ("vehicle.bicycle", "without_rider", 0.6)),
    "traffic_cone": (("movable_object.trafficcone", None, 1.0),),
    "barrier": (("movable_object.barrier", None, 1.0),),
}

# The size table pools ridden and parked two-wheelers, whose heights differ by the rider: a riderless one takes
# the lower part of the table's height range (min..mean), a ridden one the upper part (mean..max).
CYCLE_HEIGHT_PART = {"without_rider": (0.0, 1.0), "with_rider": (1.0, 2.0)}  # in units of [min, mean, max]

_GENERATORS: dict[str, Callable[..., Asset]] = {
    "truck": procedural_truck, "bus": procedural_bus, "trailer": procedural_trailer,
    "construction_vehicle": procedural_construction_vehicle, "pedestrian": procedural_pedestrian,
    "motorcycle": procedural_motorcycle, "bicycle": procedural_bicycle, "traffic_cone": procedural_traffic_cone,
    "barrier": procedural_barrier,
}


def check_detection_class(name: str, where: str = "--classes") -> str:
    """``name`` if it is a detection class, else an :class:`InputError` listing the valid ones."""
    if name not in DETECTION_CLASSES:
        raise InputError(f"{where}: unknown class {name!r}; valid classes: {', '.join(DETECTION_CLASSES)}")
    return name


def _variant_wlh(variant: str | None, wlh: np.ndarray, size: CategorySize) -> np.ndarray:
    """``wlh`` with a two-wheeler's height moved into its variant's part of the table's range."""
    if variant not in CYCLE_HEIGHT_PART:
        return wlh
    t = (wlh[2] - size.min_wlh[2]) / max(size.max_wlh[2] - size.min_wlh[2], 1e-9)  # 0..1 in the whole range
    lo, hi = CYCLE_HEIGHT_PART[variant]
    u = lo + float(np.clip(t, 0, 1)) * (hi - lo)  # 0..2 over [min, mean, max]
    knots = [size.min_wlh[2], size.mean_wlh[2], size.max_wlh[2]]
    return np.array([wlh[0], wlh[1], float(np.interp(u, [0.0, 1.0, 2.0], knots))])


def procedural_object(detection_class: str, seed: int, sizes: dict[str, CategorySize] | None = None,
                      still: bool = False, plate_style: str = "eu", paint_region: str = "global",
                      anonymised_plates: bool = False, paint_weights: tuple[float, ...] | None = None) -> Asset:
    """One procedural object of ``detection_class``, deterministic in ``seed``.

    Args:
        detection_class: one of :data:`DETECTION_CLASSES`.
        seed: draws the category within the class, the variant, the size and the generator's own choices.
        sizes: the class-sizes table (default the shipped one, :func:`read_class_sizes`).
        still: an object that stays put for a whole track: pedestrians stand, two-wheelers have no rider.
        plate_style: cars' number plates and driving side (``sg``, ``us``, ``eu``; see
            :func:`~.number_plates.plate_style_for_location`); other classes ignore it.
        paint_region, anonymised_plates, paint_weights: cars' paint colours and plates (see
            :func:`~.procedural.procedural_car`).

    Raises:
        InputError: unknown class, or the table lacks the drawn category.
    """
    check_detection_class(detection_class, "procedural_object")
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xC1A5])
    options = CLASS_CATEGORIES[detection_class]
    weights = np.array([o[2] for o in options])
    category, variant, _ = options[int(rng.choice(len(options), p=weights / weights.sum()))]
    if still and variant == "with_rider":
        variant = "without_rider"
    if detection_class == "car":
        return procedural_car(int(rng.integers(2**31)), plate_style=plate_style, paint_region=paint_region,
                              anonymised_plates=anonymised_plates, paint_weights=paint_weights)
    table = sizes if sizes is not None else read_class_sizes()
    if category not in table:
        raise InputError(f"class sizes table: no entry for {category!r} (needed for class {detection_class!r})")
    wlh = _variant_wlh(variant, draw_wlh(table[category], rng), table[category])
    extra = {"pose": "standing"} if still and detection_class == "pedestrian" else {}
    return _GENERATORS[detection_class](int(rng.integers(2**31)), wlh=wlh, variant=variant, **extra)


@dataclass(frozen=True)
class ClassMix:
    """The detection classes objects are drawn from, with their weights (normalised when drawing).

    Attributes:
        classes: detection class names (no repeats).
        weights: (len(classes),) non-negative weights, at least one positive.
    """

    classes: tuple[str, ...]
    weights: tuple[float, ...]

    def __post_init__(self) -> None:
        for c in self.classes:
            check_detection_class(c)
        if len(set(self.classes)) != len(self.classes):
            raise InputError(f"--classes: a class is listed twice: {', '.join(self.classes)}")
        if len(self.weights) != len(self.classes) or not self.classes:
            raise InputError(f"--class-weights: expected one weight per class ({len(self.classes)}), "
                             f"got {len(self.weights)}")
        w = np.asarray(self.weights, dtype=np.float64)
        if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise InputError(f"--class-weights: expected non-negative numbers, at least one positive, got "
                             f"{list(self.weights)}")

    @classmethod
    def parse(cls, classes: str | None, weights: str | None = None) -> "ClassMix | None":
        """From the CLI's ``--classes a,b,c`` and ``--class-weights`` (``1,1,3`` in the same order, or
        ``name=weight,...`` with unlisted classes at 1); None when neither is given (cars, as ever).

        ``--class-weights`` alone draws from every class.
        """
        if classes is None and weights is None:
            return None
        names = tuple(n.strip() for n in classes.split(",") if n.strip()) if classes is not None else DETECTION_CLASSES
        if not names:
            raise InputError(f"--classes: no class given; valid classes: {', '.join(DETECTION_CLASSES)}")
        for n in names:
            check_detection_class(n)
        if weights is None:
            return cls(names, (1.0,) * len(names))
        items = [w.strip() for w in weights.split(",") if w.strip()]
        if items and all("=" in w for w in items):
            table = {}
            for item in items:
                k, v = (x.strip() for x in item.split("=", 1))
                check_detection_class(k, "--class-weights")
                if k not in names:
                    raise InputError(f"--class-weights: class {k!r} is not among --classes ({', '.join(names)})")
                table[k] = _weight(v)
            return cls(names, tuple(table.get(n, 1.0) for n in names))
        return cls(names, tuple(_weight(v) for v in items))

    def draw(self, rng: np.random.Generator, n: int) -> list[str]:
        """``n`` class names drawn with replacement by weight (one uniform per object from ``rng``)."""
        w = np.asarray(self.weights, dtype=np.float64)
        cdf = np.cumsum(w / w.sum())
        idx = np.searchsorted(cdf, rng.random(n), side="right").clip(0, len(w) - 1)
        return [self.classes[int(i)] for i in idx]


def _weight(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"--class-weights: {text!r} is not a number") from None


__all__ = ["CLASS_CATEGORIES", "CYCLE_HEIGHT_PART", "ClassMix", "DETECTION_CLASSES", "check_detection_class",
           "procedural_object"]
