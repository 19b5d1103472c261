"""The side glass's front edge leans back with the windscreen (an A pillar, not a vertical cut)."""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.assets import car_body as cb
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.validate import face_normals


@pytest.mark.parametrize("body", sorted(cb.BODY_SPECS))
def test_front_side_window_edge_leans_back(body):
    car = procedural_car(11, body)
    n, _ = face_normals(car.vertices, car.faces)
    c = car.vertices[car.faces].mean(axis=1)
    glass = (car.face_material == cb.GLASS) & (np.abs(n[:, 1]) > 0.5)
    z = c[glass, 2]
    low, high = z < np.quantile(z, 0.25), z > np.quantile(z, 0.75)
    # The foremost side glass high up is behind the foremost side glass low down.
    assert c[glass][high, 0].max() < c[glass][low, 0].max() - 0.1, body
    spec = cb.BODY_SPECS[body]()
    e0, e1 = cb.side_window_limits(spec, np.array([spec.belt_front, spec.height]))
    assert e0[1] > e0[0] and e1[1] < e1[0]
