"""The shoulder (character) line of the procedural body: a crisp turn of the shading normal along both sides."""

import numpy as np
import pytest

from streetaug.augment.assets.car_body import (BODY_SPECS, SHOULDER_STRIP_M, axle_distances, body_part,
                                               panel_gaps, shoulder_height)
from streetaug.augment.core.raycast import RayScene


def _side_normals(part, spec, d: np.ndarray, z: np.ndarray, side: float) -> np.ndarray:
    """Interpolated shading normals (N, 3) where rays from outside the ``side`` (+1 left, -1 right) meet the body at
    distances from the nose ``d`` and heights ``z`` (N,)."""
    x = spec.length / 2 - d
    origins = np.stack([x, np.full_like(x, side * 3.0), z], axis=1)
    hits = RayScene(part.vertices, part.faces).intersect(origins, np.tile([0.0, -side, 0.0], (len(x), 1)))
    assert hits.hit.all()
    tri = part.normals[part.faces[hits.face]]  # (N, 3 vertices, 3)
    u, v = hits.bary[:, :1], hits.bary[:, 1:]
    n = (1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("body", sorted(BODY_SPECS))
def test_the_shoulder_line_turns_the_normal_within_a_centimetre(body):
    spec = BODY_SPECS[body]()
    part = body_part(spec)
    # Along the cabin (ahead of it the line runs out where the wings round over into the bonnet).
    d = np.linspace(spec.d_ws + 0.2, min(spec.d_rear, axle_distances(spec)[1]) - 0.2, 25)
    gaps = np.array([g for g, _ in panel_gaps(spec)])
    d = d[np.min(np.abs(d[:, None] - gaps[None]), axis=1) > 0.03]  # not on a door's shut line
    z0 = shoulder_height(spec, d)
    for side in (1.0, -1.0):
        below = _side_normals(part, spec, d, z0 - 0.003, side)
        above = _side_normals(part, spec, d, z0 + SHOULDER_STRIP_M + 0.003, side)
        turn_deg = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", below, above), -1, 1)))
        # The old smooth loft turned ~1 deg over these 11 mm.  The upper surface faces further up.
        assert np.median(turn_deg) > 15.0 and turn_deg.min() > 8.0, (body, side, turn_deg.round(1))
        assert (above[:, 2] > below[:, 2]).all(), body
        # ... and is a line: over the next 11 mm on either side the normal turns far less.
        for z_near, n_line in ((z0 - 0.014, below), (z0 + SHOULDER_STRIP_M + 0.014, above)):
            n_near = _side_normals(part, spec, d, z_near, side)
            next_deg = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n_near, n_line), -1, 1)))
            assert np.median(next_deg) < 0.35 * np.median(turn_deg), (body, next_deg.round(1))


@pytest.mark.parametrize("body", sorted(BODY_SPECS))
def test_the_crease_keeps_the_body_closed_and_inside_its_outline(body):
    spec = BODY_SPECS[body]()
    part = body_part(spec)
    F = part.faces
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()
    # The crease only moves the surface inwards: nothing beyond the loft's half width.
    assert np.abs(part.vertices[:, 1]).max() <= spec.width / 2 + 1e-9
