"""Files of ``streetaug predict-light``: lighting.json, envmap_camera.exr, preview.png (all atomic)."""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from ..core import (
    camera_dir_to_lonlat,
    camera_envmap_directions,
    check_shape,
    equirect_solid_angles,
    hdr_to_ldr_uint8,
    luminance,
    sample_equirect,
)
from ..core import write_exr, write_image_rgb, write_json_atomic
from .types import LightingEstimate

LIGHTING_SCHEMA = "streetaug.lighting/1"
DEFAULT_QUERY_POINT_CAM = (0.0, 1.5, 15.0)  # ground 15 m ahead of a camera 1.5 m above it
PREVIEW_HEIGHT = 192


def diffuse_sphere(env: np.ndarray, size: int, albedo: float = 0.8) -> np.ndarray:
    """Lambertian sphere (size, size, 3) radiance under an env map (H, W, 3), seen along +z (camera frame).

    Irradiance per normal = sum over a 16 x 32 downsampled map of L cos+ dOmega (vectorised).
    Pixels outside the sphere are 0.
    """
    small = cv2.resize(env.astype(np.float32), (32, 16), interpolation=cv2.INTER_AREA).astype(np.float64)
    d = camera_envmap_directions(16, 32).reshape(-1, 3)
    omega = equirect_solid_angles(16, 32).reshape(-1)
    # energy-consistent downsampling: preserve the integral of each channel
    full_int = (env.reshape(-1, 3) * equirect_solid_angles(*env.shape[:2]).reshape(-1, 1)).sum(axis=0)
    small_int = (small.reshape(-1, 3) * omega[:, None]).sum(axis=0)
    small = small.reshape(-1, 3) * np.where(small_int > 0, full_int / np.maximum(small_int, 1e-30), 0.0)
    normals, inside = _sphere_normals(size)
    cosw = np.maximum(normals.reshape(-1, 3) @ d.T, 0.0) * omega[None]
    irr = cosw @ small
    out = albedo / np.pi * irr
    return (out.reshape(size, size, 3) * inside[..., None]).astype(np.float32)


def mirror_sphere(env: np.ndarray, size: int) -> np.ndarray:
    """Mirror sphere (size, size, 3) radiance: reflection of the view ray (+z) about the normal."""
    normals, inside = _sphere_normals(size)
    view = np.array([0.0, 0.0, 1.0])  # ray from the camera into the scene
    n = normals.reshape(-1, 3)
    refl = view[None] - 2.0 * (n @ view)[:, None] * n
    lon, lat = camera_dir_to_lonlat(refl)
    out = sample_equirect(env, lon, lat).reshape(size, size, 3)
    return (out * inside[..., None]).astype(np.float32)


