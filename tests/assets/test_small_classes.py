"""Procedural small classes: pedestrians, bicycles, motorcycles, traffic cones, barriers (and their primitives)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from streetaug.augment.assets.barrier import procedural_barrier, procedural_barrier_variants
from streetaug.augment.assets.class_sizes import read_class_sizes
from streetaug.augment.assets.mesh_parts import signed_volume
from streetaug.augment.assets.pedestrian import (
    body_for, procedural_pedestrian, procedural_pedestrian_variants, rider_parts,
)
from streetaug.augment.assets.revolve import box, capsule, ellipsoid, prism, revolve, straight_tubes, torus, tube
from streetaug.augment.assets.traffic_cone import procedural_traffic_cone, procedural_traffic_cone_variants
from streetaug.augment.assets.two_wheeler import (
    procedural_bicycle, procedural_bicycle_variants, procedural_motorcycle, procedural_motorcycle_variants,
)
from streetaug.augment.assets.validate import validate_asset

SIZES = read_class_sizes()

# generator, its variants, category
RIGID = {
    "bicycle": (procedural_bicycle, procedural_bicycle_variants(), "vehicle.bicycle"),
    "motorcycle": (procedural_motorcycle, procedural_motorcycle_variants(), "vehicle.motorcycle"),
    "trafficcone": (procedural_traffic_cone, procedural_traffic_cone_variants(), "movable_object.trafficcone"),
    "barrier": (procedural_barrier, procedural_barrier_variants(), "movable_object.barrier"),
}
RIGID_CASES = [(k, v) for k, (_, vs, _) in RIGID.items() for v in vs]
CYCLE_ATTR = {"with_rider": "cycle.with_rider", "without_rider": "cycle.without_rider"}


def _targets(category: str) -> list[np.ndarray]:
    s = SIZES[category]
    mixed = np.array([s.max_wlh[0], s.min_wlh[1], s.mean_wlh[2]])
    return [s.min_wlh, s.mean_wlh, s.max_wlh, mixed]


def _mesh(asset) -> trimesh.Trimesh:
    return trimesh.Trimesh(asset.vertices, asset.faces, process=False)


def _down_hits(asset, n: int = 24) -> np.ndarray:
    """(n*n,) bool: vertical rays from above over the box's footprint that hit the mesh."""
    lo, hi = asset.vertices.min(axis=0), asset.vertices.max(axis=0)
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    origins = np.stack([x.ravel(), y.ravel(), np.full(x.size, hi[2] + 1.0)], 1)
    dirs = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    return _mesh(asset).ray.intersects_any(origins, dirs)


# ----------------------------------------------------------------------------- rigid classes: box, category


@pytest.mark.parametrize("kind,variant", RIGID_CASES)
def test_rigid_box_matches_target_at_min_mean_max(kind, variant):
    gen, _, category = RIGID[kind]
    for i, target in enumerate(_targets(category)):
        asset = gen(i, target, variant)
        np.testing.assert_allclose(asset.wlh, target, rtol=0.01, err_msg=f"{kind}/{variant} at {target}")
        assert asset.category == category
        assert asset.attribute == (CYCLE_ATTR[variant] if kind in ("bicycle", "motorcycle") else None)
        assert abs(asset.vertices[:, 2].min()) < 1e-9  # on the ground
        np.testing.assert_allclose(asset.box_center_object[:2], 0.0, atol=1e-9)
        assert len(validate_asset(asset).faces) == len(asset.faces)  # nothing left to clean
        assert 150 <= len(asset.faces) <= 12_000, f"{kind}/{variant}: {len(asset.faces)} triangles"
        assert np.allclose(np.linalg.norm(asset.vertex_normals, axis=1), 1.0)


@pytest.mark.parametrize("kind", list(RIGID))
def test_rigid_defaults_are_typical_and_deterministic(kind):
    gen, _, category = RIGID[kind]
    s = SIZES[category]
    seen = set()
    for seed in range(6):
        a = gen(seed)
        assert np.all(a.wlh >= s.min_wlh * 0.99) and np.all(a.wlh <= s.max_wlh * 1.01), (kind, a.wlh)
        seen.add(a.name)
    b1, b2, b3 = gen(11), gen(11), gen(12)
    assert np.array_equal(b1.vertices, b2.vertices) and np.array_equal(b1.faces, b2.faces)
    assert np.array_equal(b1.face_material, b2.face_material) and b1.name == b2.name
    assert b1.vertices.shape != b3.vertices.shape or not np.array_equal(b1.vertices, b3.vertices)
    assert len(seen) > 1


@pytest.mark.parametrize("kind", list(RIGID))
def test_bad_variant_and_wlh_raise_naming_the_valid_ones(kind):
    gen, variants, _ = RIGID[kind]
    with pytest.raises(ValueError) as e:
        gen(0, None, "hovercraft")
    for v in variants:
        assert v in str(e.value)
    for bad in ([1.0, 2.0], [1.0, -1.0, 1.0], [np.nan, 1.0, 1.0]):
        with pytest.raises(ValueError, match="wlh"):
            gen(0, bad, variants[0])


