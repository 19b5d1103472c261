"""Canopies seen with sky through them (augment/lighting/build.py): partly transparent voxels."""

from __future__ import annotations

import numpy as np

from streetaug.augment.lighting.build import DistantSun, build_volume, sky_crossings, sky_gap_alpha
from streetaug.augment.lighting.observe import ViewObservation
from streetaug.augment.lighting.volume import CH_ALPHA, HybridLighting, LogGrid

GRID = LogGrid(shape=(48, 48, 16), half_extent_xy_m=40.0, z_min_m=-4.0, z_max_m=20.0)
CENTRE = np.array([0.0, 0.0, 1.5])


def _canopy(gaps: bool) -> ViewObservation:
    """A camera looking up at a canopy 8..11 m high, 6..12 m ahead: pixels on a 0.25 m lattice of the canopy's
    underside, and (with ``gaps``) as many sky pixels in between whose rays pass through the same voxels."""
    x, y = np.meshgrid(np.arange(6.0, 12.0, 0.25), np.arange(-3.0, 3.0, 0.25))
    leaves = np.stack([x.ravel(), y.ravel(), np.full(x.size, 8.5)], 1)
    vd = CENTRE - leaves
    vd /= np.linalg.norm(vd, axis=1, keepdims=True)
    if gaps:  # sky pixels between the leaves (their rays cross the canopy's voxels)
        holes = leaves + np.array([0.125, 0.125, 0.0])
        far = holes - CENTRE
        far /= np.linalg.norm(far, axis=1, keepdims=True)
    else:
        far = np.zeros((0, 3))
    n_f = len(far)
    return ViewObservation("CAM_FRONT", leaves, np.full((len(leaves), 3), 0.05, np.float32), vd,
                           np.zeros(len(leaves), bool), far, np.ones((n_f, 3), np.float32), np.ones(n_f, bool),
                           np.zeros(n_f, bool), CENTRE)


def _build(obs: ViewObservation) -> np.ndarray:
    sky = np.full((16, 32, 3), 1.0, np.float32)
    light = DistantSun(None, np.zeros(3), np.array([0.2, 0.2, 0.2]))
    params, _ = build_volume(GRID, [obs], None, light, sky)
    return params


def test_sky_gap_alpha_is_the_fraction_of_rays_that_stop():
    a = sky_gap_alpha(np.array([4.0, 4.0, 0.0]), np.array([0, 1, 2]), stride=4, weight=1.0)
    assert np.allclose(a, [1.0, 0.5, 0.0])


def test_sky_rays_count_once_per_voxel():
    d = np.array([[1.0, 0.0, 1.0]]) / np.sqrt(2.0)
    obs = ViewObservation("CAM", np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros((0, 3)), np.zeros(0, bool),
                          np.repeat(d, 3, 0), np.ones((3, 3), np.float32), np.ones(3, bool), np.zeros(3, bool), CENTRE)
    counts = sky_crossings(GRID, [obs], stride=1)
    assert counts.max() == 3 and set(np.unique(counts)) <= {0, 3}


def test_canopy_with_sky_gaps_is_less_opaque_than_a_solid_one():
    solid, gappy = _build(_canopy(False)), _build(_canopy(True))
    leaves = _canopy(False).points
    flat, inside = GRID.flat_index(leaves)
    a_solid = solid.reshape(-1, solid.shape[-1])[flat[inside], CH_ALPHA]
    a_gappy = gappy.reshape(-1, gappy.shape[-1])[flat[inside], CH_ALPHA]
    assert np.all(a_solid == 1.0)
    assert a_gappy.mean() < 0.8 and np.all(a_gappy > 0.0)  # partly open, never removed
    # the camera's own view up through the canopy: light comes through the gappy one
    sky = np.full((16, 32, 3), 1.0, np.float32)
    up = leaves[len(leaves) // 2 : len(leaves) // 2 + 20] - CENTRE
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    p = np.repeat(CENTRE[None], len(up), 0)
    tau_solid = HybridLighting(sky, grid=GRID, params=solid).transmittance(p, up)
    tau_gappy = HybridLighting(sky, grid=GRID, params=gappy).transmittance(p, up)
    assert np.mean(tau_solid) < 0.05 and np.mean(tau_gappy) > np.mean(tau_solid) + 0.1
