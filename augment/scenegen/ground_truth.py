"""Reading the ground-truth lighting of the generated sample scenes back, for accuracy tests.

``ground_truth/<scene>/lighting.json`` (written by :mod:`.make`) holds the sun and sky parameters the
images were rendered with and the exposure k; :func:`ground_truth_light` rebuilds the exact distant
light (analytic sky + sun) in a camera's frame on the image's radiometric scale, comparable with
``streetaug predict-light``'s ``envmap_camera.exr`` (sky dome only: below the horizon it is the sky
model's uniform ground, not the street's buildings).  :class:`GroundTruthScene` regenerates a scene's
street in-process and traces the true *local* light at any point (buildings, their shadows and the
sky as seen from there), for accuracy measurements of spatially varying lighting and of insertions.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from streetaug.augment.core import camera_envmap_directions, make_transform, transform_points, yaw_to_quat
from streetaug.augment.core import InputError, read_json
from streetaug.augment.lighting.light import DistantLight, SunLight
from streetaug.augment.lighting.sky import make_sky_light
from streetaug.augment.lighting.sun import sun_direction_global
from streetaug.datasets.sample import CameraView

from .make import SAMPLE_SCENES
from .patterns import surface_albedo
from .render import SkyParams, StreetRenderer
from .street import StreetParams, build_street


def read_ground_truth(dataroot: str | Path, scene_name: str) -> dict:
    """The parsed ``lighting.json`` of a generated scene."""
    path = Path(dataroot) / "ground_truth" / scene_name / "lighting.json"
    gt = read_json(path)
    if gt.get("schema") != "streetaug.sample_lighting/1":
        raise InputError(f"{path}: field 'schema' is {gt.get('schema')!r}, expected 'streetaug.sample_lighting/1'")
    return gt


def ground_truth_light(dataroot: str | Path, scene_name: str, channel: str = "CAM_FRONT",
                       height: int = 128, width: int = 256) -> DistantLight:
    """Distant light (camera-frame equirect envmap (height, width, 3) + sun) of ``channel`` in a generated scene,
    on the image's radiometric scale (x exposure k)."""
    gt = read_ground_truth(dataroot, scene_name)
    cams = gt["cameras"]
    if channel not in cams:
        raise InputError(f"ground truth of {scene_name}: no camera {channel!r}; have {sorted(cams)}")
    sky = gt["sky"]
    light = make_sky_light(
        np.array(cams[channel]["sun_direction_camera"]), np.array(cams[channel]["up_direction_camera"]),
        turbidity=sky["turbidity"], cloud_cover=sky["cloud_cover"], ground_albedo=sky["ground_albedo"],
        height=height, width=width, scale=gt["exposure_k"],
    )
    if light.sun is not None:
        light = replace(light, sun=replace(light.sun, half_angle_rad=float(np.radians(gt["sun"]["half_angle_deg"]))))
    return light


