"""How a static point's global height changes from keyframe to keyframe of a scene.

nuScenes' ego poses are localised in x, y and yaw on a flat map: their z is 0 in every keyframe (roll and
pitch come from the IMU), so each keyframe's global frame sits at the ego's height and a static point's
global z drifts through the scene as the road climbs or falls; more so far from the ego, where the tilt's
error adds up. On scene-0916 one parked car's annotated bottom goes from 2.4 m (keyframe 8) to 0.7 m
(keyframe 40); the median static object moves 1.0 m over the scene. Anything that stays put through a scene
(a parked track) must follow that drift to stand on each keyframe's ground.

The annotated static objects measure it: their boxes are drawn on each keyframe's LiDAR, so the change of a
static object's bottom between two consecutive keyframes is the drift at its place. :func:`height_drift_m`
takes the median of those changes over the static objects near a point, step by step, and adds them up from a
reference keyframe.

Shapes: I instances, K keyframes (in time order); heights in metres, global frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:  # a leaf module: benchmarks load it by path next to other checkouts' code
    from streetaug.datasets.sample import Sample

STATIC_MAX_XY_SPREAD_M = 0.5  # an instance whose box centre moves less than this (x and y range) is static
DRIFT_RADIUS_M = 25.0  # static objects within this of the point measure its drift (grown 2x, 4x if too few)
MIN_OBJECTS = 2


def static_bottoms(samples: Sequence[Sample]) -> np.ndarray:
    """(I, K, 3) bottom centres of the scene's static annotated instances in each keyframe (NaN where the
    instance is not annotated); static = annotated in at least two keyframes, its centre moving less than
    ``STATIC_MAX_XY_SPREAD_M`` in x and in y. (0, K, 3) when there are none."""
    K = len(samples)
    per_instance: dict[str, np.ndarray] = {}
    for k, sample in enumerate(samples):
        for box in sample.boxes:
            if not box.instance_token:
                continue
            row = per_instance.setdefault(box.instance_token, np.full((K, 3), np.nan))
            row[k] = [box.center[0], box.center[1], box.center[2] - 0.5 * box.wlh[2]]
    rows = []
    for row in per_instance.values():
        seen = np.isfinite(row[:, 0])
        if seen.sum() >= 2 and np.all(np.ptp(row[seen, :2], axis=0) < STATIC_MAX_XY_SPREAD_M):
            rows.append(row)
    return np.array(rows) if rows else np.zeros((0, K, 3))


def step_drift_m(bottoms: np.ndarray, xy: np.ndarray, radius_m: float = DRIFT_RADIUS_M,
                 min_objects: int = MIN_OBJECTS) -> np.ndarray:
    """(K - 1,) the change of the ground's global height at ``xy`` (2,) from keyframe k to k + 1: the median
    change of the static objects annotated in both within ``radius_m`` (grown 2x and 4x until
    ``min_objects`` are found; fewer if that is all there is), else of all static objects in both; 0 where
    none is in both."""
    K = bottoms.shape[1]
    out = np.zeros(max(K - 1, 0))
    if len(bottoms) == 0 or K < 2:
        return out
    with np.errstate(invalid="ignore"):
        dz = bottoms[:, 1:, 2] - bottoms[:, :-1, 2]  # (I, K-1), NaN unless annotated in both
        dist = np.linalg.norm(np.nanmean(bottoms[:, :, :2], axis=1) - np.asarray(xy, np.float64)[None], axis=1)
    both = np.isfinite(dz)
    for k in range(K - 1):
        pair = both[:, k]
        if not pair.any():
            continue
        for scale in (1.0, 2.0, 4.0):
            chosen = pair & (dist <= radius_m * scale)
            if chosen.sum() >= min_objects:
                break
        if not chosen.any():
            chosen = pair
        out[k] = float(np.median(dz[chosen, k]))
    return out


def height_drift_m(bottoms: np.ndarray, xy: np.ndarray, ref: int, radius_m: float = DRIFT_RADIUS_M) -> np.ndarray:
    """(K,) the ground's global height at ``xy`` in each keyframe minus its height in keyframe ``ref`` (0 at
    ``ref``), summed from :func:`step_drift_m` outwards from ``ref``."""
    steps = step_drift_m(bottoms, xy, radius_m)
    cumulative = np.concatenate([[0.0], np.cumsum(steps)])
    return cumulative - cumulative[ref]


def held_out_errors_m(bottoms: np.ndarray, ego_xy: np.ndarray, min_keyframes: int = 10
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Leave one out over the static objects seen in >= ``min_keyframes`` keyframes: each one's bottom height in
    its other keyframes predicted from the keyframe where the ego (``ego_xy`` (K, 2)) passes closest, held
    constant and plus the drift the *other* objects measure; the signed errors (constant, with drift), (N,)."""
    constant, drifted = [], []
    for i in range(len(bottoms)):
        seen = np.flatnonzero(np.isfinite(bottoms[i, :, 2]))
        if len(seen) < min_keyframes:
            continue
        xy = np.nanmean(bottoms[i, :, :2], axis=0)
        ref = int(seen[np.argmin(np.linalg.norm(ego_xy[seen] - xy, axis=1))])
        drift = height_drift_m(np.delete(bottoms, i, axis=0), xy, ref)
        other = seen[seen != ref]
        z, z_ref = bottoms[i, other, 2], bottoms[i, ref, 2]
        constant.append(z - z_ref)
        drifted.append(z - (z_ref + drift[other]))
    return (np.concatenate(constant), np.concatenate(drifted)) if constant else (np.zeros(0), np.zeros(0))
