"""Small scenes for renderer tests and benchmarks: a primitive car, spheres, lights, a ground-plane image."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import trimesh

from streetaug.augment.assets.asset import Asset, Material
from streetaug.augment.core import (
    PinholeCamera,
    camera_dir_to_lonlat,
    camera_envmap_directions,
    hdr_to_ldr_uint8,
    luminance,
    sample_equirect,
)
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.lighting.light import DistantLight, SunLight
from streetaug.augment.render.sampling import hemisphere_irradiance

SHARED_DATA = (Path(__file__).parents[1] / ".." / "shared" / "data").resolve()
NUSCENES_K = np.array([[1266.4, 0.0, 816.3], [0.0, 1266.4, 491.5], [0.0, 0.0, 1.0]])


def _flat(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unshared vertices with flat normals: (V, 3), (F, 3), (V, 3)."""
    V = mesh.vertices[mesh.faces].reshape(-1, 3)
    F = np.arange(len(V)).reshape(-1, 3)
    N = np.repeat(mesh.face_normals, 3, axis=0)
    return V, F, N


def primitive_car(paint=(0.6, 0.05, 0.04)) -> Asset:
    """A boxy car (4.4 x 1.8 x 1.5 m): painted body, glass cabin, rubber tyres. Object frame, origin bottom centre."""
    parts = []
    body = trimesh.creation.box(extents=[4.4, 1.8, 0.75])
    body.apply_translation([0, 0, 0.3 + 0.375])
    parts.append((body, 0, False))
    cabin = trimesh.creation.box(extents=[2.3, 1.6, 0.5])
    cabin.apply_translation([-0.3, 0, 1.05 + 0.25])
    parts.append((cabin, 1, False))
    for x in (-1.4, 1.4):
        for y in (-0.8, 0.8):
            wheel = trimesh.creation.cylinder(radius=0.33, height=0.24, sections=24)
            wheel.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
            wheel.apply_translation([x, y, 0.33])
            parts.append((wheel, 2, True))
    Vs, Fs, Ns, Ms = [], [], [], []
    off = 0
    for mesh, mat, smooth in parts:
        if smooth:
            V, F, N = mesh.vertices, mesh.faces, mesh.vertex_normals
        else:
            V, F, N = _flat(mesh)
        Vs.append(V)
        Fs.append(F + off)
        Ns.append(N)
        Ms.append(np.full(len(F), mat))
        off += len(V)
    V = np.concatenate(Vs)
    V[:, 2] -= V[:, 2].min()
    mats = (
        Material("paint", np.array(paint), metallic=0.0, roughness=0.35, specular=0.5, clearcoat=1.0),
        Material("glass", np.array([0.05, 0.06, 0.07]), roughness=0.05, specular=0.5, opacity=0.25),
        Material("tyre", np.array([0.03, 0.03, 0.03]), roughness=0.85, specular=0.3),
    )
    return Asset("primitive_car", V, np.concatenate(Fs), np.concatenate(Ms), mats, np.concatenate(Ns))


