"""The car body's shape: hard normals across creases only, the section's planes and creases (flat sides,
set-in side glass, crowned roof), black window surround, A pillars leaning with the windscreen."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from streetaug.augment.assets import car_body as cb
from streetaug.augment.assets.mesh_parts import crease_normals
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.validate import face_normals


def test_crease_normals_split_a_cube_but_not_a_sphere():
    cube = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    V, F, N = crease_normals(cube.vertices, cube.faces, 35.0)
    assert len(V) == 24  # 8 corners x 3 faces each
    fn, _ = face_normals(V, F)
    assert np.allclose(N[F[:, 0]], fn, atol=1e-9)  # flat faces keep their own normal
    sphere = trimesh.creation.icosphere(subdivisions=3)
    V, F, N = crease_normals(sphere.vertices, sphere.faces, 35.0)
    assert len(V) == len(sphere.vertices)  # smooth: nothing split
    assert np.allclose(N, V / np.linalg.norm(V, axis=1, keepdims=True), atol=0.02)


@pytest.mark.parametrize("body", sorted(cb.BODY_SPECS))
def test_section_has_flat_sides_set_in_glass_and_a_crowned_roof(body):
    spec = cb.BODY_SPECS[body]()
    d_mid = 0.5 * (spec.d_roof_front + spec.d_roof_back)
    Y, Z = cb.section_rows(spec, np.array([d_mid]))
    Y, Z = Y[0], Z[0]
    assert np.all(np.diff(Z) >= 0)
    top, _, hw, belt = (float(a[0]) for a in cb.body_profiles(spec, np.array([d_mid])))
    side = (Z >= cb._bumper_line(spec)) & (Z <= belt - 0.1)
    assert side.sum() >= 3 and np.ptp(Y[side]) < 0.02  # the door is a near-vertical plane
    glass = slice(sum(cb._SEG_ROWS[:3]), sum(cb._SEG_ROWS[:4]))
    assert Y[glass].max() < hw - 0.05  # the side glass stands inboard of the shoulder (a ledge)
    assert Y[glass][-1] < Y[glass][0] - 0.1  # ... and leans in (tumblehome)
    roof = slice(sum(cb._SEG_ROWS[:4]) + 1, None)
    assert np.all(np.diff(Z[roof]) > 0) and top - Z[roof][0] > 0.02  # crowned, rising to the centre


def test_hard_normals_at_the_belt_ledge_smooth_on_the_door():
    part = cb.body_part(cb.sedan_spec())
    V, N = part.vertices, part.normals
    spec = cb.sedan_spec()
    x_mid = spec.length / 2 - 0.5 * (spec.d_roof_front + spec.d_roof_back)
    near = np.abs(V[:, 0] - x_mid) < 0.2
    # The same position with two normals: a crease (the ledge, the window frame); the door's plane: one.
    key = np.round(V[near] * 1e6).astype(np.int64)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    split_z = V[near][counts[inv] > 1][:, 2]
    _, _, _, belt = cb.body_profiles(spec, np.array([0.5 * (spec.d_roof_front + spec.d_roof_back)]))
    assert np.any(np.abs(split_z - belt[0]) < 0.02)
    door = near & (V[:, 2] > cb._bumper_line(spec) + 0.05) & (V[:, 2] < belt[0] - 0.15) & (np.abs(V[:, 1]) > 0.5)
    assert door.sum() >= 4 and np.abs(N[door, 1]).min() > 0.97


@pytest.mark.parametrize("body", sorted(cb.BODY_SPECS))
def test_black_window_surround_and_leaning_a_pillar(body):
    car = procedural_car(11, body)
    n, _ = face_normals(car.vertices, car.faces)
    c = car.vertices[car.faces].mean(axis=1)
    glass = (car.face_material == cb.GLASS) & (np.abs(n[:, 1]) > 0.5)
    trim_up = (car.face_material == cb.TRIM) & (np.abs(n[:, 1]) > 0.3) & (c[:, 2] > c[glass, 2].min())
    assert trim_up.sum() >= 20, body  # window frames, belt seal, B pillar
    # The front side window's leading edge leans back: its foremost point high up is behind the one low down.
    z = c[glass, 2]
    lo, hi = z < np.quantile(z, 0.25), z > np.quantile(z, 0.75)
    assert c[glass][hi, 0].max() < c[glass][lo, 0].max() - 0.1, body
