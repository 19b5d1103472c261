"""Radiance the inserted object sends back along the rays it blocks: one bounce, approximated.

When a ray from the ground (shadow ratio map) or from the object itself (self-occlusion) hits the
object, it no longer sees the sky but the object's surface there.  That surface's radiance towards
the ray's origin is approximated as a diffuse-like reflection of the light it receives::

    L_hit = rho / pi x [ E_env(n) - t (1 - S_foot) E_low(n) + E_sun max(0, n.s) V_sun ] + emission

* ``rho``: the material's directional albedo (diffuse colour + the GGX lobe's albedo from
  :func:`streetaug.augment.render.brdf.specular_albedo`, at ``n.v = 0.6``; metallic flakes keep the diffuse
  colour's albedo, :func:`streetaug.augment.render.brdf.flake_lobe`), textures included.
* ``E_env(n)``: irradiance from the unoccluded environment (sky above, ground radiance below).
* The ground a downward-facing surface sees is the object's own shadow, not the unshadowed ground
  of the environment map: with ``t = max(0, -n.up)`` the ground part ``E_low(n) = pi L_g (1 - n.up) / 2``
  (uniform ground radiance ``L_g``) is scaled by ``S_foot``, the mean shadow ratio under the object.
  ``S_foot`` is only known after the shadow pass, so the radiance is returned as ``A + B S_foot``.
* ``V_sun``: the visible fraction of four points of the face, towards the sun's centre.
* All of it is evaluated once per face (at its centroid) and looked up per ray: a second bounce does
  not need per-pixel precision, and this keeps its cost independent of the number of rays.
* Back faces (the inside of a mesh that is open, e.g. a hollow tyre) send nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..core import camera_envmap_directions, equirect_solid_angles
from ..lighting.light import DistantLight
from .brdf import specular_albedo, to_world
from .surface import PreparedAsset, surface_at_hits
from .environment import EnvironmentTables, environment_tables
from .sampling import lookup_irradiance

RAY_EPS_M = 1e-3
VIEW_COS = 0.6  # n.v at which the faces' directional albedo is taken
VISIBILITY_RAYS = 12


def _cosine_spiral(n: int) -> np.ndarray:
    """n cosine-distributed directions (n, 3) on the z-up hemisphere (equal-weight Fibonacci spiral)."""
    k = np.arange(n) + 0.5
    r = np.sqrt(k / n)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)


VISIBILITY_LOCAL = _cosine_spiral(VISIBILITY_RAYS)
SUN_POINTS = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3], [1 / 3, 1 / 3, 1 / 3]])


def ground_radiance_below(env: EnvironmentTables, up_cam: np.ndarray) -> np.ndarray:
    """Mean radiance (3,) of the map below the horizon of ``up_cam`` (solid-angle weighted): the ground's.

    Computed on a reduced copy of the map (at most 128 wide, from its pyramid).
    """
    levels = env.pyramid
    envmap = next((lev for lev in levels if lev.shape[1] <= 128), levels[-1])
    H, W = envmap.shape[:2]
    below = camera_envmap_directions(H, W) @ np.asarray(up_cam, dtype=np.float64) < 0
    w = equirect_solid_angles(H, W) * below
    if w.sum() <= 0:
        return np.zeros(3)
    return np.einsum("hw,hwc->c", w, np.asarray(envmap, dtype=np.float64)) / w.sum()


@dataclass(frozen=True)
class BounceLight:
    """What the object's surfaces receive and send back, per face, in the object frame.

    The radiance is evaluated once per face (at its centroid, sun visibility averaged over
    :data:`SUN_POINTS` points of the face, viewed at ``n.v = VIEW_COS``), the first time a ray hits
    that face, and looked up per ray.  Not thread-safe (the tables fill in place).

    Attributes:
        light: the camera-frame distant light.
        env: the tables of its env map (irradiance, pyramid).
        prep: the prepared object.
        R_cam_from_obj: (3, 3) rotation object -> camera.
        up_obj: (3,) unit ground normal (up), object frame.
        ground_rgb: (3,) radiance of the unshadowed ground (the map below the horizon).
    """

    light: DistantLight
    env: EnvironmentTables
    prep: PreparedAsset
    R_cam_from_obj: np.ndarray
    up_obj: np.ndarray
    ground_rgb: np.ndarray

    @staticmethod
    def build(light: DistantLight, prep: PreparedAsset, T_cam_from_object: np.ndarray, up_cam: np.ndarray) -> "BounceLight":
        R = np.asarray(T_cam_from_object, dtype=np.float64)[:3, :3]
        up = np.asarray(up_cam, dtype=np.float64)
        up = up / np.linalg.norm(up)
        env = environment_tables(light.envmap)
        return BounceLight(light, env, prep, R, R.T @ up, ground_radiance_below(env, up))

    @cached_property
    def _tables(self) -> dict[str, np.ndarray]:
        """Per-face values filled on demand (NaN = not computed yet): only the faces rays actually hit."""
        F = len(self.prep.faces)
        return {"A": np.full((F, 3), np.nan), "B": np.full((F, 3), np.nan), "V": np.full(F, np.nan)}

    def _needed(self, key: str, face: np.ndarray) -> np.ndarray:
        first = self._tables[key].reshape(len(self.prep.faces), -1)[:, 0]
        return np.unique(face[np.isnan(first[face])])  # the faces not computed yet, each once

    def face_radiance(self, face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, B), each (N, 3): outgoing radiance ``A + B S_foot`` of the outer side of faces ``face`` (N,)."""
        todo = self._needed("A", face)
        if len(todo):
            self._tables["A"][todo], self._tables["B"][todo] = self._compute_radiance(todo)
        return self._tables["A"][face], self._tables["B"][face]

    def _compute_radiance(self, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        prep = self.prep
        F = len(faces)
        n_g = prep.face_normal[faces]
        surface = surface_at_hits(prep, faces, np.full((F, 2), 1.0 / 3.0), -n_g)
        n_s, params, emission = surface.normal, surface.params, surface.emission
        albedo = params.c_diff + specular_albedo(np.full(F, VIEW_COS), params)
        E = lookup_irradiance(self.env.irradiance, n_s @ self.R_cam_from_obj.T)
        n_up = n_s @ self.up_obj
        t = np.clip(-n_up, 0.0, 1.0)
        E_low = np.pi * self.ground_rgb[None] * ((1.0 - n_up) / 2.0)[:, None]
        E_sun = np.zeros((F, 3))
        sun = self.light.sun
        if sun is not None:
            s_obj = self.R_cam_from_obj.T @ np.asarray(sun.direction, dtype=np.float64)
            cos = np.clip(n_s @ s_obj, 0.0, None) * (n_g @ s_obj > 0)
            lit = np.flatnonzero(cos > 0)
            if len(lit):
                tri = prep.asset.vertices[prep.faces[faces[lit]]]  # (L, 3, 3)
                pts = np.einsum("kj,ljc->lkc", SUN_POINTS, tri).reshape(-1, 3)
                org = pts + RAY_EPS_M * np.repeat(n_g[lit], len(SUN_POINTS), axis=0)
                vis = ~prep.scene.occluded(org, np.broadcast_to(s_obj, org.shape))
                vis = vis.reshape(len(lit), len(SUN_POINTS)).mean(axis=1)
                E_sun[lit] = (cos[lit] * vis)[:, None] * np.asarray(sun.irradiance_rgb, dtype=np.float64)[None]
        k = albedo / np.pi
        return k * np.maximum(E - t[:, None] * E_low + E_sun, 0.0) + emission, k * t[:, None] * E_low

    def face_sky_visibility(self, face: np.ndarray) -> np.ndarray:
        """(N,) cosine-weighted fraction of the outer hemisphere of faces ``face`` the object leaves open.

        :data:`VISIBILITY_RAYS` rays per face from its centroid (a cosine-distributed Fibonacci spiral,
        rotated per face).  The foreground shader scales its control variates by it.
        """
        todo = self._needed("V", face)
        if len(todo):
            prep = self.prep
            F, n = len(todo), len(VISIBILITY_LOCAL)
            phi = np.mod(todo * 0.6180339887498949, 1.0) * 2 * np.pi  # per-face rotation, order-independent
            c, s_ = np.cos(phi)[:, None], np.sin(phi)[:, None]
            lx = c * VISIBILITY_LOCAL[None, :, 0] - s_ * VISIBILITY_LOCAL[None, :, 1]
            ly = s_ * VISIBILITY_LOCAL[None, :, 0] + c * VISIBILITY_LOCAL[None, :, 1]
            local = np.stack([lx, ly, np.broadcast_to(VISIBILITY_LOCAL[None, :, 2], lx.shape)], axis=2).reshape(-1, 3)
            normal = prep.face_normal[todo]
            dirs = to_world(local, np.repeat(normal, n, axis=0))
            centroid = prep.asset.vertices[prep.faces[todo]].mean(axis=1)
            org = np.repeat(centroid + RAY_EPS_M * normal, n, axis=0)
            self._tables["V"][todo] = 1.0 - prep.scene.occluded(org, dirs).reshape(F, n).mean(axis=1)
        return self._tables["V"][face]

    def radiance(self, face: np.ndarray, dirs_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, B), each (N, 3): radiance ``A + B S_foot`` leaving hits on faces ``face`` (N,) back along
        the rays (unit directions (N, 3), object frame).  Back faces (the inside of an open mesh) send 0."""
        A, B = self.face_radiance(face)
        front = (np.einsum("ij,ij->i", dirs_obj, self.prep.face_normal[face]) < 0)[:, None]
        return np.where(front, A, 0.0), np.where(front, B, 0.0)
