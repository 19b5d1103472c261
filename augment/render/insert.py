"""Insert one object into one image: foreground render, shadow ratio map, depth test, composite.

This is the renderer's single entry point::

    prepare (cached BVH) -> render_shadow -> render_foreground (sees the shadow) -> depth_visibility
      -> [match the image's blur and noise] -> composite
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..assets.asset import Asset
from ..core import check_shape
from ..core import InputError
from ..lighting.light import DistantLight
from .camera_effects import add_object_noise, blur_object_layer, estimate_camera_effects
from .composite import composite, depth_visibility
from .geometry import prepare_asset
from .sampling import sky_irradiance
from .settings import QUALITY_PRESETS, RenderSettings, resolve_settings
from .shade import render_foreground
from .bounce import BounceLight
from .shadow import GroundShadow, car_ambient_radiance, render_shadow

__all__ = ["QUALITY_PRESETS", "RenderSettings", "Insertion", "render_insertion"]

INTERIOR_SKY_FRACTION = 0.1  # a car interior receives roughly a tenth of the sky through its windows


@dataclass(frozen=True)
class Insertion:
    """Result of :func:`render_insertion`.

    Attributes:
        image: (H, W, 3) uint8 composited image (pixels outside the affected region byte-identical).
        mask: (H, W) float32 final object alpha after occlusion, 0..1.
        coverage: (H, W) float32 object coverage before occlusion (for the visible fraction).
        shadow_ratio: (H, W) float32 ratio map S (luminance of the per-channel ratio), 1 = unchanged.
        object_depth_m: (H, W) float32 camera-z of the object, inf where none.
        timing_s: seconds per stage: "prepare" (cached BVH, irradiance), "shadow", "foreground" (= "raycast"
            inside it + "shade"), "composite", and "total".
        stats: rays cast per stage, sample counts, pixel boxes.
        shadow_ratio_rgb: (H, W, 3) float32 per-channel ratio actually used in the composite.
        object_radiance: (H, W, 3) float32 un-premultiplied linear object radiance (0 where no coverage).
    """

    image: np.ndarray
    mask: np.ndarray
    coverage: np.ndarray
    shadow_ratio: np.ndarray
    object_depth_m: np.ndarray
    timing_s: dict[str, float]
    stats: dict
    shadow_ratio_rgb: np.ndarray | None = None
    object_radiance: np.ndarray | None = None


def render_insertion(image_rgb: np.ndarray, K: np.ndarray, depth_m: np.ndarray, light: DistantLight,
                     asset: Asset, T_cam_from_object: np.ndarray, ground_normal_cam: np.ndarray | None = None,
                     quality: str | RenderSettings = "default", ev: float = 0.0, seed: int = 0) -> Insertion:
    """Render ``asset`` at ``T_cam_from_object`` into ``image_rgb`` with its shadow and occlusion.

    Args:
        image_rgb: (H, W, 3) uint8 LDR image (the contract's camera response with exposure ``ev``).
        K: (3, 3) intrinsics.
        depth_m: (H, W) scene camera-z depth (metres), inf where unknown.
        light: camera-frame distant light (envmap without the sun + the sun).
        asset: the object (object frame x front, y left, z up, metres, origin at the bottom centre).
        T_cam_from_object: (4, 4) pose of the object in the camera frame.
        ground_normal_cam: (3,) ground normal (up) in the camera frame; default: the object's up axis.
        quality: a :data:`QUALITY_PRESETS` name or explicit :class:`RenderSettings`.
        ev: exposure of the camera response.
        seed: random seed (the result is deterministic for a seed).
    """
    t_start = time.perf_counter()
    image_rgb = np.asarray(image_rgb)
    if image_rgb.dtype != np.uint8 or image_rgb.ndim != 3 or image_rgb.shape[2] != 3:
        raise InputError(f"image: expected an (H, W, 3) uint8 RGB array, got {image_rgb.shape} {image_rgb.dtype}")
    H, W = image_rgb.shape[:2]
    K = np.asarray(K, dtype=np.float64)
    check_shape(K, (3, 3), "K")
    depth_m = np.asarray(depth_m, dtype=np.float32)
    if depth_m.shape != (H, W):
        raise InputError(f"depth: expected shape {(H, W)} (same as the image), got {depth_m.shape}")
    T = np.asarray(T_cam_from_object, dtype=np.float64)
    check_shape(T, (4, 4), "T_cam_from_object")
    if not np.all(np.isfinite(T)):
        raise InputError("T_cam_from_object: must be finite")
    settings = resolve_settings(quality)
    rng = np.random.default_rng(seed)
    timing: dict[str, float] = {}

    t0 = time.perf_counter()
    prep = prepare_asset(asset)
    up = T[:3, 2] if ground_normal_cam is None else np.asarray(ground_normal_cam, dtype=np.float64)
    check_shape(up, (3,), "ground_normal_cam")
    up = up / np.linalg.norm(up)
    E_sky_up = sky_irradiance(light.envmap, up)
    ambient = car_ambient_radiance(light, prep.mean_albedo, up)
    interior = INTERIOR_SKY_FRACTION * E_sky_up / np.pi
    bounce = BounceLight.build(light, prep, T, up)
    timing["prepare"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    sh = render_shadow(K, W, H, depth_m, light, prep, T, up, settings, rng, bounce)
    timing["shadow"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    foot = None if sh is None else sh.foot_ratio
    ground = None if sh is None else GroundShadow(sh, K, T, T[:3, :3].T @ up)
    fg = render_foreground(K, W, H, light, prep, T, settings, rng, ambient, interior, bounce, foot, ground)
    timing["foreground"] = time.perf_counter() - t0
    timing["raycast"] = fg.stats.get("raycast_s", 0.0) if fg is not None else 0.0
    timing["shade"] = timing["foreground"] - timing["raycast"]

    t0 = time.perf_counter()
    coverage = np.zeros((H, W), np.float32)
    mask = np.zeros((H, W), np.float32)
    obj_depth = np.full((H, W), np.inf, np.float32)
    rad_premult = np.zeros((H, W, 3), np.float32)
    vis_full = np.zeros((H, W), np.float32)
    ratio = np.ones((H, W, 3), np.float32)
    if fg is not None:
        h, w = fg.alpha.shape
        sl = (slice(fg.y0, fg.y0 + h), slice(fg.x0, fg.x0 + w))
        vis = depth_visibility(fg.depth_m, depth_m[sl])
        coverage[sl] = fg.alpha
        mask[sl] = fg.alpha * vis
        vis_full[sl] = vis
        obj_depth[sl] = fg.depth_m
        rad_premult[sl] = fg.radiance_premult
    if sh is not None:
        h, w = sh.ratio_rgb.shape[:2]
        ratio[sh.y0 : sh.y0 + h, sh.x0 : sh.x0 + w] = sh.ratio_rgb
    # Everything below only touches the union of the object's and the shadow's boxes.
    boxes = [(fg.x0, fg.y0, fg.x0 + fg.alpha.shape[1], fg.y0 + fg.alpha.shape[0])] if fg is not None else []
    if sh is not None:
        boxes.append((sh.x0, sh.y0, sh.x0 + sh.ratio_rgb.shape[1], sh.y0 + sh.ratio_rgb.shape[0]))
    image = image_rgb.copy()
    obj_rad = np.zeros((H, W, 3), np.float32)
    ratio_lum = np.ones((H, W), np.float32)
    effects = None
    if boxes:
        bx0, by0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
        bx1, by1 = max(b[2] for b in boxes), max(b[3] for b in boxes)
        if settings.match_camera:
            # Measured locally (blur and noise vary over an image): the object's box grown by 96 px.
            g = 96
            effects = estimate_camera_effects(image_rgb[max(by0 - g, 0) : by1 + g, max(bx0 - g, 0) : bx1 + g])
            m = int(np.ceil(3 * effects.blur_sigma_px))  # room for the blurred object's rim
            bx0, by0, bx1, by1 = max(bx0 - m, 0), max(by0 - m, 0), min(bx1 + m, W), min(by1 + m, H)
        ub = (slice(by0, by1), slice(bx0, bx1))
        if effects is None:
            image[ub] = composite(image_rgb[ub], rad_premult[ub], mask[ub], vis_full[ub], ratio[ub], ev)
        else:  # blur the visible object layer like the image, composite, then add the image's noise
            obj_b, mask_b = blur_object_layer(rad_premult[ub] * vis_full[ub][..., None], mask[ub], effects.blur_sigma_px)
            image[ub] = composite(image_rgb[ub], obj_b, mask_b, np.ones_like(mask_b), ratio[ub], ev)
            image[ub] = add_object_noise(image[ub], mask_b, effects.noise_sigma, rng)
        cov = coverage[ub][..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            obj_rad[ub] = np.where(cov > 0, rad_premult[ub] / cov, 0.0)
        lum_w = np.array([0.2126, 0.7152, 0.0722], np.float32)
        ratio_lum[ub] = np.einsum("hwc,c->hw", ratio[ub], lum_w)
    timing["composite"] = time.perf_counter() - t0
    timing["total"] = time.perf_counter() - t_start

    rays = {}
    for part in (fg, sh):
        if part is not None:
            for k, v in part.stats.get("rays", {}).items():
                rays[k] = rays.get(k, 0) + int(v)
    stats = {
        "quality": quality if isinstance(quality, str) else "custom",
        "rays": rays,
        "rays_total": int(sum(rays.values())),
        "foreground": None if fg is None else {k: v for k, v in fg.stats.items() if k != "rays"},
        "shadow": None if sh is None else {k: v for k, v in sh.stats.items() if k != "rays"},
        "ambient_rgb": ambient.tolist(),
    }
    if effects is not None:
        stats["camera_effects"] = {"blur_sigma_px": effects.blur_sigma_px, "noise_sigma": effects.noise_sigma}
    return Insertion(image=image, mask=mask, coverage=coverage, shadow_ratio=ratio_lum, object_depth_m=obj_depth,
                     timing_s=timing, stats=stats, shadow_ratio_rgb=ratio, object_radiance=obj_rad)
