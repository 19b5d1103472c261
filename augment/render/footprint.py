"""Where an insertion can change an image: the object's pixel box and its shadow's.

Both boxes are conservative (projected boxes of the object and of where its shadow and sky occlusion
can fall, a few pixels of margin): outside them the renderer leaves every byte of the image unchanged.
They cost a few projected corners, no ray tracing, so callers can ask first whether an object reaches
a camera at all (:func:`footprint`, :attr:`Footprint.reaches_image`); the renderer works on the same boxes
and returns them with its result (:attr:`streetaug.augment.render.insert.Insertion.footprint`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..assets.asset import Asset
from ..core import PinholeCamera
from ..lighting.light import DistantLight
from .settings import RenderSettings
from .surface import box_corners_object

SKY_RADIUS_PER_HEIGHT = 2.0  # sky occlusion beyond ~2 object heights is below a few per cent
SKY_RADIUS_PAD_M = 0.3
SKY_FADE_START = 0.85  # the sky occlusion fades out from this fraction of the sky radius to the radius
SUN_FADE_START = 0.6  # sun shadows fade out from this fraction of ``shadow_max_length_m`` to all of it
OBJECT_BOX_PAD_PX = 2


def sky_radius_m(height_m: float) -> float:
    """How far (metres, along the ground from the object's footprint box) the sky occlusion of an object
    ``height_m`` tall is computed; it fades to exactly 0 there (:func:`fade_weight`, :data:`SKY_FADE_START`)."""
    return SKY_RADIUS_PER_HEIGHT * max(float(height_m), 0.0) + SKY_RADIUS_PAD_M


def fade_weight(dist_m: np.ndarray, end_m: float, start_fraction: float) -> np.ndarray:
    """Smooth cut-off (N,): 1 up to ``start_fraction x end_m``, a smoothstep down to exactly 0 at ``end_m`` and beyond.

    The shadow's sun and sky parts are truncated with it (at the shadow's longest length and at the sky
    radius), so the ratio map reaches 1 smoothly inside :func:`shadow_pixel_box` instead of being cut at its edge.
    """
    start = start_fraction * end_m
    x = np.clip((np.asarray(dist_m, dtype=np.float64) - start) / max(end_m - start, 1e-9), 0.0, 1.0)
    return 1.0 - x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class PixelBox:
    """An integer pixel box of an image, end-exclusive: columns x0 .. x1 - 1, rows y0 .. y1 - 1."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0

    @property
    def slices(self) -> tuple[slice, slice]:
        """(rows, columns) slices of an (H, W, ...) image array."""
        return slice(self.y0, self.y1), slice(self.x0, self.x1)

    def paste(self, layer: np.ndarray, shape_px: tuple[int, int], fill: float) -> np.ndarray:
        """A new (H, W[, C]) array of ``shape_px`` holding ``layer`` (this box's (height, width[, C])) inside this box
        and ``fill`` everywhere else (the full frame of a layer held only in its box)."""
        out = np.full(tuple(shape_px) + layer.shape[2:], fill, layer.dtype)
        out[self.slices] = layer
        return out

    def union(self, other: "PixelBox | None") -> "PixelBox":
        """The smallest box holding this one and ``other``."""
        if other is None:
            return self
        return PixelBox(min(self.x0, other.x0), min(self.y0, other.y0), max(self.x1, other.x1), max(self.y1, other.y1))

    def grown(self, margin_px: int, camera: PinholeCamera) -> "PixelBox":
        """The box grown by ``margin_px`` on every side, clipped to the image of ``camera``."""
        return PixelBox(max(self.x0 - margin_px, 0), max(self.y0 - margin_px, 0),
                        min(self.x1 + margin_px, camera.width), min(self.y1 + margin_px, camera.height))

    def as_list(self) -> list[int]:
        """[x0, y0, x1, y1] (for JSON stats)."""
        return [self.x0, self.y0, self.x1, self.y1]


def edge_pixels(uv_tri: np.ndarray, box: PixelBox) -> np.ndarray:
    """(h, w) bool over ``box``: pixels the edges of projected triangles cross (or pass within about a pixel of).

    ``uv_tri`` (F, 3, 2) are image pixel coordinates (pixel centres at integers) of the triangles'
    corners.  Every pixel a triangle partly overlaps is crossed by one of its edges, so these pixels
    together with the pixels some sample already hit hold every pixel the triangles touch: thin
    geometry far under a pixel (spokes, wires) is found even where a first, sparse pass of samples
    missed it.  Anti-aliased lines with 4 fractional bits (a conservative raster of each edge).
    """
    mask = np.zeros((box.height, box.width), np.uint8)
    if len(uv_tri):
        local = np.clip(np.asarray(uv_tri, dtype=np.float64) - [box.x0, box.y0], -1e5, 1e5)
        pts = np.round(local * 16.0).astype(np.int32)
        cv2.polylines(mask, pts, True, 255, 1, cv2.LINE_AA, 4)
    return mask > 0


def _clipped(x0: int, y0: int, x1: int, y1: int, camera: PinholeCamera) -> PixelBox | None:
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, camera.width), min(y1, camera.height)
    if x1 <= x0 or y1 <= y0:
        return None
    return PixelBox(int(x0), int(y0), int(x1), int(y1))


NEAR_PLANE_M = 1e-3  # camera z below which an object's box corner is behind the camera