def test_cones_and_barriers_stand_flat_on_the_ground():
    for kind in ("trafficcone", "barrier"):
        gen, variants, category = RIGID[kind]
        for v in variants:
            a = gen(3, SIZES[category].mean_wlh, v)
            z = a.vertices[:, 2]
            assert z.min() == 0.0
            assert (z == 0.0).sum() >= 4, f"{kind}/{v}: the base is not flat"
            hit = _down_hits(a)
            # a fence is a thin panel on two feet: seen from above mostly its feet
            least = {"trafficcone": 0.45, "barrier": 0.1 if v == "fence" else 0.6}[kind]
            assert hit.mean() > least, (kind, v, hit.mean())


def test_cone_bands_are_retroreflective_and_body_orange():
    for v in procedural_traffic_cone_variants():
        a = procedural_traffic_cone(5, None, v)
        mats = {m.name: m for m in a.materials}
        band = [i for i, m in enumerate(a.materials) if m.retroreflective >= 0.8]
        assert band and np.isin(a.face_material, band).any(), v
        body = mats["cone_plastic"].base_color
        assert body[0] > 2 * body[1] > 0 and body[2] < body[1], v  # red-orange
        assert 0.3 <= mats["cone_plastic"].roughness <= 0.7


def test_barrier_long_side_runs_along_y():
    for v in procedural_barrier_variants():
        a = procedural_barrier(2, [2.4, 0.6, 1.0], v)
        ext = np.ptp(a.vertices, axis=0)
        assert ext[1] > 3 * ext[0], (v, ext)
    names = [m.name for m in procedural_barrier(0, None, "concrete").materials]
    assert names[0] == "concrete"
    assert procedural_barrier(0, None, "concrete").materials[0].roughness == pytest.approx(0.9)


# ----------------------------------------------------------------------------- two-wheelers


def test_two_wheelers_ray_cast_from_above():
    for gen in (procedural_bicycle, procedural_motorcycle):
        for v in ("with_rider", "without_rider"):
            hit = _down_hits(gen(4, None, v), n=40)
            assert hit.mean() > 0.05, (gen.__name__, v, hit.mean())


def test_bicycle_frame_tubes_are_thin_and_still_hit():
    a = procedural_bicycle(7, [0.6, 1.75, 1.05], "without_rider")
    paint = [m.name for m in a.materials].index("frame_paint")
    hi = a.vertices.max(axis=0)
    # horizontal rays along -y on a 2 mm grid over the middle of the frame
    x, z = np.meshgrid(np.linspace(-0.15, 0.15, 31), np.arange(0.3, hi[2], 0.002), indexing="ij")
    origins = np.stack([x.ravel(), np.full(x.size, hi[1] + 1.0), z.ravel()], 1)
    tri, ray = _mesh(a).ray.intersects_id(origins, np.tile([0.0, -1.0, 0.0], (len(origins), 1)),
                                          multiple_hits=False)[:2]
    on_paint = np.zeros(len(origins), dtype=bool)
    on_paint[ray[a.face_material[tri] == paint]] = True
    on_paint = on_paint.reshape(x.shape)
    assert on_paint.any(), "no ray hit the frame"
    runs = []
    for col in on_paint:  # contiguous runs of hits along z in each column
        d = np.diff(np.concatenate([[0], col.astype(int), [0]]))
        runs += list((np.flatnonzero(d == -1) - np.flatnonzero(d == 1)) * 0.002)
    assert 0.0 < min(runs) and np.median(runs) < 0.05, runs  # tubes under 5 cm thick


def test_bicycle_height_depends_on_the_rider():
    with_r = [procedural_bicycle(s, None, "with_rider").wlh[2] for s in range(3)]
    without = [procedural_bicycle(s, None, "without_rider").wlh[2] for s in range(3)]
    assert min(with_r) > 1.5 and max(without) < 1.2
    assert procedural_bicycle(1, [0.6, 1.8, 1.75]).attribute == "cycle.with_rider"
    assert procedural_bicycle(1, [0.6, 1.8, 1.0]).attribute == "cycle.without_rider"
    moto = procedural_motorcycle(2, None, "with_rider")
    assert "rider_helmet" in [m.name for m in moto.materials]


def test_rider_parts_hold_the_grips_and_stand_on_the_pedals():
    seat = np.array([-0.3, 0.0, 0.95])
    hands = np.array([[0.3, 0.28, 1.02], [0.3, -0.28, 1.02]])
    feet = np.array([[0.05, 0.12, 0.35], [-0.05, -0.12, 0.2]])
    parts, mats = rider_parts(3, seat, hands, feet, 1.75)
    assert len(parts) >= 15 and all(p.face_material.max() < len(mats) for p in parts)
    V = np.concatenate([p.vertices for p in parts])
    for h in hands:
        assert np.linalg.norm(V - h, axis=1).min() < 0.06  # a hand at each grip
    for f in feet:
        assert np.linalg.norm(V - f, axis=1).min() < 0.08  # a shoe on each pedal
    assert V[:, 2].max() > seat[2] + 0.6  # sits upright-ish: the head well above the saddle
    parts2, _ = rider_parts(3, seat, hands, feet, 1.75)
    assert all(np.array_equal(p.vertices, q.vertices) for p, q in zip(parts, parts2))


