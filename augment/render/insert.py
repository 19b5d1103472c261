"""Insert one object into one image: the renderer's single entry point, a one-way chain of stages::

    prepare (BVH cached on the asset, bounce light) -> footprint (pixel boxes) -> render_shadow
      -> render_foreground (sees the shadow) -> object_layers (depth test) -> composite_layers
      (seen through the image's veil, matching its blur, noise, the object's motion blur and the JPEG
      quality; on by default)
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from threadpoolctl import ThreadpoolController

from ..assets.asset import Asset
from ..core import InputError, PinholeCamera, check_shape
from ..lighting.light import DistantLight
from .bounce import BounceLight
from .camera_look import DAY_EXPOSURE_S, NIGHT_EXPOSURE_S, NeutralAxis, apply_neutral_axis, image_motion_px, \
    neutral_axis
from .composite import Composited, ObjectLayers, composite_layers, object_layers
from .footprint import Footprint, footprint
from .foreground import Foreground, render_foreground
from .settings import RenderSettings, resolve_settings
from .shade import ShadingContext
from .shadow import GroundShadow, ShadowMap, car_ambient_radiance, ground_snapped_depth, render_shadow
from .surface import PreparedAsset, prepare_asset
from .veil import Veil, estimate_veil

__all__ = ["Insertion", "render_insertion"]

NIGHT_MEDIAN_LEVEL = 40.0  # an image whose median 8-bit level is below this counts as night (exposure)
# The cabin's light over the sky's horizontal irradiance: what the windows pass to the seats, 1/pi int T cos dw over
# the directions that leave through glass (T the pane's transmission (1 - opacity) sqrt(tint) (1 - F), F its
# Fresnel), the street below at 0.15 of the sky's radiance.  Measured on the procedural cars (seat cushions and
# backrests, fitted to interior_shading's 1.5 / 1.0, body types by their weights): 0.112 (sedan 0.112, hatchback
# 0.118, SUV 0.103, van 0.122; tests/render/test_lamps_and_cabin.py).  Inter-reflections inside the cabin (dark:
# seats 0.035, dashboard 0.022) and sun patches on the seats are left out.
INTERIOR_SKY_FRACTION = 0.11


@dataclass(frozen=True)
class Insertion:
    """Result of :func:`render_insertion`.

    Only the object's and shadow's pixel boxes are held (``layers``, ``composited``): the full-frame float
    layers below build a new (H, W) array on each access (they were ~63 MB per object at 1600 x 900). Use
    ``layers.box`` / :meth:`~.composite.ObjectLayers.crop` and ``composited.box`` for box-local work.

    Attributes:
        image: (H, W, 3) uint8 composited image (pixels outside ``footprint.box`` byte-identical).
        layers: the object and its shadow as layers inside their union box (:class:`~.composite.ObjectLayers`).
        composited: the composite's box and its box-local outputs (radiance, shadow ratio).
        timing_s: seconds per stage: "prepare" (cached BVH, irradiance), "shadow", "foreground" (= "raycast"
            inside it + "shade"), "composite", and "total".
        stats: rays cast per stage, sample counts, pixel boxes.
        footprint: the pixel boxes the object and its shadow could reach (:func:`~.footprint.footprint`).

    Full-frame properties (new arrays):
        mask: (H, W) float32 the object's visible extent after occlusion, 0..1 (its see-through glass counts as
            the object: labels, the 2D box, occluding the objects rendered after it).
        coverage: (H, W) float32 the object's extent before occlusion (for the visible fraction).
        shadow_ratio: (H, W) float32 ratio map S (luminance of the per-channel ratio), 1 = unchanged.
        object_depth_m: (H, W) float32 camera-z of the object, inf where none.
        shadow_ratio_rgb: (H, W, 3) float32 per-channel ratio actually used in the composite.
        object_radiance: (H, W, 3) float32 un-premultiplied linear object radiance (0 where no coverage).
        alpha: (H, W) float32 the composited alpha after occlusion (``mask`` less what its glass lets through).
    """

    image: np.ndarray
    layers: ObjectLayers
    composited: Composited
    timing_s: dict[str, float]
    stats: dict
    footprint: Footprint | None = None

    mask = property(lambda self: self.layers.solid_mask, doc="(H, W) float32, a new array")
    coverage = property(lambda self: self.layers.solid_coverage, doc="(H, W) float32, a new array")
    object_depth_m = property(lambda self: self.layers.depth_m, doc="(H, W) float32, a new array")
    shadow_ratio_rgb = property(lambda self: self.layers.ratio_rgb, doc="(H, W, 3) float32, a new array")
    alpha = property(lambda self: self.layers.mask, doc="(H, W) float32, a new array")
    shadow_ratio = property(lambda self: self.composited.shadow_ratio, doc="(H, W) float32, a new array")
    object_radiance = property(lambda self: self.composited.object_radiance, doc="(H, W, 3) float32, a new array")

    @cached_property
    def coverage_px(self) -> float:
        """The object's coverage summed over the image (pixels), before occlusion."""
        return float(self.coverage.sum())

    @cached_property
    def visible_px(self) -> float:
        """The object's visible extent summed over the image (pixels): what remains visible after occlusion."""
        return float(self.mask.sum())


