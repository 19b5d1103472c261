"""The fixed content of the nuScenes v1.0 table format, written once for the reader, the writer and the generator.

* Tokens: 32 hex digits; the rows streetaug makes get md5 hashes of descriptive parts
  (:func:`content_token`), so the same run gives the same tables.
* Categories: :data:`CATEGORY_NAMES` in the devkit's ``category.index`` order, which is also the
  nuScenes-lidarseg class index of a point (``LIDARSEG_*``).
* Attributes: :data:`ATTRIBUTES` (name -> description, as the devkit's table).
* Visibility: four bins of the visible fraction, tokens "1".."4" (:func:`visibility_token`), with their
  ``level`` names and the devkit's descriptions (:data:`VISIBILITY_LEVELS`).
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

# nuScenes category names in ``category.index`` order = nuScenes-lidarseg class index.
CATEGORY_NAMES = (
    "noise", "animal", "human.pedestrian.adult", "human.pedestrian.child",
    "human.pedestrian.construction_worker", "human.pedestrian.personal_mobility",
    "human.pedestrian.police_officer", "human.pedestrian.stroller", "human.pedestrian.wheelchair",
    "movable_object.barrier", "movable_object.debris", "movable_object.pushable_pullable",
    "movable_object.trafficcone", "static_object.bicycle_rack", "vehicle.bicycle", "vehicle.bus.bendy",
    "vehicle.bus.rigid", "vehicle.car", "vehicle.construction", "vehicle.emergency.ambulance",
    "vehicle.emergency.police", "vehicle.motorcycle", "vehicle.trailer", "vehicle.truck",
    "flat.driveable_surface", "flat.other", "flat.sidewalk", "flat.terrain", "static.manmade",
    "static.other", "static.vegetation", "vehicle.ego",
)


def lidarseg_index(category: str) -> int:
    """The nuScenes-lidarseg class index (``category.index``) of a category name, e.g. 17 for ``vehicle.car``."""
    return CATEGORY_NAMES.index(category)


LIDARSEG_NOISE = lidarseg_index("noise")
LIDARSEG_TRAFFICCONE = lidarseg_index("movable_object.trafficcone")
LIDARSEG_CAR = lidarseg_index("vehicle.car")
LIDARSEG_DRIVEABLE = lidarseg_index("flat.driveable_surface")
LIDARSEG_SIDEWALK = lidarseg_index("flat.sidewalk")
LIDARSEG_TERRAIN = lidarseg_index("flat.terrain")
LIDARSEG_MANMADE = lidarseg_index("static.manmade")
LIDARSEG_VEGETATION = lidarseg_index("static.vegetation")
LIDARSEG_EGO = lidarseg_index("vehicle.ego")
# flat.other, sidewalk, terrain, manmade, static.other, vegetation: where no car may stand
LIDARSEG_NON_DRIVABLE = tuple(lidarseg_index(n) for n in (
    "flat.other", "flat.sidewalk", "flat.terrain", "static.manmade", "static.other", "static.vegetation"))
LIDARSEG_GROUND = tuple(i for i, n in enumerate(CATEGORY_NAMES) if n.startswith("flat."))  # the ground's classes

ATTRIBUTES = {
    "cycle.with_rider": "A rider is on the cycle.",
    "cycle.without_rider": "No rider is on the cycle.",
    "pedestrian.moving": "The pedestrian is moving.",
    "pedestrian.standing": "The pedestrian is standing.",
    "pedestrian.sitting_lying_down": "The pedestrian is sitting or lying down.",
    "vehicle.moving": "The vehicle is moving.",
    "vehicle.parked": "The vehicle is parked.",
    "vehicle.stopped": "The vehicle has stopped but intends to move on.",
}
VEHICLE_MOVING = "vehicle.moving"
VEHICLE_PARKED = "vehicle.parked"
VEHICLE_STOPPED = "vehicle.stopped"

# visibility token -> (level, the devkit's description); bins of the visible fraction split at VISIBILITY_EDGES
VISIBILITY_LEVELS = {
    "1": ("v0-40", "visibility of whole object is between 0 and 40%"),
    "2": ("v40-60", "visibility of whole object is between 40 and 60%"),
    "3": ("v60-80", "visibility of whole object is between 60 and 80%"),
    "4": ("v80-100", "visibility of whole object is between 80 and 100%"),
}
VISIBILITY_EDGES = (0.4, 0.6, 0.8)


def visibility_token(visible_fraction: float) -> str:
    """nuScenes visibility token ("1".."4") of a visible fraction in [0, 1]: "1" [0, 0.4), "2" [0.4, 0.6),
    "3" [0.6, 0.8), "4" [0.8, 1] (edges belong to the higher bin)."""
    return str(1 + int(np.searchsorted(VISIBILITY_EDGES, float(visible_fraction), side="right")))


def content_token(*parts: Any, sep: str = "/") -> str:
    """A 32-hex-digit token (as nuScenes tokens): the md5 of ``parts`` joined by ``sep``, stable across runs."""
    return hashlib.md5(sep.join(str(p) for p in parts).encode()).hexdigest()


def new_token(*keys: Any) -> str:
    """The token of a row streetaug adds to a dataset (namespaced "streetaug", keys joined by "|")."""
    return content_token("streetaug", *keys, sep="|")


__all__ = [
    "ATTRIBUTES", "CATEGORY_NAMES", "LIDARSEG_CAR", "LIDARSEG_DRIVEABLE", "LIDARSEG_EGO", "LIDARSEG_GROUND",
    "LIDARSEG_MANMADE", "LIDARSEG_NOISE", "LIDARSEG_NON_DRIVABLE", "LIDARSEG_SIDEWALK", "LIDARSEG_TERRAIN",
    "LIDARSEG_TRAFFICCONE", "LIDARSEG_VEGETATION", "VEHICLE_MOVING", "VEHICLE_PARKED", "VEHICLE_STOPPED", "VISIBILITY_EDGES",
    "VISIBILITY_LEVELS", "content_token", "lidarseg_index", "new_token", "visibility_token",
]
