"""Per-class placement rules: where each nuScenes detection class goes and what it keeps clear of.

One readable table, ``class_rules.json`` beside this module (its ``description`` explains every field), maps
each detection class (``car``, ``truck``, ``bus``, ``trailer``, ``construction_vehicle``, ``motorcycle``,
``bicycle``, ``pedestrian``, ``traffic_cone``, ``barrier``) to a :class:`ClassRule`, and every nuScenes object
category to the class whose rule it follows (an ambulance is placed like a car, a stroller like a pedestrian).
A user overrides it with a file of the same schema (``--class-rules``): its classes replace the built-in ones
field by field, its categories are added.

A rule turns into thresholds through :meth:`ClassRule.config`: the base :class:`PlacementConfig` with the
class's distances and clearances, so every rule function keeps reading one config.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from streetaug.augment.assets.categories import DETECTION_CLASSES
from streetaug.augment.core import InputError

from .config import PlacementConfig

CLASS_RULES_PATH = Path(__file__).with_name("class_rules.json")
SCHEMA = "streetaug.class_rules/1"

ZONES = ("lane", "kerb", "road_edge", "sidewalk", "crossing")
HEADINGS = ("lane", "path", "across", "random")
ATTRIBUTE_MODES = ("vehicle", "parked", "asset", "none")
ZONE_WEIGHTS = ("fixed", "scene")


@dataclass(frozen=True)
class ClusterRule:
    """Members placed in a line along the road after the first (a row of cones, barriers end to end).

    Attributes:
        size: (min, max) members, the first included; drawn uniformly.
        gap_m: (min, max) gap between neighbours' footprints along the road, drawn once per cluster.
        taper_deg: (min, max) angle of the line into the road (a work zone's taper), drawn once per cluster.
    """

    size: tuple[int, int]
    gap_m: tuple[float, float]
    taper_deg: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class ClassRule:
    """Where one detection class may be placed.

    Attributes:
        name: the detection class.
        zones: surface -> weight (see ``ZONES`` and the table's description); zero-weight zones are dropped.
        distance_m: (min, max) horizontal camera-to-centre distance; None: the placement config's.
        dynamic_clearance_m, static_clearance_m, mutual_clearance_m: as :class:`PlacementConfig`'s, for this class
            (the mutual clearance between two inserted objects is the larger of their two); None: the config's.
        lane_margin_m: in the ``lane`` zone, the footprint grown by this on every side must be drivable (a bus
            needs a wide lane).
        heading: ``lane``, ``path``, ``across`` or ``random``.
        yaw_sigma_deg: yaw noise of this class (None: the placement config's).
        attribute: ``vehicle``, ``parked``, ``asset`` or ``none``.
        cluster: the line the class is placed in, or None (one object).
        sidewalk_band_m: (min, max) distance off the road of the ``sidewalk`` zone without a walkway map.
        ground_radius_m: LiDAR radius of the local ground fit (small objects read the ground right under them).
        zone_weights: ``fixed`` (the weights as given) or ``scene``: the ``lane`` / ``kerb`` split follows the share
            of the sample's annotated boxes of the class that are parked, these weights the prior
            (:func:`~streetaug.placement.parking.with_parked_share`), and kerb placements stand as the nearest
            parked box does (:func:`~streetaug.placement.parking.kerb_poses`).
    """

    name: str
    zones: dict[str, float]
    distance_m: tuple[float, float] | None = None
    dynamic_clearance_m: float | None = None
    static_clearance_m: float | None = None
    mutual_clearance_m: float | None = None
    lane_margin_m: float = 0.0
    heading: str = "lane"
    yaw_sigma_deg: float | None = None
    attribute: str = "vehicle"
    cluster: ClusterRule | None = None
    sidewalk_band_m: tuple[float, float] = (0.3, 4.0)
    ground_radius_m: float | None = None
    zone_weights: str = "fixed"

    def config(self, base: PlacementConfig) -> PlacementConfig:
        """``base`` with the distances, clearances, yaw noise and ground radius this class sets (the fields the
        rule leaves None keep ``base``'s)."""
        changes = {}
        if self.distance_m is not None:
            changes.update(min_distance_m=self.distance_m[0], max_distance_m=self.distance_m[1])
        for key in ("dynamic_clearance_m", "static_clearance_m", "mutual_clearance_m"):
            if getattr(self, key) is not None:
                changes[key] = getattr(self, key)
        if self.yaw_sigma_deg is not None:
            changes["yaw_sigma_deg"] = self.yaw_sigma_deg
        if self.ground_radius_m is not None:
            changes["ground_radius_m"] = self.ground_radius_m
        return dataclasses.replace(base, **changes) if changes else base

    def parks_like_the_scene(self, zone: str) -> bool:
        """Whether a placement of this class in ``zone`` stands as the sample's parked boxes do: the ``kerb`` zone of
        a ``lane``-heading rule with ``zone_weights: scene`` (:func:`~streetaug.placement.parking.kerb_poses`)."""
        return zone == "kerb" and self.heading == "lane" and self.zone_weights == "scene"

    @property
    def is_vehicle_on_road(self) -> bool:
        """Whether every zone of the class is on the road itself (lane or kerb)."""
        return set(self.zones) <= {"lane", "kerb"}


@dataclass(frozen=True)
class ClassRules:
    """The rule table: detection class -> :class:`ClassRule`, nuScenes category -> detection class."""

    classes: dict[str, ClassRule]
    categories: dict[str, str]

    def class_of(self, category: str) -> str:
        """The detection class whose rule ``category`` follows.

        Raises:
            InputError: the category is not in the table (names the valid ones).
        """
        if category in self.categories:
            return self.categories[category]
        raise InputError(f"category {category!r} has no placement rule; the class rules map "
                         f"{', '.join(sorted(self.categories))}")

    def categories_of(self, name: str) -> set[str]:
        """The nuScenes categories whose objects follow detection class ``name``'s rule."""
        return {c for c, k in self.categories.items() if k == name}

    def for_category(self, category: str) -> ClassRule:
        """The :class:`ClassRule` of an object of nuScenes ``category``."""
        return self.classes[self.class_of(category)]


def _pair(value, where: str, kind=float, positive: bool = False) -> tuple:
    if not (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise InputError(f"{where}: expected [min, max] (2 numbers), got {value!r}")
    lo, hi = kind(value[0]), kind(value[1])
    if not lo <= hi or lo < 0 or (positive and lo <= 0):
        raise InputError(f"{where}: expected 0 {'<' if positive else '<='} min <= max, got {value!r}")
    return lo, hi


def _number(value, where: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not value >= 0:
        raise InputError(f"{where}: expected a non-negative number, got {value!r}")
    return float(value)


def _parse_rule(name: str, fields: dict, where: str) -> ClassRule:
    known = {f.name for f in dataclasses.fields(ClassRule)} - {"name"}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise InputError(f"{where}: unknown field(s) {', '.join(unknown)}; expected some of {', '.join(sorted(known))}")
    zones = fields.get("zones")
    if not isinstance(zones, dict) or not zones:
        raise InputError(f"{where}.zones: expected {{zone: weight}} with zones among {', '.join(ZONES)}, got {zones!r}")
    for z, w in zones.items():
        if z not in ZONES:
            raise InputError(f"{where}.zones: unknown zone {z!r}; expected one of {', '.join(ZONES)}")
        _number(w, f"{where}.zones.{z}")
    zones = {z: float(w) for z, w in zones.items() if w > 0}
    if not zones:
        raise InputError(f"{where}.zones: every weight is 0; give at least one zone a positive weight")
    kw: dict = {"zones": zones}
    if "distance_m" in fields:
        kw["distance_m"] = _pair(fields["distance_m"], f"{where}.distance_m")
        if kw["distance_m"][0] >= kw["distance_m"][1]:
            raise InputError(f"{where}.distance_m: need min < max, got {fields['distance_m']!r}")
    for key in ("dynamic_clearance_m", "static_clearance_m", "mutual_clearance_m", "lane_margin_m"):
        if key in fields:
            kw[key] = _number(fields[key], f"{where}.{key}")
    for key in ("yaw_sigma_deg", "ground_radius_m"):
        if fields.get(key) is not None:
            kw[key] = _number(fields[key], f"{where}.{key}")
    for key, valid in (("heading", HEADINGS), ("attribute", ATTRIBUTE_MODES), ("zone_weights", ZONE_WEIGHTS)):
        if key in fields:
            if fields[key] not in valid:
                raise InputError(f"{where}.{key}: expected one of {', '.join(valid)}, got {fields[key]!r}")
            kw[key] = fields[key]
    if "sidewalk_band_m" in fields:
        kw["sidewalk_band_m"] = _pair(fields["sidewalk_band_m"], f"{where}.sidewalk_band_m")
    c = fields.get("cluster")
    if c is not None:
        if not isinstance(c, dict) or "size" not in c or "gap_m" not in c:
            raise InputError(f"{where}.cluster: expected {{'size': [min, max], 'gap_m': [min, max], "
                             f"'taper_deg': [min, max]}} or null, got {c!r}")
        kw["cluster"] = ClusterRule(_pair(c["size"], f"{where}.cluster.size", int, positive=True),
                                    _pair(c["gap_m"], f"{where}.cluster.gap_m"),
                                    _pair(c.get("taper_deg", [0, 0]), f"{where}.cluster.taper_deg"))
    return ClassRule(name=name, **kw)


def _read_document(path: Path) -> dict:
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the class rules ({e})") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise InputError(f"{path}: expected a JSON object with 'schema': {SCHEMA!r}, 'classes': {{class: rule}} and "
                         f"optionally 'categories': {{category: class}}")
    for key in ("classes", "categories"):
        if not isinstance(doc.get(key, {}), dict):
            raise InputError(f"{path}: field {key!r} must be an object")
    return doc


@lru_cache(maxsize=8)
def _read_rules(override: str | None, mtime_ns: int) -> ClassRules:
    base = _read_document(CLASS_RULES_PATH)
    classes = {k: dict(v) for k, v in base["classes"].items()}
    categories = dict(base["categories"])
    origin = {k: CLASS_RULES_PATH for k in classes}
    if override is not None:
        doc = _read_document(Path(override))
        for name, fields in doc.get("classes", {}).items():
            if not isinstance(fields, dict):
                raise InputError(f"{override}: classes.{name}: expected an object of rule fields, got {fields!r}")
            classes[name] = {**classes.get(name, {}), **fields}
            origin[name] = Path(override)
        categories.update(doc.get("categories", {}))
    rules = {name: _parse_rule(name, fields, f"{origin[name]}: classes.{name}") for name, fields in classes.items()}
    for category, name in categories.items():
        if name not in rules:
            raise InputError(f"{override or CLASS_RULES_PATH}: categories.{category}: class {name!r} has no rule; "
                             f"expected one of {', '.join(sorted(rules))}")
    return ClassRules(rules, categories)


def read_class_rules(path: str | Path | None = None) -> ClassRules:
    """The built-in class rules, overridden by the file ``path`` when given (see the module docstring).

    Raises:
        InputError: unreadable file, wrong schema, an unknown field/zone/heading, bad numbers (names the field).
    """
    if path is None:
        return _read_rules(None, 0)
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: class rules file not found")
    return _read_rules(str(p), p.stat().st_mtime_ns)


__all__ = ["ATTRIBUTE_MODES", "CLASS_RULES_PATH", "ClassRule", "ClassRules", "ClusterRule", "DETECTION_CLASSES",
           "HEADINGS", "ZONES", "ZONE_WEIGHTS", "read_class_rules"]