# ----------------------------------------------------------------------------- pedestrians


@pytest.mark.parametrize("variant", procedural_pedestrian_variants())
@pytest.mark.parametrize("pose", ["walking", "standing"])
def test_pedestrian_height_box_and_labels(variant, pose):
    category = f"human.pedestrian.{variant}"
    s = SIZES[category]
    for i, h in enumerate((s.min_wlh[2], s.mean_wlh[2], s.max_wlh[2])):
        a = procedural_pedestrian(i, [0.6, 0.6, h], variant, pose)
        assert a.wlh[2] == pytest.approx(h, rel=0.01)
        assert np.all(a.wlh[:2] >= s.min_wlh[:2]) and np.all(a.wlh[:2] <= s.max_wlh[:2]), (a.wlh, s.min_wlh, s.max_wlh)
        assert a.category == category
        assert a.attribute == {"walking": "pedestrian.moving", "standing": "pedestrian.standing"}[pose]
        assert abs(a.vertices[:, 2].min()) < 1e-12
        assert 1000 <= len(a.faces) <= 10_000
        mats = {m.name: m for m in a.materials}
        assert 0.8 <= mats["fabric_top"].roughness <= 0.95 and mats["fabric_top"].metallic == 0.0
        assert mats["skin"].roughness == pytest.approx(0.5)


def test_pedestrian_defaults_determinism_and_errors():
    a, b = procedural_pedestrian(21), procedural_pedestrian(21)
    assert np.array_equal(a.vertices, b.vertices) and a.name == b.name
    poses = [procedural_pedestrian(s, variant="adult").attribute for s in range(20)]
    assert "pedestrian.moving" in poses and "pedestrian.standing" in poses
    with pytest.raises(ValueError, match="adult.*child"):
        procedural_pedestrian(0, variant="elf")
    with pytest.raises(ValueError, match="walking.*standing"):
        procedural_pedestrian(0, pose="dancing")
    with pytest.raises(ValueError, match="wlh"):
        procedural_pedestrian(0, [0.5, 0.5])


def test_walking_stride_is_longer_than_standing_and_feet_touch_the_ground():
    walk = np.median([procedural_pedestrian(s, [0.6, 0.6, 1.75], "adult", "walking").wlh[1] for s in range(6)])
    stand = np.median([procedural_pedestrian(s, [0.6, 0.6, 1.75], "adult", "standing").wlh[1] for s in range(6)])
    assert walk > stand
    a = procedural_pedestrian(4, [0.6, 0.6, 1.7], "adult", "standing")
    shoes = [m.name for m in a.materials].index("shoes")
    z_shoes = a.vertices[np.unique(a.faces[a.face_material == shoes])][:, 2]
    assert z_shoes.min() == pytest.approx(0.0, abs=1e-12)
    skin = [m.name for m in a.materials].index("skin")
    z_skin = a.vertices[np.unique(a.faces[a.face_material == skin])][:, 2]
    assert z_skin.max() > 0.9 * 1.7  # the face / head is at the top


def test_child_has_the_bigger_head():
    rng = np.random.default_rng(0)
    adult = body_for(1.7, False, rng)
    child = body_for(1.2, True, rng)
    assert child.head_h / child.height > 1.2 * adult.head_h / adult.height
    assert child.hip_z / child.height < adult.hip_z / adult.height  # relatively shorter legs


# ----------------------------------------------------------------------------- primitives


def test_primitives_are_closed_and_outward():
    parts = [
        ellipsoid([0, 0, 1], [0.1, 0.2, 0.3], 0), capsule([0, 0, 0], [0.3, 0.1, 0.5], 0.05, 0.03, 0),
        tube(np.array([[0, 0, 0], [0.2, 0, 0.1], [0.4, 0.1, 0.1]]), 0.02, 0),
        torus([0, 0, 0.3], [0, 1, 0], 0.3, 0.03, 0),
        prism(np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), [0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0], 2.0, 0),
        box([0, 0, 0], [1, 2, 3], 0), revolve([0, 0, 1], [0.3, 0.2, 0.0], [0, 0, 0], [0, 0, 1], 0, caps="flat"),
        straight_tubes(np.eye(3) * 0.5 + 1.0, np.eye(3) + 1.0, 0.01, 0),
    ]
    for p in parts:
        m = trimesh.Trimesh(p.vertices, p.faces, process=True)  # merge duplicated (sharp-edge) vertices
        assert m.is_watertight
        assert signed_volume(p.vertices, p.faces) > 0
        fc = p.vertices[p.faces].mean(axis=1)
        assert len(p.normals) == len(p.vertices) and np.all(np.isfinite(p.normals))
        assert len(fc) == len(p.face_material)
    assert signed_volume(parts[5].vertices, parts[5].faces) == pytest.approx(6.0)