@dataclass(frozen=True)
class _Inputs:
    """Validated inputs: the uint8 image, its camera, the float32 scene depth (H, W), the pose (4, 4)."""

    image_rgb: np.ndarray
    camera: PinholeCamera
    depth_m: np.ndarray
    T_cam_from_object: np.ndarray


@dataclass(frozen=True)
class _Prepared:
    """What every stage reads: the prepared asset, the ground normal (3,) camera frame, the object's
    ambient radiance (3,) and interior factor (3,), its bounce light."""

    prep: PreparedAsset
    up_cam: np.ndarray
    ambient_rgb: np.ndarray
    interior_rgb: np.ndarray
    bounce: BounceLight


def render_insertion(image_rgb: np.ndarray, K: np.ndarray, depth_m: np.ndarray, light: DistantLight,
                     asset: Asset, T_cam_from_object: np.ndarray, ground_normal_cam: np.ndarray | None = None,
                     quality: str | RenderSettings = "default", ev: float = 0.0, seed: int = 0,
                     velocity_cam_mps: np.ndarray | None = None, exposure_s: float | None = None,
                     jpeg_quality: int | None = None, veil: Veil | None = None,
                     neutral: NeutralAxis | None = None) -> Insertion:
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
        velocity_cam_mps: (3,) the object's velocity relative to the camera (camera frame, m/s); with
            ``settings.match_camera`` it is smeared along its image motion during the exposure (None: none).
        exposure_s: exposure time (seconds); None: ``camera_look.DAY_EXPOSURE_S`` or ``NIGHT_EXPOSURE_S``
            by the image's median brightness (an assumption: nuScenes does not record it).
        jpeg_quality: the source file's JPEG quality (``camera_look.jpeg_quality_from_file``); with
            ``settings.match_camera`` the object's blocks are re-encoded at it (None: not re-encoded).
        veil: the image's haze and veiling glare (:func:`~.veil.estimate_veil` of the image and ``depth_m``);
            with ``settings.match_camera`` the object is seen through it (None: estimated here).
        neutral: the camera's neutral axis in the image (:func:`~.camera_look.neutral_axis` of the image as
            captured); with ``settings.match_camera`` it is added to the object's pixels (None: measured here on
            ``image_rgb``). Several objects put into one image share the one measured before any is drawn.
    """
    with _one_blas_thread():
        return _render_insertion(image_rgb, K, depth_m, light, asset, T_cam_from_object, ground_normal_cam, quality, ev,
                                 seed, velocity_cam_mps, exposure_s, jpeg_quality, veil, neutral)


def _one_blas_thread():
    """A context running BLAS on one thread.

    The renderer's matrix products are (N, 3) x (3, 3) or (3,): OpenBLAS splits them over its threads from
    N ~ 30 k on, where the threads cost more than they compute and spin while numpy works (on two threads an
    insert took 1.5x the CPU and the wall time of one, bench_render_reference's sunrise / sedan).
    """
    return _blas_controller().limit(limits=1, user_api="blas")


@functools.cache
def _blas_controller() -> ThreadpoolController:
    """The process's thread pools (looked up once, after numpy has loaded its BLAS)."""
    return ThreadpoolController()


def _render_insertion(image_rgb: np.ndarray, K: np.ndarray, depth_m: np.ndarray, light: DistantLight, asset: Asset,
                      T_cam_from_object: np.ndarray, ground_normal_cam: np.ndarray | None, quality: str | RenderSettings,
                      ev: float, seed: int, velocity_cam_mps: np.ndarray | None, exposure_s: float | None,
                      jpeg_quality: int | None, veil: Veil | None, neutral: NeutralAxis | None) -> Insertion:
    """:func:`render_insertion` (with BLAS on one thread)."""
    t_start = time.perf_counter()
    x = _check_inputs(image_rgb, K, depth_m, T_cam_from_object)
    settings = resolve_settings(quality)
    rng = np.random.default_rng(seed)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    prepared = _prepare(asset, light, x.T_cam_from_object, ground_normal_cam)  # validates the asset
    where = footprint(x.camera, asset, x.T_cam_from_object, light, settings)
    timing["prepare"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    sh = render_shadow(x.camera, where.shadow_box, x.depth_m, light, prepared.prep, x.T_cam_from_object,
                       prepared.up_cam, settings, rng, prepared.bounce)
    timing["shadow"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fg = _foreground(x, where, light, prepared, sh, settings, rng)
    timing["foreground"] = time.perf_counter() - t0
    timing["raycast"] = fg.stats.get("raycast_s", 0.0) if fg is not None else 0.0
    timing["shade"] = timing["foreground"] - timing["raycast"]
    t0 = time.perf_counter()
    # The occlusion test sees the ground the shadow sees (snapped to the object's plane near it).
    occluder_depth_m = ground_snapped_depth(x.camera, x.depth_m, where.object_box, prepared.up_cam,
                                            x.T_cam_from_object)
    layers = object_layers(fg, sh, occluder_depth_m)
    motion = _image_motion(x, layers, velocity_cam_mps, exposure_s) if settings.match_camera else None
    if settings.match_camera and veil is None:
        veil = estimate_veil(x.image_rgb, x.depth_m, ev)
    out = composite_layers(x.image_rgb, layers, x.camera, settings.match_camera, ev, rng, motion, jpeg_quality,
                           veil)
    if settings.match_camera and layers.box is not None:  # the camera's neutral axis (its cast) on the object's pixels
        sl, alpha = layers.box.slices, layers.crop("mask", layers.box)  # out.image is this call's own copy
        if np.any(alpha > 0):  # else no pixel to change (a shadow alone): nothing measured
            axis = neutral if neutral is not None else neutral_axis(x.image_rgb)
            out.image[sl] = apply_neutral_axis(out.image[sl], alpha, axis)
    timing["composite"] = time.perf_counter() - t0
    timing["total"] = time.perf_counter() - t_start
    layers = dataclasses.replace(layers, scene_depth_m=None)  # the full-frame depth is not kept in the result
    return Insertion(image=out.image, layers=layers, composited=out, timing_s=timing,
                     stats=_stats(quality, fg, sh, prepared, out), footprint=where)


def _image_motion(x: _Inputs, layers: ObjectLayers, velocity_cam_mps: np.ndarray | None,
                  exposure_s: float | None) -> np.ndarray | None:
    """(2,) image motion (pixels) during the exposure of the object's visible part (the point under its
    visible pixels' mean, at their mean depth: an object mostly beside the camera smears as its part in the
    image does, not as its centre would), or None without a velocity or a visible part."""
    if velocity_cam_mps is None or layers.box is None:
        return None
    if exposure_s is None:
        night = np.median(x.image_rgb[::8, ::8].mean(axis=2)) < NIGHT_MEDIAN_LEVEL
        exposure_s = NIGHT_EXPOSURE_S if night else DAY_EXPOSURE_S
    sl = layers.box.slices
    depth = layers.crop("depth_m", layers.box)
    hit = np.isfinite(depth)
    w = layers.crop("solid_mask", layers.box) * hit
    if w.sum() < 1.0:
        return None
    ys, xs = np.mgrid[sl]
    uv = np.array([[(w * xs).sum(), (w * ys).sum()]]) / w.sum()
    z = np.array([(w * np.where(hit, depth, 0.0)).sum() / w.sum()])
    point = x.camera.unproject(uv, z)[0]
    return image_motion_px(x.camera.K, point, np.asarray(velocity_cam_mps, np.float64), exposure_s)


def _check_inputs(image_rgb: np.ndarray, K: np.ndarray, depth_m: np.ndarray, T_cam_from_object: np.ndarray) -> _Inputs:
    """Validate and convert the inputs (clear :class:`InputError` messages)."""
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
    return _Inputs(image_rgb, PinholeCamera(K, W, H), depth_m, T)


def _prepare(asset: Asset, light: DistantLight, T: np.ndarray, ground_normal_cam: np.ndarray | None) -> _Prepared:
    """The prepared asset (cached on it), the unit ground normal, the ambient and interior light, the bounce light."""
    prep = prepare_asset(asset)
    up = T[:3, 2] if ground_normal_cam is None else np.asarray(ground_normal_cam, dtype=np.float64)
    check_shape(up, (3,), "ground_normal_cam")
    up = up / np.linalg.norm(up)
    bounce = BounceLight.build(light, prep, T, up)
    ambient = car_ambient_radiance(bounce.env, prep.mean_albedo, up)
    interior = INTERIOR_SKY_FRACTION * bounce.env.sky_irradiance(up) / np.pi
    return _Prepared(prep, up, ambient, interior, bounce)


def _foreground(x: _Inputs, where: Footprint, light: DistantLight, prepared: _Prepared, sh: ShadowMap | None,
                settings: RenderSettings, rng: np.random.Generator) -> Foreground | None:
    """The foreground stage: shading context (with the shadow seen from the object), then the render."""
    T = x.T_cam_from_object
    foot = None if sh is None else sh.foot_ratio
    ground = None if sh is None else GroundShadow(sh, x.camera, T, T[:3, :3].T @ prepared.up_cam)
    ctx = ShadingContext.for_object(prepared.prep, light, prepared.bounce.env, T, settings, rng, prepared.ambient_rgb,
                                    prepared.interior_rgb, prepared.bounce, foot, ground)
    return render_foreground(x.camera, where.object_box, ctx, T)


def _stats(quality: str | RenderSettings, fg: Foreground | None, sh: ShadowMap | None, prepared: _Prepared,
           out: Composited) -> dict:
    """Rays per stage summed over the passes, each pass's own stats, the ambient radiance, the camera effects."""
    rays: dict[str, int] = {}
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
        "ambient_rgb": prepared.ambient_rgb.tolist(),
    }
    if out.effects is not None:
        stats["camera_effects"] = {"blur_sigma_px": out.effects.blur_sigma_px, "noise_sigma": out.effects.noise_sigma}
    return stats

