"""The street prior for what the cameras did not see: the street continues along its axis.

Streets are close to extrusions along their direction: lanes, kerbs, sidewalks, hedges and facades keep their
lateral offset and height for long stretches (the mirror symmetry "the road behind looks like the road ahead"
is the special case of a reflection across the plane perpendicular to the street). So an unobserved surface
voxel takes the material of the *observed* surface voxels in the same cell of (lateral offset from the
street's axis, height), wherever along the street they are: :func:`.build.build_volume` multiplies its
physical shading (sun, traced shadows, sky) by the cell's observed/shaded ratio, shrunk towards 1 where few
voxels were observed (a conditional mean: a good blurry guess rather than a sharp wrong one). Only colours
are predicted: the occupancy (shadows, occlusion) stays what the LiDAR and the canyon prior give.

Frames: the volume frame (z up, metres); the street's axis is the ego vehicle's forward direction (it drives
along the street), else the volume's x axis.
"""

from __future__ import annotations

import numpy as np

from ..core import hdr_to_ldr, ldr_to_hdr


def street_axis_xy(forward_vol: np.ndarray | None) -> np.ndarray:
    """Unit (2,) xy direction of the street: the horizontal part of the ego's forward axis (3,) in the volume
    frame; the volume's x axis without one (or if it is near vertical)."""
    if forward_vol is not None:
        f = np.asarray(forward_vol, dtype=np.float64)[:2]
        norm = float(np.hypot(f[0], f[1]))
        if norm >= 0.5:
            return f / norm
    return np.array([1.0, 0.0])


def lateral_offsets_m(points_xy: np.ndarray, axis_xy: np.ndarray) -> np.ndarray:
    """(N,) signed lateral offset (metres, + to the left) of points (N, 2) from the street's axis through the
    volume origin."""
    return np.asarray(points_xy, dtype=np.float64).reshape(-1, 2) @ np.array([-axis_xy[1], axis_xy[0]])


def street_extrusion(lat_obs_m: np.ndarray, z_obs: np.ndarray, values_obs: np.ndarray, lat_q_m: np.ndarray,
                     z_q: np.ndarray, half_width_q_m: np.ndarray, fallback_q: np.ndarray, prior_weight: float,
                     n_z: int, bin_m: float = 0.25) -> np.ndarray:
    """The street extruded along its axis: per query, ``(sum of the observations in its cell + k fallback) /
    (their number + k)``, (Q, C); a query's cell is its height bin and the lateral offsets within its
    half width (a voxel's centre can sit up to about its size off the surface it stands for).

    Args:
        lat_obs_m, z_obs: (N,) lateral offsets (metres) and int height bins in ``[0, n_z)`` of the observations.
        values_obs: (N, C) observed values (build_volume: linear radiance and the shading model's, side by side).
        lat_q_m, z_q, half_width_q_m: (Q,) the queries' lateral offsets, height bins and half widths (metres).
        fallback_q: (Q, C) the queries' prior prediction (the shading model).
        prior_weight: k, the fallback's weight in observations.
        bin_m: resolution of the lateral offsets.
    """
    v = np.asarray(values_obs, dtype=np.float64).reshape(len(lat_obs_m), -1)
    lat_obs, lat_q = np.asarray(lat_obs_m, np.float64), np.asarray(lat_q_m, np.float64)
    hw = np.asarray(half_width_q_m, np.float64)
    lo_m = min(lat_obs.min(initial=0.0), (lat_q - hw).min(initial=0.0)) - bin_m
    hi_m = max(lat_obs.max(initial=0.0), (lat_q + hw).max(initial=0.0)) + bin_m
    n_lat = int(np.ceil((hi_m - lo_m) / bin_m)) + 1
    bin_obs = np.floor((lat_obs - lo_m) / bin_m).astype(np.int64)
    cell = bin_obs * n_z + np.asarray(z_obs, dtype=np.int64)
    count = np.bincount(cell, minlength=n_lat * n_z).astype(np.float64).reshape(n_lat, n_z, 1)
    sums = np.stack([np.bincount(cell, v[:, c], minlength=n_lat * n_z) for c in range(v.shape[1])],
                    axis=1).reshape(n_lat, n_z, -1)
    # prefix sums over the lateral bins: any window in O(1)
    cum = np.concatenate([np.zeros((1, n_z, v.shape[1] + 1)), np.cumsum(np.concatenate([count, sums], -1), 0)], 0)
    lo = np.clip(np.floor((lat_q - hw - lo_m) / bin_m).astype(np.int64), 0, n_lat - 1)
    hi = np.clip(np.floor((lat_q + hw - lo_m) / bin_m).astype(np.int64), 0, n_lat - 1)
    zq = np.asarray(z_q, dtype=np.int64)
    win = cum[hi + 1, zq] - cum[lo, zq]  # (Q, 1 + C)
    fb = np.asarray(fallback_q, dtype=np.float64).reshape(len(lat_q), v.shape[1])
    return (win[:, 1:] + prior_weight * fb) / (win[:, 0] + prior_weight)[:, None]


UNSEEN_KEEP = 0.25  # what no camera saw: this much of the model's log-radiance, the rest the seen mean colour
# (fitted by benchmarks/fit_unseen_prior.py on the dev scene's even keyframes; see there)


def mean_colour_radiance(radiance: np.ndarray) -> np.ndarray:
    """(3,) the linear radiance the contract's response records as the mean colour of radiance samples (N, 3):
    the best constant guess of a view of them (the mean *linear* radiance overweights the bright ones)."""
    return mean_colour_of_ldr([clipped_ldr(radiance)])


def clipped_ldr(radiance: np.ndarray) -> np.ndarray:
    """(N, 3) float64 the contract's LDR of radiance samples (N, 3), clipped to [0, 1] (what
    :func:`mean_colour_radiance` averages; an array's LDR once for several means)."""
    return np.clip(hdr_to_ldr(np.asarray(radiance, dtype=np.float64).reshape(-1, 3)), 0.0, 1.0)


def mean_colour_of_ldr(parts: list[np.ndarray]) -> np.ndarray:
    """(3,) :func:`mean_colour_radiance` of the samples whose :func:`clipped_ldr` are ``parts`` (each (N_i, 3)),
    all together: the same numbers as of their radiance concatenated."""
    ldr = np.concatenate(parts) if parts else np.zeros((0, 3))
    if not len(ldr):
        return np.zeros(3)
    return np.maximum(ldr_to_hdr(ldr.mean(axis=0)), 1e-9)


def shrink_unseen(radiance: np.ndarray, anchor_rgb: np.ndarray, keep: float = UNSEEN_KEEP) -> np.ndarray:
    """Radiance (..., 3) of unseen directions or surfaces shrunk towards ``anchor_rgb`` (3,) in log space:
    ``exp(keep log L + (1 - keep) log anchor)``: a model's guess of what no camera saw is uncertain, and the seen
    mean colour is the guess with the least expected error; ``keep`` = 1 leaves the model as is."""
    rad = np.maximum(np.asarray(radiance, dtype=np.float64), 1e-12)
    anchor = np.maximum(np.asarray(anchor_rgb, dtype=np.float64), 1e-12)
    return np.exp(keep * np.log(rad) + (1.0 - keep) * np.log(anchor))
