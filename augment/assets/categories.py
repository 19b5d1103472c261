"""nuScenes category of an asset, from its file name and a mapping file.

The built-in mapping is ``asset_categories.json`` beside this module: shell patterns (fnmatch) on the
lower-case file stem, tried in order, first match wins, else its ``default`` (``vehicle.car``). A
folder of assets may carry its own ``categories.json`` in the same format; its rules are tried
first (its ``default``, when given, replaces the built-in one). Procedural cars are ``vehicle.car``.
"""

from __future__ import annotations

import fnmatch
import json
from functools import lru_cache
from pathlib import Path

from ..core import InputError

BUILTIN_MAPPING_PATH = Path(__file__).with_name("asset_categories.json")
FOLDER_MAPPING_NAME = "categories.json"
SCHEMA = "streetaug.asset_categories/1"

# nuScenes object categories an inserted object may have (the devkit's category table minus the
# lidarseg-only background classes, noise and the ego).
NUSCENES_OBJECT_CATEGORIES = (
    "animal", "human.pedestrian.adult", "human.pedestrian.child", "human.pedestrian.construction_worker",
    "human.pedestrian.personal_mobility", "human.pedestrian.police_officer", "human.pedestrian.stroller",
    "human.pedestrian.wheelchair", "movable_object.barrier", "movable_object.debris",
    "movable_object.pushable_pullable", "movable_object.trafficcone", "static_object.bicycle_rack",
    "vehicle.bicycle", "vehicle.bus.bendy", "vehicle.bus.rigid", "vehicle.car", "vehicle.construction",
    "vehicle.emergency.ambulance", "vehicle.emergency.police", "vehicle.motorcycle", "vehicle.trailer",
    "vehicle.truck",
)

# The nuScenes detection benchmark's ten classes (what detectors are scored on; each groups some categories).
DETECTION_CLASSES = ("car", "truck", "bus", "trailer", "construction_vehicle", "pedestrian", "motorcycle",
                     "bicycle", "traffic_cone", "barrier")


@lru_cache(maxsize=32)
def _read_mapping(path: str, mtime_ns: int) -> tuple[tuple[tuple[str, str], ...], str | None]:
    """(rules ((pattern, category), ...), default or None) of one mapping file, validated."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the asset category mapping ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("rules", []), list):
        raise InputError(f"{path}: expected a JSON object with 'rules': [{{'match': PATTERN, 'category': NAME}}, ...]")
    if data.get("schema", SCHEMA) != SCHEMA:
        raise InputError(f"{path}: field 'schema': expected {SCHEMA!r}, got {data.get('schema')!r}")
    rules = []
    for i, rule in enumerate(data.get("rules", [])):
        if not isinstance(rule, dict) or not isinstance(rule.get("match"), str):
            raise InputError(f"{path}: rules[{i}]: expected {{'match': PATTERN, 'category': NAME}}, got {rule!r}")
        rules.append((rule["match"].lower(), _check_category(rule.get("category"), f"{path}: rules[{i}].category")))
    default = data.get("default")
    if default is not None:
        default = _check_category(default, f"{path}: default")
    return tuple(rules), default


def _check_category(name, where: str) -> str:
    if name not in NUSCENES_OBJECT_CATEGORIES:
        raise InputError(f"{where}: {name!r} is not a nuScenes object category; expected one of "
                         f"{', '.join(NUSCENES_OBJECT_CATEGORIES)}")
    return name


def _mapping(path: Path) -> tuple[tuple[tuple[str, str], ...], str | None]:
    return _read_mapping(str(path), path.stat().st_mtime_ns)


def category_for_asset(asset_path: str | Path) -> str:
    """The nuScenes category of the asset file ``asset_path``.

    Example: ``.../ambulance.glb`` -> ``vehicle.emergency.ambulance``.

    Raises:
        InputError: a mapping file is unreadable or names an unknown category.
    """
    asset_path = Path(asset_path)
    stem = asset_path.stem.lower()
    rules, default = _mapping(BUILTIN_MAPPING_PATH)
    folder_file = asset_path.parent / FOLDER_MAPPING_NAME
    if folder_file.is_file():
        folder_rules, folder_default = _mapping(folder_file)
        rules = folder_rules + rules
        default = folder_default or default
    for pattern, category in rules:
        if fnmatch.fnmatchcase(stem, pattern):
            return category
    return default or "vehicle.car"