def _sphere_normals(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame normals (size, size, 3) of a sphere seen orthographically (x right, y down, facing -z)."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    r2 = x * x + y * y
    inside = r2 <= 1.0
    z = -np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
    n = np.stack([x, y, z], axis=-1)
    return n, inside


def make_preview(estimate: LightingEstimate, image_rgb: np.ndarray, env_full: np.ndarray,
                 env_no_sun: np.ndarray | None = None) -> np.ndarray:
    """uint8 (h, w, 3): input (downscaled) | env map (tone-mapped, contract response) | diffuse | mirror sphere.

    ``env_full`` (sun included) lights the diffuse sphere; the mirror sphere reflects ``env_no_sun`` (default:
    the estimate's distant environment) so that the sun's huge pixels do not bleed.
    """
    h = PREVIEW_HEIGHT
    H, W = image_rgb.shape[:2]
    img = cv2.resize(np.ascontiguousarray(image_rgb), (max(int(round(W * h / H)), 1), h), interpolation=cv2.INTER_AREA)
    env_small = cv2.resize(env_full, (2 * h, h), interpolation=cv2.INTER_AREA)
    # Tone map the map with the image's own response, but clip the sun's huge pixels.
    env_ldr = hdr_to_ldr_uint8(env_small)
    s = h // 2
    diffuse = hdr_to_ldr_uint8(diffuse_sphere(env_full, s, albedo=0.5))
    mirror = hdr_to_ldr_uint8(mirror_sphere(estimate.light_cam.envmap if env_no_sun is None else env_no_sun, s))
    spheres = np.zeros((h, s, 3), np.uint8)
    spheres[:s] = diffuse
    spheres[s : 2 * s] = mirror
    return np.concatenate([img, env_ldr, spheres], axis=1)


def write_lighting_outputs(
    estimate: LightingEstimate,
    out_dir: str | Path,
    image_rgb: np.ndarray,
    query_point_cam: tuple[float, float, float] | np.ndarray = DEFAULT_QUERY_POINT_CAM,
    envmap_height: int = 128,
    envmap_width: int = 256,
    extra_timing_s: dict | None = None,
    save_hybrid: bool = True,
) -> dict:
    """Write ``lighting.json``, ``envmap_camera.exr`` (sun included) and ``preview.png`` into ``out_dir``.

    The env map is the local light at ``query_point_cam`` (:meth:`LightingEstimate.light_at`: the same at every
    point for L0/L1; the volume + sky seen from the point, and the sun's transmittance from it, for L2/L3).
    With ``save_hybrid`` an L2/L3 estimate also writes its representation into ``out_dir/hybrid/``
    (``sky_world.exr``, ``volume.npz``, ``hybrid.json``). Returns the lighting.json content.
    """
    if envmap_height < 128 or envmap_width < 256:
        raise ValueError(f"envmap must be at least 128 x 256, got {envmap_height} x {envmap_width}")
    q = np.asarray(query_point_cam, dtype=np.float64)
    check_shape(q, (3,), "query_point_cam")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    local = estimate.light_at(q, envmap_height, envmap_width)
    env = local.to_envmap(envmap_height, envmap_width).astype(np.float32)
    t_local = time.perf_counter() - t0
    write_exr(out / "envmap_camera.exr", env)
    write_image_rgb(out / "preview.png", make_preview(estimate, np.asarray(image_rgb), env, local.envmap))
    sun = estimate.sun_dir_cam
    timing = dict(estimate.timing_s)
    timing["local_envmap"] = t_local
    if "total" in timing:
        timing["total"] = timing["total"] + t_local
    if extra_timing_s:
        timing.update(extra_timing_s)
    files = {"envmap_camera": "envmap_camera.exr", "preview": "preview.png"}
    hybrid = estimate.hybrid
    if save_hybrid and hybrid is not None and hybrid.params is not None:
        hybrid.save(out / "hybrid", extra={
            "T_vol_from_camera": np.asarray(estimate.T_vol_from_cam).tolist(),
            "radiometric_scale": float(estimate.radiometric_scale),
        })
        files["hybrid"] = "hybrid/hybrid.json"
    visibility = float(estimate.sun_visibility)
    transmittance = None
    if sun is not None and estimate.light_cam.sun is not None and local.sun is not None and estimate.light_cam.sun.visibility > 0:
        transmittance = float(local.sun.visibility / estimate.light_cam.sun.visibility)
        visibility = float(local.sun.visibility)
    doc = {
        "schema": LIGHTING_SCHEMA,
        "sun": {
            "direction_camera": None if sun is None else [float(x) for x in sun],
            "source": estimate.sun_source,
            "visibility": visibility,
            "cloud_visibility": float(estimate.sun_visibility),
            "transmittance_at_query": transmittance,
        },
        "query_point_camera": [float(x) for x in q],
        "files": files,
        "level": estimate.level,
        "reason": estimate.reason,
        "params": estimate.params,
        "timing_s": timing,
        "envmap_mean_luminance": float(luminance(env).mean()),
    }
    write_json_atomic(out / "lighting.json", doc)
    return doc
