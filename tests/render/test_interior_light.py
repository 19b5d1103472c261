"""The interior seen through glass: the car's interior light x base colour, brighter on faces looking up."""

from __future__ import annotations

import numpy as np

from streetaug.augment.render.foreground import OBJECT_UP, interior_shading


def test_interior_shading_keeps_the_interior_lights_scale():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200_000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert abs(interior_shading(n, OBJECT_UP).mean() - 1.0) < 0.01  # mean 1 over the sphere
    up, down, side = interior_shading(np.array([[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0]]), OBJECT_UP)
    assert up > side > down > 0  # seat cushions brighter than the footwell, never black
