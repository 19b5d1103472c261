"""Procedural cars carry the number plates, driving side and paint colours of the scene's location."""

from __future__ import annotations

import numpy as np

from streetaug.augment.assets.car_paint import paint_region_for_location
from streetaug.augment.assets.classes import ClassMix
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.select import select_assets


def _seed_drawn(rng_seed: int) -> int:
    return int(np.random.default_rng(rng_seed).integers(0, 4096, size=1)[0])  # select_assets' draw


def test_select_assets_builds_the_locations_plates():
    seed = _seed_drawn(0)
    for location, style in (("singapore-queenstown", "sg"), ("boston-seaport", "us"), (None, "eu"), ("berlin", "eu")):
        (car,) = select_assets(np.random.default_rng(0), 1, location=location)
        expected = procedural_car(seed, plate_style=style, paint_region=paint_region_for_location(location),
                                  anonymised_plates=True)
        np.testing.assert_array_equal(car.vertices, expected.vertices)
        np.testing.assert_array_equal(car.faces, expected.faces)
    sg, us = (select_assets(np.random.default_rng(0), 1, location=loc)[0] for loc in ("singapore-onenorth", "boston-seaport"))
    assert sg.faces.shape != us.faces.shape or not np.array_equal(sg.vertices, us.vertices)


def test_a_class_mix_passes_the_location_to_its_cars():
    mix = ClassMix(("car",), (1.0,))
    sg = select_assets(np.random.default_rng(3), 2, class_mix=mix, location="singapore-hollandvillage")
    us = select_assets(np.random.default_rng(3), 2, class_mix=mix, location="boston-seaport")
    assert [a.category for a in sg] == ["vehicle.car"] * 2
    assert any(not np.array_equal(a.vertices, b.vertices) or a.faces.shape != b.faces.shape for a, b in zip(sg, us))
