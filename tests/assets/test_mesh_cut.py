"""mesh_parts.cut_along_levels: cutting a closed mesh along zero levels keeps it closed and unchanged in shape."""

from __future__ import annotations

import numpy as np
import trimesh

from streetaug.augment.assets.mesh_parts import cut_along_levels, signed_volume
from streetaug.augment.assets.validate import face_normals, smooth_vertex_normals


def _sphere():
    m = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)
    return V, F, smooth_vertex_normals(V, F)


def test_cut_keeps_the_mesh_closed_its_shape_and_its_winding():
    V, F, N = _sphere()
    levels = np.stack([V[:, 0] + 0.3 * V[:, 1] ** 2 - 0.1, V[:, 2] - 0.2], axis=1)
    V2, F2, N2, lv2, parent = cut_along_levels(V, F, N, levels)
    assert len(F2) > len(F) and np.array_equal(V2[: len(V)], V)
    edges = np.sort(np.concatenate([F2[:, [0, 1]], F2[:, [1, 2]], F2[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()  # still watertight: a crossing vertex is shared by both faces of its edge
    assert abs(signed_volume(V2, F2) - signed_volume(V, F)) < 1e-12  # positions unchanged: the same surface
    n_new, area = face_normals(V2, F2)
    n_old, _ = face_normals(V, F)
    assert (np.einsum("ij,ij->i", n_new, n_old[parent]) > 0.999).all() and area.min() > 0.0
    assert np.allclose(np.linalg.norm(N2, axis=1), 1.0)
    # Every face lies on one side of each level; new vertices sit on the level they were cut along.
    for k in range(2):
        v = lv2[F2][:, :, k]
        assert not ((v.max(axis=1) > 0) & (v.min(axis=1) < 0)).any()
    exact = np.stack([V2[:, 0] + 0.3 * V2[:, 1] ** 2 - 0.1, V2[:, 2] - 0.2], axis=1)
    on_plane = lv2[len(V):, 1] == 0.0
    assert on_plane.any() and np.abs(exact[len(V):][on_plane, 1]).max() < 1e-12  # z = 0.2 is linear: exact


def test_crossings_near_a_vertex_snap_onto_it():
    V, F, N = _sphere()
    # A level passing 1 % of an edge from many vertices: no slivers, the vertices move onto the level instead.
    z0 = np.sort(np.unique(np.round(V[:, 2], 9)))[len(np.unique(np.round(V[:, 2], 9))) // 2] + 1e-3
    V2, F2, _, lv2, _ = cut_along_levels(V, F, N, (V[:, 2] - z0)[:, None], snap=0.05)
    _, area = face_normals(V2, F2)
    assert area.min() > 1e-5
    assert (lv2[: len(V), 0] == 0.0).any()


def test_nothing_to_cut_returns_the_mesh():
    V, F, N = _sphere()
    V2, F2, N2, lv2, parent = cut_along_levels(V, F, N, np.ones((len(V), 1)))
    assert np.array_equal(F2, F) and np.array_equal(parent, np.arange(len(F))) and len(V2) == len(V)
