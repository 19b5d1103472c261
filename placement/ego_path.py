"""The ego's path through a scene as a lane reference: arc length, lateral offset, smooth heading; traffic side.

Where the map has no lanes (or to follow the road the ego drives on), inserted moving objects follow the
ego's own path shifted sideways by a lane offset. Conventions: global x/y in metres; arc length ``s`` along
the path from its first vertex; lateral offset ``d`` positive to the LEFT of the direction of travel; the
path continues straight beyond both ends (its end tangents).

The path is a cubic spline through the ego's positions: an object following it turns gradually, moves where
it points, and its velocity is smooth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from streetaug.augment.core import InputError

# Locations whose traffic keeps left (all nuScenes Singapore maps); Boston keeps right.
LEFT_HAND_PREFIXES = ("singapore",)
RIGHT_HAND_PREFIXES = ("boston",)


def traffic_side(location: str) -> str | None:
    """``"left"`` or ``"right"``: the side of the road traffic keeps to at ``location``; None when unknown."""
    loc = location.lower()
    if loc.startswith(LEFT_HAND_PREFIXES):
        return "left"
    if loc.startswith(RIGHT_HAND_PREFIXES):
        return "right"
    return None


@dataclass(frozen=True)
class PathCoords:
    """Query points located on a path: arc length ``s`` (N,), left offset ``d`` (N,), path heading (N,) rad."""

    s: np.ndarray
    d: np.ndarray
    heading_rad: np.ndarray


@dataclass(frozen=True)
class EgoPath:
    """A smooth path in global x/y: a cubic spline through the given points, parameterised by chord length.

    Position and heading come from the same curve (heading = direction of its derivative), so an object
    following it moves where it points, and its velocity is smooth. Beyond both ends the path continues
    straight along its end tangents.

    Attributes:
        spline: scipy ``CubicSpline`` s -> (x, y) on [0, length_m] ("not-a-knot" ends).
        length_m: chord length of the points (the parameter range; ~ the arc length).
        dense_s: (M,) parameters of a dense sampling (every ~0.25 m) used by :meth:`locate`.
        dense_xy: (M, 2) the curve at ``dense_s``.
    """

    spline: CubicSpline
    length_m: float
    dense_s: np.ndarray
    dense_xy: np.ndarray

    @classmethod
    def from_points(cls, xy: np.ndarray, min_step_m: float = 0.05) -> "EgoPath":
        """The path through ``xy`` (N, 2) in order; points closer than ``min_step_m`` to the last kept are dropped.

        Raises:
            InputError: fewer than two distinct points (a standing ego gives no direction).
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        kept = [xy[0]] if len(xy) else []
        for p in xy[1:]:
            if np.linalg.norm(p - kept[-1]) >= min_step_m:
                kept.append(p)
        if len(kept) < 2:
            raise InputError("ego path: the ego does not move in this scene (fewer than two distinct positions); "
                             "no direction of travel to follow")
        v = np.array(kept)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))])
        spline = CubicSpline(s, v, axis=0, bc_type="not-a-knot" if len(v) > 3 else "natural")
        dense_s = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / 0.25)) + 1, 2))
        return cls(spline, float(s[-1]), dense_s, spline(dense_s))

    def _tangent(self, s: np.ndarray) -> np.ndarray:
        t = self.spline(np.clip(s, 0.0, self.length_m), 1)
        return t / np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)

    def heading_at(self, s: np.ndarray) -> np.ndarray:
        """(N,) heading (rad) of the path at parameters ``s`` (N,) (end tangents beyond the ends)."""
        t = self._tangent(np.asarray(s, dtype=np.float64))
        return np.arctan2(t[..., 1], t[..., 0])

    def curvature_at(self, s: np.ndarray) -> np.ndarray:
        """(N,) signed curvature (1/m, + = turning left) at ``s`` (N,); 0 beyond the ends."""
        s = np.asarray(s, dtype=np.float64)
        inside = (s >= 0) & (s <= self.length_m)
        c = np.clip(s, 0.0, self.length_m)
        d1, d2 = self.spline(c, 1), self.spline(c, 2)
        k = (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]) / np.maximum(np.linalg.norm(d1, axis=-1) ** 3, 1e-12)
        return np.where(inside, k, 0.0)

    def centre_at(self, s: np.ndarray) -> np.ndarray:
        """(N, 2) points of the path at ``s`` (N,), continued straight beyond the ends."""
        s = np.asarray(s, dtype=np.float64)
        c = np.clip(s, 0.0, self.length_m)
        return self.spline(c) + (s - c)[..., None] * self._tangent(c)

    def point_at(self, s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points at parameter ``s`` and left offset ``d`` (broadcast arrays): (xy (..., 2), heading (...))."""
        s, d = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(d, dtype=np.float64))
        shape = s.shape
        s, d = s.ravel(), d.ravel()
        t = self._tangent(s)
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
        xy = self.centre_at(s) + d[:, None] * normal
        return xy.reshape(*shape, 2), np.arctan2(t[:, 1], t[:, 0]).reshape(shape)

    def locate(self, xy: np.ndarray) -> PathCoords:
        """The nearest point of the path (its straight continuations included) to each of ``xy`` (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a, b = self.dense_xy[:-1], self.dense_xy[1:]
        ab = b - a
        L2 = np.maximum(np.einsum("kd,kd->k", ab, ab), 1e-12)
        f = np.einsum("nkd,kd->nk", xy[:, None] - a[None], ab) / L2[None]
        lo, hi = np.zeros(len(ab)), np.ones(len(ab))
        lo[0], hi[-1] = -np.inf, np.inf  # the ends continue straight
        f = np.clip(f, lo[None], hi[None])
        dist = np.linalg.norm(xy[:, None] - (a[None] + f[..., None] * ab[None]), axis=2)
        k = np.argmin(dist, axis=1)
        n = np.arange(len(xy))
        s = self.dense_s[k] + f[n, k] * (self.dense_s[k + 1] - self.dense_s[k])
        t = self._tangent(s)
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
        d = np.einsum("nd,nd->n", xy - self.centre_at(s), normal)
        return PathCoords(s, d, np.arctan2(t[:, 1], t[:, 0]))


__all__ = ["EgoPath", "LEFT_HAND_PREFIXES", "PathCoords", "RIGHT_HAND_PREFIXES", "traffic_side"]