class GroundTruthScene:
    """A bundled scene regenerated in-process: the true local light anywhere (camera frame, image scale)."""

    def __init__(self, dataroot: str | Path, name: str, seed: int = 0) -> None:
        spec = SAMPLE_SCENES[name]
        self.gt = read_ground_truth(dataroot, name)
        self.k = float(self.gt["exposure_k"])
        T_global_from_street = make_transform(yaw_to_quat(np.radians(spec.heading_deg)), [*spec.origin_xy, 0.0])
        self.scene = build_street(StreetParams(seed=seed * 7919 + spec.street_seed, drive_on_left=spec.drive_on_left),
                                  T_global_from_street)
        sun = sun_direction_global(spec.location, spec.timestamp_us)
        self.sky = SkyParams(sun.direction_global, spec.turbidity, spec.cloud_cover, 0.15,
                             float(np.radians(spec.sun_half_angle_deg)))
        self.renderer = StreetRenderer(self.scene, self.sky)
        self.name = name

    def sun_visibility(self, points_global: np.ndarray, n_rays: int = 16) -> np.ndarray:
        """(N,) fraction of the sun's disc visible from points (N, 3) (0 without a sun)."""
        r = self.renderer
        if not np.any(r.sun_e > 0):
            return np.zeros(len(points_global))
        rng = np.random.default_rng(0)
        n = np.tile(r.sun_dir, (len(points_global), 1))
        samples = [(rng.uniform(size=len(n)), rng.uniform(size=len(n))) for _ in range(n_rays)]
        return r.sun_visibility_at(points_global, n, rng, samples)

    def radiance(self, origins_global: np.ndarray, dirs_global: np.ndarray, sky_rays: int = 8,
                 seed: int = 1) -> np.ndarray:
        """True radiance (N, 3) along rays (global frame, unit directions) on the image's radiometric scale.

        Rays that escape see the sky model (sun disc excluded); rays that hit the street see its Lambertian
        shading: albedo / pi x (sun with shadow rays + sky gathered over ``sky_rays`` cosine rays)."""
        r = self.renderer
        rng = np.random.default_rng(seed)
        hits = r.rays.intersect(origins_global, dirs_global)
        L = np.zeros((len(dirs_global), 3))
        miss = ~hits.hit
        L[miss] = self.sky.radiance(dirs_global[miss])
        hi = np.nonzero(hits.hit)[0]
        if len(hi):
            q = r.rays.hit_points(hits)[hi]
            face = hits.face[hi]
            nq = r.oriented_normals(face, dirs_global[hi])
            T_street = r.T_street_from_global
            albedo, _ = surface_albedo(self.scene.materials, self.scene.face_material[face],
                                       transform_points(T_street, q), nq @ T_street[:3, :3].T)
            vis = r.sun_visibility_at(q, nq, rng, [(rng.uniform(size=len(hi)), rng.uniform(size=len(hi)))
                                                 for _ in range(4)])
            e = r.sun_e[None] * vis[:, None]
            samples = [(rng.uniform(size=len(hi)), rng.uniform(size=len(hi))) for _ in range(sky_rays)]
            e = e + r.sky_gather(q, nq, samples, rng)
            L[hi] = albedo / np.pi * e
        return L * self.k

    def local_light(self, point_global: np.ndarray, T_cam_from_global: np.ndarray, h: int = 64, w: int = 128,
                    sky_rays: int = 8) -> DistantLight:
        """True local light at a point: env map (h, w, 3) camera-frame convention (sun excluded) + visible sun."""
        r = self.renderer
        d = camera_envmap_directions(h, w).reshape(-1, 3) @ T_cam_from_global[:3, :3]
        env = self.radiance(np.tile(point_global, (len(d), 1)), d, sky_rays).reshape(h, w, 3).astype(np.float32)
        sun = None
        if np.any(r.sun_e > 0):
            v = float(self.sun_visibility(point_global[None])[0])
            sun = SunLight(T_cam_from_global[:3, :3] @ r.sun_dir, r.sun_e * self.k * v,
                           self.sky.sun_half_angle_rad, v * self.sky.sun_visibility)
        return DistantLight(env, sun)

    def test_points(self, view: CameraView, n_each: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points (M, 3) 0.5 m above the road 8-40 m ahead, ``n_each`` lit and shadowed; their visibility."""
        T_gc = view.T_global_from_cam
        xs, zs = np.meshgrid(np.linspace(-6, 6, 13), np.linspace(8, 40, 17))
        cam_h = T_gc[2, 3] - view.T_global_from_ego[2, 3]
        p_cam = np.stack([xs.ravel(), np.full(xs.size, cam_h - 0.5), zs.ravel()], axis=1)
        p_glob = transform_points(T_gc, p_cam)
        vis = self.sun_visibility(p_glob)
        lit, shade = np.flatnonzero(vis > 0.99), np.flatnonzero(vis < 0.01)
        pick = []
        for group in (lit, shade):
            if len(group):
                idx = np.linspace(0, len(group) - 1, min(n_each, len(group))).round().astype(int)
                pick += list(group[idx])
        if not pick:
            pick = list(np.linspace(0, len(p_cam) - 1, 2 * n_each).round().astype(int))
        return p_cam[pick], vis[pick]
