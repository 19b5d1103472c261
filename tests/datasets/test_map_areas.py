"""Polygon layers of a map expansion: drivable area, walkways and pedestrian crossings."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely

from streetaug.datasets.errors import DatasetError
from streetaug.datasets.nuscenes_map import read_area_layer, read_drivable_area


def _expansion(tmp_path, **layers):
    nodes, polygons = [], []

    def square(name, x0, y0, x1, y1):
        ids = []
        for i, (x, y) in enumerate([(x0, y0), (x1, y0), (x1, y1), (x0, y1)]):
            nodes.append({"token": f"{name}-n{i}", "x": x, "y": y})
            ids.append(f"{name}-n{i}")
        polygons.append({"token": f"{name}-p", "exterior_node_tokens": ids, "holes": []})
        return f"{name}-p"

    doc = {"node": nodes, "polygon": polygons,
           "drivable_area": [{"token": "road", "polygon_tokens": [square("road", 0, 0, 100, 10)]}]}
    for layer, boxes in layers.items():
        doc[layer] = [{"token": f"{layer}{i}", "polygon_token": square(f"{layer}{i}", *b)} for i, b in enumerate(boxes)]
    path = tmp_path / "city.json"
    path.write_text(json.dumps(doc))
    return path


def test_walkways_and_crossings_are_read_as_polygons(tmp_path):
    path = _expansion(tmp_path, walkway=[(0, 10, 100, 14), (0, -4, 100, 0)], ped_crossing=[(40, 0, 44, 10)])
    walkways = read_area_layer(path, "walkway")
    crossings = read_area_layer(path, "ped_crossing")
    assert len(walkways) == 2 and np.isclose(sum(w.area for w in walkways), 800.0)
    assert len(crossings) == 1 and crossings[0].contains(shapely.Point(42, 5))
    assert np.isclose(read_drivable_area(path)[0].area, 1000.0)


def test_a_missing_optional_layer_is_empty_a_broken_one_is_an_error(tmp_path):
    path = _expansion(tmp_path)
    assert read_area_layer(path, "walkway", required=False) == []
    with pytest.raises(DatasetError, match="no 'walkway' layer"):
        read_area_layer(path, "walkway")
    doc = json.loads(path.read_text())
    doc["ped_crossing"] = [{"token": "x", "polygon_token": "nowhere"}]
    path.write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match="ped_crossing refers to unknown polygon token 'nowhere'"):
        read_area_layer(path, "ped_crossing", required=False)
