"""A material's metallic flakes reach the BRDF at its ray hits (the renderer shades them)."""

from __future__ import annotations

import numpy as np

from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.render.surface import prepare_asset, surface_at_hits


def _two_squares(flakes: tuple[float, float]) -> Asset:
    V = np.array([[0, -1, 0], [0, 1, 0], [0, 1, 1], [0, -1, 1],
                  [0, -1, 1.2], [0, 1, 1.2], [0, 1, 2.2], [0, -1, 2.2]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    mats = tuple(Material(f"m{i}", base_color=np.array([0.5, 0.1, 0.1]), metallic=0.3, roughness=0.4,
                          clearcoat=1.0, flake=k) for i, k in enumerate(flakes))
    return Asset(name=f"squares-{flakes}", vertices=V, faces=F, face_material=np.array([0, 0, 1, 1]),
                 materials=mats, vertex_normals=np.tile([[-1.0, 0.0, 0.0]], (8, 1)), uv=None, category="vehicle.car")


def test_flakes_reach_the_brdf_per_hit_material():
    prep = prepare_asset(_two_squares((0.6, 0.0)))
    np.testing.assert_allclose(prep.flake, [0.6, 0.0])
    dirs = np.tile([[-1.0, 0.0, 0.0]], (4, 1))
    hits = surface_at_hits(prep, np.array([0, 1, 2, 3]), np.full((4, 2), 0.25), dirs)
    np.testing.assert_allclose(hits.params.flake, [0.6, 0.6, 0.0, 0.0])


def test_an_asset_without_flakes_has_no_flake_lobe():
    prep = prepare_asset(_two_squares((0.0, 0.0)))
    assert prep.flake is None
    hits = surface_at_hits(prep, np.array([0]), np.full((1, 2), 0.25), np.array([[-1.0, 0.0, 0.0]]))
    assert hits.params.flake is None and not hits.params.has_flake
