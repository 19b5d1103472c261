"""DrivableArea.boundary_distance: exactly shapely's distance to the region's boundary, through fewer segments."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from streetaug.placement.drivable import DrivableArea


def _regions():
    rng = np.random.default_rng(0)
    ring = np.c_[np.cos(np.linspace(0, 2 * np.pi, 300, endpoint=False)), np.sin(np.linspace(0, 2 * np.pi, 300,
                                                                                           endpoint=False))]
    blob = shapely.Polygon(700.0 + 30 * ring * rng.uniform(0.7, 1.0, (300, 1)))  # global-size coordinates
    holed = shapely.Polygon(shapely.get_coordinates(shapely.box(600, 1700, 680, 1760).exterior),
                            [shapely.get_coordinates(shapely.box(620, 1720, 630, 1730).exterior),
                             shapely.get_coordinates(shapely.Point(650, 1740).buffer(5).exterior)])
    multi = shapely.MultiPolygon([shapely.box(0, 0, 10, 3), shapely.box(0, 5, 10, 8),
                                  shapely.Polygon([(12, 0), (20, 0), (20, 0), (16, 9)])])  # a repeated vertex
    return [blob, holed, multi]


@pytest.mark.parametrize("index", range(3))
def test_boundary_distance_equals_shapely_exactly(index):
    region = _regions()[index]
    area = DrivableArea("map", "high", region=region)
    rng = np.random.default_rng(index)
    x0, y0, x1, y1 = region.bounds
    pad = 0.3 * max(x1 - x0, y1 - y0)
    xy = np.c_[rng.uniform(x0 - pad, x1 + pad, 4000), rng.uniform(y0 - pad, y1 + pad, 4000)]
    vertices = shapely.get_coordinates(shapely.boundary(region))
    on_and_near = np.concatenate([vertices, vertices + rng.normal(0, 1e-6, vertices.shape),
                                  0.5 * (vertices[:-1] + vertices[1:])])  # on vertices, next to them, on edges
    xy = np.concatenate([xy, on_and_near])
    want = shapely.distance(shapely.points(xy), shapely.boundary(region))
    got = area.boundary_distance(xy)
    assert got.dtype == np.float64 and got.shape == (len(xy),)
    assert np.array_equal(got, want)
    assert area.boundary_distance(np.zeros((0, 2))).shape == (0,)
