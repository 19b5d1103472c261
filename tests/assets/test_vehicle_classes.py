"""Procedural trucks, buses, trailers and construction vehicles: built to the target box, solid, deterministic."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from streetaug.augment.assets.bus import procedural_bus, procedural_bus_variants
from streetaug.augment.assets.class_sizes import read_class_sizes
from streetaug.augment.assets.construction_vehicle import (procedural_construction_vehicle,
                                                           procedural_construction_vehicle_variants)
from streetaug.augment.assets.trailer import procedural_trailer, procedural_trailer_variants
from streetaug.augment.assets.truck import procedural_truck, procedural_truck_variants
from streetaug.augment.assets.validate import face_normals, validate_asset
from streetaug.augment.assets.vehicle_parts import TYRE

# generator, its variants, variant -> nuScenes category
GENERATORS = {
    "truck": (procedural_truck, procedural_truck_variants, lambda v: "vehicle.truck"),
    "bus": (procedural_bus, procedural_bus_variants, lambda v: f"vehicle.bus.{v}"),
    "trailer": (procedural_trailer, procedural_trailer_variants, lambda v: "vehicle.trailer"),
    "construction": (procedural_construction_vehicle, procedural_construction_vehicle_variants,
                     lambda v: "vehicle.construction"),
}
CASES = [(g, v) for g, (_, variants, _) in GENERATORS.items() for v in variants()]
MAX_TRIANGLES = 20_000


def _sizes(category: str) -> dict[str, np.ndarray]:
    s = read_class_sizes()[category]
    return {"min": s.min_wlh, "mean": s.mean_wlh, "max": s.max_wlh,
            # long but low and narrow, short but tall and wide: proportions off the diagonal
            "long-low": np.array([s.min_wlh[0], s.max_wlh[1], s.min_wlh[2]]),
            "short-tall": np.array([s.max_wlh[0], s.min_wlh[1], s.max_wlh[2]])}


def _down_ray_hits(asset) -> np.ndarray:
    """(n,) bool: vertical rays cast down over a grid covering the footprint, hitting the mesh."""
    lo, hi = asset.vertices.min(axis=0), asset.vertices.max(axis=0)
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], 25)[1:-1], np.linspace(lo[1], hi[1], 9)[1:-1])
    origins = np.stack([x.ravel(), y.ravel(), np.full(x.size, hi[2] + 1.0)], 1)
    mesh = trimesh.Trimesh(asset.vertices, asset.faces, process=False)
    return mesh.ray.intersects_any(origins, np.tile([0.0, 0.0, -1.0], (len(origins), 1)))


@pytest.mark.parametrize("gen,variant", CASES)
def test_built_to_every_size_of_the_table(gen, variant):
    make, _, category_of = GENERATORS[gen]
    category = category_of(variant)
    for k, (label, wlh) in enumerate(_sizes(category).items()):
        a = make(k, wlh, variant)
        assert a.category == category
        np.testing.assert_allclose(a.wlh, wlh, rtol=0.01, err_msg=f"{gen}/{variant} at the {label} size")
        assert len(a.faces) <= MAX_TRIANGLES, f"{gen}/{variant} {label}: {len(a.faces)} triangles"
        assert len(a.faces) >= 1000, f"{gen}/{variant} {label}: only {len(a.faces)} triangles"
        # origin at the bottom centre; the ground contact at z = 0 belongs to the tyres / tracks
        lo, hi = a.vertices.min(axis=0), a.vertices.max(axis=0)
        np.testing.assert_allclose([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]], 0.0, atol=1e-9)
        low = a.vertices[a.faces].min(axis=1)[:, 2] < 0.005
        assert np.all(a.face_material[low] == TYRE), f"{gen}/{variant} {label}: non-tyre faces touch the ground"
        v2 = validate_asset(a)
        assert len(v2.faces) == len(a.faces)  # already clean: nothing left to drop


@pytest.mark.parametrize("gen,variant", CASES)
def test_deterministic_and_seeded(gen, variant):
    make = GENERATORS[gen][0]
    a, b, c = make(7, None, variant), make(7, None, variant), make(8, None, variant)
    for field in ("vertices", "faces", "face_material", "vertex_normals"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert [m.base_color.tolist() for m in a.materials] == [m.base_color.tolist() for m in b.materials]
    differs = a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices) or \
        [m.base_color.tolist() for m in a.materials] != [m.base_color.tolist() for m in c.materials]
    assert differs, f"{gen}/{variant}: seeds 7 and 8 gave the same asset"


@pytest.mark.parametrize("gen,variant", CASES)
def test_solid_to_rays_and_outward(gen, variant):
    make = GENERATORS[gen][0]
    a = make(3, None, variant)
    hits = _down_ray_hits(a)
    # loads, masts and open frames leave gaps; a body-on-wheels vehicle covers most of its footprint
    need = 0.45 if variant in ("excavator", "loader", "crane_truck", "flatbed") else 0.7
    assert hits.mean() > need, f"{gen}/{variant}: only {hits.mean():.0%} of downward rays hit"
    # faces wind outwards: normals of the top-most hits point up
    mesh = trimesh.Trimesh(a.vertices, a.faces, process=False)
    lo, hi = a.vertices.min(axis=0), a.vertices.max(axis=0)
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], 15)[1:-1], np.linspace(lo[1], hi[1], 7)[1:-1])
    origins = np.stack([x.ravel(), y.ravel(), np.full(x.size, hi[2] + 1.0)], 1)
    _, _, tri = mesh.ray.intersects_location(origins, np.tile([0.0, 0.0, -1.0], (len(origins), 1)),
                                             multiple_hits=False)
    fn, _ = face_normals(a.vertices, a.faces)
    assert np.mean(fn[tri, 2] > 0) > 0.9, f"{gen}/{variant}: top faces wind inwards"
    assert np.all(np.isfinite(a.vertex_normals)) and np.allclose(np.linalg.norm(a.vertex_normals, axis=1), 1.0)


@pytest.mark.parametrize("gen", list(GENERATORS))
def test_variant_drawn_and_defaults(gen):
    make, variants, category_of = GENERATORS[gen]
    size = read_class_sizes()
    biggest = max((size[category_of(v)].max_wlh for v in variants()), key=lambda w: w[1])
    drawn = {make(s, None if s % 2 else biggest).name.split("-")[2] for s in range(10)}
    assert drawn <= set(variants()) and len(drawn) >= 2, f"{gen}: drew only {drawn}"
    for v in variants():
        a = make(0, None, v)
        s = size[category_of(v)]
        assert np.all(a.wlh >= s.min_wlh - 1e-6) and np.all(a.wlh <= s.max_wlh + 1e-6), f"{gen}/{v}: {a.wlh}"


@pytest.mark.parametrize("gen", list(GENERATORS))
def test_bad_inputs_raise(gen):
    make, variants, _ = GENERATORS[gen]
    with pytest.raises(ValueError) as e:
        make(0, None, "hovercraft")
    assert all(v in str(e.value) for v in variants()) and "hovercraft" in str(e.value)
    for bad in ([2.5, 0.0, 3.0], [2.5, -8.0, 3.0], [np.nan, 8.0, 3.0], [2.5, 8.0], [2.5, np.inf, 3.0]):
        with pytest.raises(ValueError, match="wlh"):
            make(0, bad, None)


def test_parts_that_matter():
    """Spot checks of the described parts: glass on cabs, lamps at the front and rear, many wheels on long
    vehicles, a bendy bus's three axles, an excavator's boom reaching over the tracks."""
    t = procedural_truck(1, [2.5, 10.0, 3.6], "box")
    names = [m.name for m in t.materials]
    used = {names[i] for i in np.unique(t.face_material)}
    assert {"glass", "headlight", "taillight", "tyre", "rim", "paint", "accent"} <= used
    glass = t.face_material == names.index("glass")
    cen = t.vertices[t.faces[glass]].mean(axis=1)
    assert cen[:, 0].min() > 10.0 / 2 - 2.5, "a lorry's glass belongs to its cab at the front"
    head = t.vertices[t.faces[t.face_material == names.index("headlight")]].mean(axis=1)
    tail = t.vertices[t.faces[t.face_material == names.index("taillight")]].mean(axis=1)
    assert head[:, 0].min() > 4.5 and tail[:, 0].max() < -4.5
    # a 10 m lorry has 3 axles: count the ground contacts of tyres along x
    def axles(asset):
        tyre = asset.faces[asset.face_material == TYRE]
        low = asset.vertices[tyre.ravel()]
        low = low[low[:, 2] < 0.01]
        xs = np.sort(np.unique(np.round(low[:, 0], 1)))
        return 1 + int(np.sum(np.diff(xs) > 0.5))
    assert axles(t) == 3
    assert axles(procedural_truck(1, [2.3, 6.0, 3.0], "box")) == 2
    assert axles(procedural_bus(0, [2.9, 17.5, 3.3], "bendy")) == 3
    assert axles(procedural_bus(0, [2.9, 10.0, 3.3], "rigid")) == 2
    assert axles(procedural_bus(0, [2.9, 14.5, 3.4], "rigid")) == 3
    ex = procedural_construction_vehicle(2, [3.0, 7.0, 3.2], "excavator")
    top = ex.vertices[:, 2].argmax()
    assert ex.vertices[top, 0] > 0.0, "the excavator's highest point (the boom) lies forward of the middle"