def clip_to_near_plane(points_cam: np.ndarray, near_m: float) -> np.ndarray:
    """Points (M, 3) whose convex hull is that of ``points_cam`` (N, 3), camera frame, cut by the plane z = near_m.

    The points in front of the plane plus every crossing of the plane by a segment between a point in front and
    one behind (the cut hull's vertices are among them, and all of them lie in it, so the projections of the
    result bound exactly what of the hull a camera can see).
    """
    z = points_cam[:, 2]
    front, behind = points_cam[z > near_m], points_cam[z <= near_m]
    a = np.repeat(front, len(behind), axis=0)
    b = np.tile(behind, (len(front), 1))
    t = (a[:, 2] - near_m) / (a[:, 2] - b[:, 2])
    crossings = a + t[:, None] * (b - a)
    crossings[:, 2] = near_m
    return np.concatenate([front, crossings])


def object_pixel_box(camera: PinholeCamera, T_cam_from_object: np.ndarray, corners_object: np.ndarray,
                     pad_px: int = OBJECT_BOX_PAD_PX) -> PixelBox | None:
    """The pixel box covering the projected object box (8, 3) (object frame), or None if off-screen."""
    pts = corners_object @ T_cam_from_object[:3, :3].T + T_cam_from_object[:3, 3]
    z = pts[:, 2]
    if np.all(z <= NEAR_PLANE_M):
        return None
    if np.any(z <= NEAR_PLANE_M):
        # The box straddles the camera plane: only its part in front of the near plane can be seen.
        pts = clip_to_near_plane(pts, NEAR_PLANE_M)
    uv, _ = camera.project(pts)
    x0 = int(np.floor(uv[:, 0].min())) - pad_px
    y0 = int(np.floor(uv[:, 1].min())) - pad_px
    x1 = int(np.ceil(uv[:, 0].max())) + pad_px + 1
    y1 = int(np.ceil(uv[:, 1].max())) + pad_px + 1
    return _clipped(x0, y0, x1, y1, camera)


def shadow_pixel_box(camera: PinholeCamera, T_cam_from_object: np.ndarray, asset: Asset, light: DistantLight,
                     settings: RenderSettings) -> PixelBox | None:
    """The pixel box where the shadow ratio map can differ from 1, or None.

    The object's footprint grown by the sky-occlusion radius (:func:`sky_radius_m`) plus its top corners
    projected along the sun onto the ground, clamped to ``settings.shadow_max_length_m`` (the renderer fades
    the sun shadow out before that length and the sky occlusion before that radius, :func:`fade_weight`, so
    the map is 1 on the box's edges), grown by the sun disc's penumbra; the ground plane z = 0 of the object frame.
    """
    V = asset.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    h_obj = float(max(hi[2], 0.0))
    r = sky_radius_m(h_obj)
    ground = np.array([[x, y, 0.0] for x in (lo[0] - r, hi[0] + r) for y in (lo[1] - r, hi[1] + r)])
    pts = [ground]
    if light.sun is not None:
        s = T_cam_from_object[:3, :3].T @ np.asarray(light.sun.direction, dtype=np.float64)
        if s[2] > 1e-3:
            horiz = -s[:2] / s[2] * h_obj
            length = np.linalg.norm(horiz)
            if length > settings.shadow_max_length_m:
                horiz *= settings.shadow_max_length_m / length
            m = 0.3 + np.tan(light.sun.half_angle_rad) * length  # penumbra (uncapped length: >= the capped one's)
            pts.append(np.array([[x + horiz[0] + dx, y + horiz[1] + dy, 0.0]
                                 for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for dx in (-m, m) for dy in (-m, m)]))
    pts = np.concatenate(pts)
    pts_cam = pts @ T_cam_from_object[:3, :3].T + T_cam_from_object[:3, 3]
    front = pts_cam[:, 2] > 0.3
    if not front.any():
        return None
    uv, _ = camera.project(pts_cam[front])
    x0, y0 = np.floor(uv.min(axis=0)).astype(int) - 2
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 3
    if not front.all():  # the region reaches behind the camera: extend to the bottom and the sides
        x0, x1, y1 = 0, camera.width, camera.height
    return _clipped(x0, y0, x1, y1, camera)


@dataclass(frozen=True)
class Footprint:
    """Where inserting one object can change an image.

    Attributes:
        object_box: pixels the object itself can cover, or None (off-screen).
        shadow_box: pixels its shadow (and sky occlusion) can darken, or None.
    """

    object_box: PixelBox | None
    shadow_box: PixelBox | None

    @property
    def reaches_image(self) -> bool:
        """Whether the object or its shadow can touch any pixel."""
        return self.object_box is not None or self.shadow_box is not None

    @property
    def box(self) -> PixelBox | None:
        """The union of both boxes, or None."""
        if self.object_box is None:
            return self.shadow_box
        return self.object_box.union(self.shadow_box)


def footprint(camera: PinholeCamera, asset: Asset, T_cam_from_object: np.ndarray, light: DistantLight,
              settings: RenderSettings) -> Footprint:
    """The :class:`Footprint` of ``asset`` at ``T_cam_from_object`` (4, 4) under ``light`` (camera frame)."""
    T = np.asarray(T_cam_from_object, dtype=np.float64)
    return Footprint(object_pixel_box(camera, T, box_corners_object(asset)),
                     shadow_pixel_box(camera, T, asset, light, settings))
