"""Where a camera's sky mesh stands against the light volume (shared by both backends of :mod:`.volume`).

A ray after the seen-surface trace either hits a seen surface, reaches only a camera's sky mesh (the sky pixel it saw
in that direction, meshed :data:`.seen_surfaces.SKY_MESH_RANGE_M` away), or misses every one. The latter two go
through Eq. 1 (:func:`through_volume`); a sky-mesh hit's pixel replaces the dome behind the volume and is blended in
front of it by :func:`sky_preempt_weight`.
"""

from __future__ import annotations

import numpy as np

from .seen_surfaces import DEPTH_UNCERTAINTY, SKY_MESH_RANGE_M

SKY_HIT_FRACTION = 0.5  # a seen-surface hit this far out (x SKY_MESH_RANGE_M) is a camera's sky mesh


# A ray that reaches a camera's sky mesh (and no nearer seen surface) shows that sky pixel with the weight
# 1 - b / SKY_PREEMPT_BASELINE_M (b: the baseline across the ray between its origin and that camera, metres),
# the rest Eq. 1 with the sky pixel behind the volume: from near the camera the sky it saw is seen past the
# volume's coarse voxels at a canopy's edge; from far across, a structure no camera saw in front of that sky (the
# volume's LiDAR / prior occupancy) stands in front of it. Scene-0916 stride-4 (bench_real_lighting,
# quick check): six-view forward median 17.03 dB (no sky mesh) -> 17.43 (sky always in front; 4 m: 17.15, 10 m:
# 17.43); the single side cameras at t + 3 (every_camera) lost up to 2 dB with the sky always in front, with 10 m
# they keep their scores (keyframes 4, 20, 32).
SKY_PREEMPT_BASELINE_M = 10.0


def sky_preempt_weight(sky: np.ndarray, t: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """(N,) weight of the sky pixel in front of the volume (see ``SKY_PREEMPT_BASELINE_M``) of rays that hit a
    camera's sky mesh (``sky`` (N,) bool) at ``t`` (N,) metres with the reprojection uncertainty ``spread`` (N,)
    radians (:meth:`.seen_surfaces.SeenSurfaces.trace_spread`: ``DEPTH_UNCERTAINTY x baseline / t`` there); 0
    elsewhere."""
    baseline = spread * np.where(sky, t, 1.0) / DEPTH_UNCERTAINTY
    return np.where(sky, np.clip(1.0 - baseline / SKY_PREEMPT_BASELINE_M, 0.0, 1.0), 0.0)


def through_volume(hit: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which rays (N,) go through Eq. 1 after the seen-surface trace (hit (N,) bool, t (N,) metres): (those that
    miss every seen surface or reach only a camera's sky mesh, the latter). A sky-mesh hit is the sky a camera
    saw in that direction; it stands for the dome behind the volume (the seen sky at the image's resolution),
    not in front of it: what the volume holds along the ray and no camera saw (a building outside the frustum
    the sky was seen through) still stands in front of it."""
    sky = hit & (t >= SKY_HIT_FRACTION * SKY_MESH_RANGE_M)
    return ~hit | sky, sky
