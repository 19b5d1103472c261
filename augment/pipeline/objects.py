"""Rendering several objects into one image, one after the other (each occluded by the earlier ones)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..assets.asset import Asset
from ..core import PinholeCamera
from ..lighting.light import DistantLight
from ..render import Insertion, NeutralAxis, PixelBox, estimate_veil, footprint, neutral_axis, render_insertion
from .options import InsertOptions, render_settings
from .results import changed_pixel_box


class _NeutralAxisOnFirstUse(NeutralAxis):
    """The :func:`~streetaug.augment.render.neutral_axis` of an image, measured when the renderer first reads it
    (the first object with a pixel to tint), not before: an image whose objects draw no pixel (a shadow alone,
    every object hidden) is not measured (~3 ms at 1600 x 900). The same values as measuring it up front.

    Args:
        image_rgb: (H, W, 3) uint8 the image as captured (kept, not copied: the caller does not write to it).
    """

    def __init__(self, image_rgb: np.ndarray) -> None:  # noqa: D107 - the dataclass fields come on first read
        object.__setattr__(self, "_image_rgb", image_rgb)

    @property
    def measured(self) -> bool:
        """Whether the axis has been measured."""
        return "levels" in self.__dict__

    def __getattr__(self, name: str):
        image = self.__dict__.get("_image_rgb")
        if name in ("levels", "offsets_dn", "n_px") and image is not None:  # only reached before they are set
            axis = neutral_axis(image)
            for f in ("levels", "offsets_dn", "n_px"):
                object.__setattr__(self, f, getattr(axis, f))
            object.__setattr__(self, "_image_rgb", None)
            return getattr(axis, name)
        raise AttributeError(name)


@dataclass(frozen=True)
class RenderedObject:
    """One object rendered into an image: what the labels read of the renderer's result, its mask and
    coverage cut to the pixel box holding every non-zero pixel of either (the renderer's other full-frame
    layers are dropped once the object is composited: ~66 MB per object at 1600 x 900).

    Attributes:
        T_cam_from_object: (4, 4) its pose in the camera frame.
        asset: the object.
        image_shape_px: (H, W) of the image it was rendered into.
        box: the pixel box of ``mask_box`` / ``coverage_box`` (empty for an object of which only the shadow
            reaches the image).
        mask_box, coverage_box: (box.height, box.width) float32 the renderer's ``mask`` (visible extent,
            after occlusion) and ``coverage`` (before occlusion) inside ``box``; 0 outside it.
        visible_px, coverage_px: the renderer's ``visible_px`` / ``coverage_px`` (sums over the full image).
        timing_s, stats: the renderer's seconds per stage and statistics.
    """

    T_cam_from_object: np.ndarray
    asset: Asset
    image_shape_px: tuple[int, int]
    box: PixelBox
    mask_box: np.ndarray
    coverage_box: np.ndarray
    visible_px: float
    coverage_px: float
    timing_s: dict[str, float]
    stats: dict

    @classmethod
    def from_insertion(cls, T_cam_from_object: np.ndarray, asset: Asset, ins: Insertion) -> RenderedObject:
        """The labels' part of ``ins`` (copies: nothing of ``ins`` stays referenced)."""
        L = ins.layers
        box = PixelBox(0, 0, 0, 0)
        if L.box is not None:
            local = changed_pixel_box((L.solid_mask_box != 0) | (L.solid_coverage_box != 0))
            if local.width and local.height:
                box = PixelBox(local.x0 + L.box.x0, local.y0 + L.box.y0, local.x1 + L.box.x0, local.y1 + L.box.y0)
        return cls(T_cam_from_object, asset, L.shape_px, box, L.crop("solid_mask", box).copy(),
                   L.crop("solid_coverage", box).copy(), ins.visible_px, ins.coverage_px, dict(ins.timing_s),
                   ins.stats)

    def full_mask(self) -> np.ndarray:
        """(H, W) float32 the renderer's ``mask`` over the full image (a new array)."""
        return self.box.paste(self.mask_box, self.image_shape_px, 0.0)

    def full_coverage(self) -> np.ndarray:
        """(H, W) float32 the renderer's ``coverage`` over the full image (a new array)."""
        return self.box.paste(self.coverage_box, self.image_shape_px, 0.0)


@dataclass(frozen=True)
class RenderedImage:
    """Objects rendered into one image (:func:`render_objects`).

    Attributes:
        image: (H, W, 3) uint8 the composite with every object.
        mask: (H, W) float32 union of the objects' visible extent (``Insertion.mask``).
        shadow_ratio: (H, W) float32 product of the objects' shadow ratio maps.
        objects: the objects, in the order given (rendered nearest first).
    """

    image: np.ndarray
    mask: np.ndarray
    shadow_ratio: np.ndarray
    objects: list[RenderedObject]