def sphere_asset(radius: float = 1.0, material: Material | None = None, subdivisions: int = 4) -> Asset:
    """An icosphere resting on z = 0 with smooth normals."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    n = m.vertices / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    V = m.vertices + [0, 0, radius]
    mat = material or Material("white", np.ones(3), roughness=1.0, specular=0.0)
    return Asset("sphere", V, m.faces, np.zeros(len(m.faces), np.int64), (mat,), n)


def sunny_light(sun_dir_cam=(0.5, -0.6, 0.62), sun_irradiance=8.0, sky=(0.25, 0.35, 0.55), ground=0.12,
                height: int = 64, width: int = 128) -> DistantLight:
    """Analytic sky (blue-ish above the horizon, grey ground below) plus a sun, camera frame."""
    d = camera_envmap_directions(height, width)
    up = -d[..., 1]
    sky_rgb = np.asarray(sky)[None, None] * (0.6 + 0.4 * (1 - np.clip(up, 0, 1)))[..., None]
    env = np.where(up[..., None] > 0, sky_rgb, ground).astype(np.float32)
    s = np.asarray(sun_dir_cam, dtype=np.float64)
    sun = SunLight(direction=s / np.linalg.norm(s), irradiance_rgb=np.array([1.0, 0.95, 0.85]) * sun_irradiance,
                   half_angle_rad=np.radians(0.5))
    return DistantLight(env, sun)


def two_level_sky(up: np.ndarray, above: float, below: float, height: int = 32, width: int = 64) -> np.ndarray:
    """(height, width, 3) float32 camera-frame env map: grey radiance ``above`` the horizon of ``up``, ``below`` under it."""
    d = camera_envmap_directions(height, width)
    return np.where((d @ np.asarray(up) > 0)[..., None], above, below).astype(np.float32) * np.ones(3, np.float32)


def plane_shadow(camera: PinholeCamera, asset: Asset, T_cam_from_object: np.ndarray, up: np.ndarray,
                 light: DistantLight, depth_m: np.ndarray, settings=None, seed: int = 0):
    """The renderer's shadow of ``asset`` on the scene ``depth_m`` (its footprint's shadow box, the bounce light
    of the asset): (box, ShadowMap)."""
    from streetaug.augment.render import RenderSettings, footprint, prepare_asset
    from streetaug.augment.render.bounce import BounceLight
    from streetaug.augment.render.shadow import render_shadow

    settings = settings or RenderSettings()
    prep = prepare_asset(asset)
    box = footprint(camera, asset, T_cam_from_object, light, settings).shadow_box
    sh = render_shadow(camera, box, depth_m, light, prep, T_cam_from_object, up, settings,
                       np.random.default_rng(seed), BounceLight.build(light, prep, T_cam_from_object, up))
    return box, sh


def read_hdri_light(name: str, height: int = 128, width: int = 256) -> DistantLight:
    """A camera-frame DistantLight from ``shared/data/hdri/<name>.hdr`` (camera looking horizontally).

    The panoramas use azimuth = 360 u / W - 180 and elevation = 90 - 180 v / H, which is the camera
    equirect convention's (lon, lat) for a level camera, so only resampling is needed.
    """
    bgr = cv2.imread(str(SHARED_DATA / "hdri" / f"{name}.hdr"), cv2.IMREAD_UNCHANGED)
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    rgb = cv2.resize(rgb, (width, height), interpolation=cv2.INTER_AREA)
    return DistantLight.from_envmap(np.maximum(rgb, 0.0))


def ground_scene(light: DistantLight, K=NUSCENES_K, width: int = 1600, height: int = 900, cam_height_m: float = 1.5,
                 albedo: float = 0.25, ev: float | None = None):
    """A Lambertian ground plane under ``light`` seen by a level camera; sky where there is no ground.

    Returns (image uint8 (H, W, 3), depth_m (H, W), ev): ``ev`` puts the ground at about 0.45 LDR.
    """
    n = np.array([0.0, -1.0, 0.0])
    depth = ground_plane_depth(K, width, height, n, cam_height_m)
    E = hemisphere_irradiance(light.envmap, n)
    if light.sun is not None:
        E = E + np.asarray(light.sun.irradiance_rgb) * max(float(light.sun.direction @ n), 0.0)
    ground_rgb = albedo * E / np.pi
    if ev is None:
        ev = float(np.log2(0.45**2.2 / luminance(ground_rgb)))
    dirs = PinholeCamera(K, width, height).rays()
    sky = sample_equirect(light.envmap, *camera_dir_to_lonlat(dirs))
    hdr = np.where(np.isfinite(depth)[..., None], ground_rgb[None, None], sky)
    return hdr_to_ldr_uint8(hdr, ev), depth, ev



# Car seeds and poses (x, y, z m in the camera frame, yaw deg) of small multi-car scenes;
# the third far off to the right (its shadow in the image at most).
CARS_ON_GROUND = ((4, (-2.0, 1.5, 10.0, 120.0)), (11, (3.0, 1.5, 16.0, 60.0)), (7, (40.0, 1.5, 8.0, 90.0)))


def cars_on_ground_scene(n_cars: int, width: int = 320, height: int = 180):
    """``n_cars`` (1-3) procedural cars on ``ground_scene`` under a sunny light, 60 deg horizontal FOV.

    Returns (image uint8 (H, W, 3), K, depth_m (H, W), lights, cars, T_cam_from_object poses, ev).
    """
    from streetaug.augment.assets.procedural import procedural_car
    from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform

    K = intrinsics_from_fov(width, height, 60.0)
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light, K, width, height)
    chosen = CARS_ON_GROUND[:n_cars]
    cars = [procedural_car(seed) for seed, _ in chosen]
    poses = [pose_camera_to_transform(*pose) for _, pose in chosen]
    return image, K, depth, [light] * n_cars, cars, poses, ev

def sharp_polygons(seed: int, width: int, height: int, n_polygons: int, radius_px: tuple[float, float],
                   ss: int = 8) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: random polygons with ideally pixel-integrated edges (no blur, no noise)."""
    rng = np.random.default_rng(seed)
    big = np.empty((height * ss, width * ss, 3), np.uint8)
    big[:] = rng.integers(60, 200, 3)
    for _ in range(n_polygons):
        n = int(rng.integers(3, 7))
        centre = rng.random(2) * [width * ss, height * ss]
        r = rng.uniform(*radius_px) * ss
        ang = np.sort(rng.random(n)) * 2 * np.pi
        pts = np.stack([centre[0] + r * np.cos(ang), centre[1] + r * np.sin(ang)], 1).astype(np.int32)
        cv2.fillPoly(big, [pts], rng.integers(0, 256, 3).tolist())
    return cv2.resize(big, (width, height), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def degrade(img: np.ndarray, blur: float, noise_levels: float, seed: int = 1) -> np.ndarray:
    """A [0, 1] image Gaussian-blurred by ``blur`` px with Gaussian noise of ``noise_levels`` / 255, as uint8."""
    out = cv2.GaussianBlur(img, (0, 0), blur) if blur > 0 else img
    out = out + np.random.default_rng(seed).normal(0, noise_levels / 255.0, out.shape).astype(np.float32)
    return np.clip(np.round(out * 255.0), 0, 255).astype(np.uint8)
