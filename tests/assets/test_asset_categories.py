"""Asset categories: the built-in name mapping, a folder's own mapping file, errors, and the loader using them."""

from __future__ import annotations

import json

import pytest

from streetaug.augment.core import InputError
from streetaug.augment.assets.categories import BUILTIN_MAPPING_PATH, NUSCENES_OBJECT_CATEGORIES, category_for_asset
from streetaug.augment.assets.loader import load_asset
from streetaug.datasets.nuscenes_format import CATEGORY_NAMES


@pytest.mark.parametrize("name,category", [
    ("ambulance.glb", "vehicle.emergency.ambulance"),
    ("police.glb", "vehicle.emergency.police"),
    ("firetruck.glb", "vehicle.truck"),
    ("delivery.glb", "vehicle.truck"),
    ("Truck.GLB", "vehicle.truck"),
    ("city_bus.obj", "vehicle.bus.rigid"),
    ("bendy_bus.obj", "vehicle.bus.bendy"),
    ("excavator.ply", "vehicle.construction"),
    ("motorbike.glb", "vehicle.motorcycle"),
    ("sedan.glb", "vehicle.car"),
    ("hatchbackSports.glb", "vehicle.car"),
    ("suv.glb", "vehicle.car"),
    ("van.glb", "vehicle.car"),
    ("taxi.glb", "vehicle.car"),
])
def test_builtin_mapping(tmp_path, name, category):
    assert category_for_asset(tmp_path / name) == category


def test_folder_mapping_file_overrides(tmp_path):
    (tmp_path / "categories.json").write_text(json.dumps({
        "schema": "streetaug.asset_categories/1", "default": "vehicle.truck",
        "rules": [{"match": "van*", "category": "vehicle.truck"}, {"match": "taxi", "category": "vehicle.car"}]}))
    assert category_for_asset(tmp_path / "van_02.glb") == "vehicle.truck"  # folder rule first
    assert category_for_asset(tmp_path / "taxi.glb") == "vehicle.car"
    assert category_for_asset(tmp_path / "ambulance.glb") == "vehicle.emergency.ambulance"  # built-in rule next
    assert category_for_asset(tmp_path / "unknown_thing.glb") == "vehicle.truck"  # the folder's default


@pytest.mark.parametrize("doc,match", [
    ({"rules": [{"match": "x*", "category": "vehicle.spaceship"}]}, r"rules\[0\]\.category.*not a nuScenes"),
    ({"rules": [{"category": "vehicle.car"}]}, r"rules\[0\]: expected"),
    ({"schema": "other/2", "rules": []}, "field 'schema'"),
    ({"default": "flat.driveable_surface"}, "default"),
])
def test_bad_mapping_file_is_a_clear_error(tmp_path, doc, match):
    (tmp_path / "categories.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match):
        category_for_asset(tmp_path / "x1.glb")


def test_builtin_categories_are_nuscenes_names():
    doc = json.loads(BUILTIN_MAPPING_PATH.read_text())
    assert all(r["category"] in NUSCENES_OBJECT_CATEGORIES for r in doc["rules"])
    assert doc["default"] == "vehicle.car"


def test_loader_takes_the_category_from_the_file_name(tmp_path):
    obj = "\n".join(["v 0 0 0", "v 4 0 0", "v 4 0 2", "v 0 0 2", "v 0 1.5 0", "v 4 1.5 0", "v 4 1.5 2", "v 0 1.5 2",
                     "f 1 2 3", "f 1 3 4", "f 5 7 6", "f 5 8 7", "f 1 5 6", "f 1 6 2", "f 4 3 7", "f 4 7 8",
                     "f 1 4 8", "f 1 8 5", "f 2 6 7", "f 2 7 3"]) + "\n"
    (tmp_path / "firetruck.obj").write_text(obj)
    (tmp_path / "sedan.obj").write_text(obj)
    assert load_asset(tmp_path / "firetruck.obj", front_axis="+x", use_cache=False).category == "vehicle.truck"
    assert load_asset(tmp_path / "sedan.obj", front_axis="+x", use_cache=False).category == "vehicle.car"
    assert load_asset(tmp_path / "sedan.obj", front_axis="+x", category="vehicle.trailer",
                      use_cache=False).category == "vehicle.trailer"


def test_object_categories_are_the_nuscenes_table_without_background_classes():
    """Assets import only the core, so their category list is checked against the datasets' table here."""
    background = ("noise", "flat.", "static.", "vehicle.ego")
    assert NUSCENES_OBJECT_CATEGORIES == tuple(c for c in CATEGORY_NAMES if not c.startswith(background))