def render_objects(image: np.ndarray, K: np.ndarray, depth_m: np.ndarray, lights: Sequence[DistantLight],
                   assets: Sequence[Asset], T_cam_from_objects: Sequence[np.ndarray],
                   ground_normals_cam: Sequence[np.ndarray], options: InsertOptions, rng: np.random.Generator,
                   timing: dict[str, float], velocities_cam_mps: Sequence[np.ndarray | None] | None = None,
                   jpeg_quality: int | None = None) -> RenderedImage:
    """Render objects nearest first (each with its light); each is occluded by the nearer ones already drawn.

    Nearest first, so that an object's mask and visible fraction (its labels) count the inserted objects in
    front of it, not only the scene: rendered the other way round, a car behind a nearer inserted car was
    drawn over first and labelled fully visible (11 of 21 such cars on the real dev scene).

    Args:
        image: (H, W, 3) uint8; K: (3, 3) intrinsics; depth_m: (H, W) scene camera-z depth, metres.
        lights, assets, T_cam_from_objects, ground_normals_cam: one per object (camera frame).
        rng: draws one render seed per object, in the given order (whatever the render order).
        timing: receives ``render`` and the renderer's stages summed over the objects (``render.<stage>``).
        velocities_cam_mps: per object, its (3,) velocity relative to the camera (camera frame, m/s; the
            renderer's motion blur), or None (no motion blur).
        jpeg_quality: the source image file's JPEG quality (``render.camera_look.jpeg_quality_from_file``), or None.

    Returns:
        The composite; ``objects`` in the given order.
    """
    mask_union = np.zeros(image.shape[:2], np.float32)
    shadow = np.ones(image.shape[:2], np.float32)
    settings = render_settings(options)
    t = time.perf_counter()
    n = len(assets)
    seeds = [int(rng.integers(2**31)) for _ in range(n)]
    velocities = list(velocities_cam_mps) if velocities_cam_mps is not None else [None] * n
    order = np.argsort([float(np.linalg.norm(np.asarray(T)[:3, 3])) for T in T_cam_from_objects], kind="stable")
    # the photo's haze and veiling glare and its camera's neutral axis, measured once on the image as captured
    # (not on the objects drawn into it); the axis only once an object has a pixel to tint
    veil = estimate_veil(image, depth_m, options.ev) if settings.match_camera and n else None
    neutral = _NeutralAxisOnFirstUse(image) if settings.match_camera and n else None
    rendered: list[RenderedObject | None] = [None] * n
    depth_in = depth_m
    for i in order:
        ins = render_insertion(
            image, K, depth_m, lights[i], assets[i], T_cam_from_objects[i], ground_normal_cam=ground_normals_cam[i],
            quality=settings, ev=options.ev, seed=seeds[i], velocity_cam_mps=velocities[i], jpeg_quality=jpeg_quality,
            veil=veil, neutral=neutral,
        )
        for stage, seconds in ins.timing_s.items():
            if stage != "total":
                timing[f"render.{stage}"] = timing.get(f"render.{stage}", 0.0) + seconds
        image = ins.image
        # box-local: outside its layers' box an object's mask is 0, outside the composite's its shadow ratio 1
        if ins.layers.box is not None:
            sl, vis = ins.layers.box.slices, ins.layers.solid_mask_box
            if depth_m is depth_in:  # the caller's depth is not written to
                depth_m = depth_m.copy()
            depth_m[sl] = np.where(vis > 0.5, np.minimum(depth_m[sl], ins.layers.depth_box), depth_m[sl])
            mask_union[sl] = np.maximum(mask_union[sl], vis)
        if ins.composited.box is not None:
            shadow[ins.composited.box.slices] *= ins.composited.shadow_ratio_box
        rendered[i] = RenderedObject.from_insertion(T_cam_from_objects[i], assets[i], ins)
        del ins  # its layers are not kept while the next object renders
    timing["render"] = time.perf_counter() - t
    return RenderedImage(image, mask_union, shadow, rendered)


def reaches_view(camera: PinholeCamera, asset: Asset, T_cam_from_object: np.ndarray, light: DistantLight,
                 options: InsertOptions) -> bool:
    """Whether the object or its shadow can touch any pixel of ``camera``'s image (the renderer's own
    pixel boxes, :func:`~streetaug.augment.render.footprint`, with the settings it renders with)."""
    return footprint(camera, asset, T_cam_from_object, light, render_settings(options)).reaches_image
