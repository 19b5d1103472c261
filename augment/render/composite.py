"""Occlusion by scene depth and the composite ``I_edit = M I_obj + (1 - M) I S`` in linear HDR.

The last stage of the chain: the box-local layers of the foreground (object radiance, coverage,
depth) and of the shadow (ratio map) are placed into :class:`ObjectLayers` of their union's pixel box, occluded by
the scene depth, optionally blurred and noised like the photo (:mod:`.camera_effects`), and composited.
Only pixels where ``M > 0`` or ``S < 1`` are converted and rewritten; every other byte of the
input image is returned unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..core import PinholeCamera, hdr_to_ldr_uint8, ldr_uint8_to_hdr, luminance
from .camera_effects import CameraEffects, add_object_noise, blur_object_layer, estimate_camera_effects
from .camera_look import jpeg_noise_survival, jpeg_round_trip, motion_kernel
from .footprint import PixelBox
from .foreground import Foreground
from .shadow import ShadowMap
from .veil import Veil

CAMERA_EFFECTS_MARGIN_PX = 96  # blur and noise are measured on the affected box grown by this much

COMPOSITE_CHUNK_PX = 65_536  # touched pixels composited at a time (~2 MB per float64 buffer; a whole frame: 35 MB)

OCCLUSION_SOFT_M = 0.10  # width of the soft depth test at 0 m ...
OCCLUSION_SOFT_PER_M = 0.01  # ... growing 1 cm per metre of depth (LiDAR / completion error grows)


def depth_visibility(object_depth_m: np.ndarray, scene_depth_m: np.ndarray) -> np.ndarray:
    """Soft depth test (h, w) float32 in [0, 1]: 1 where the object is in front of the scene.

    The object stays fully visible while it is no more than 0 m behind the scene surface and fades to
    0 over ``OCCLUSION_SOFT_M + OCCLUSION_SOFT_PER_M * depth`` behind it (so a tyre touching the
    ground it stands on is not cut), then a 3 x 3 box blur softens the boundary by a pixel.
    """
    obj = np.asarray(object_depth_m, dtype=np.float64)
    scene = np.asarray(scene_depth_m, dtype=np.float64)
    scene = np.where(np.isfinite(scene) & (scene > 0), scene, np.inf)
    soft = OCCLUSION_SOFT_M + OCCLUSION_SOFT_PER_M * np.where(np.isfinite(obj), obj, 0.0)
    with np.errstate(invalid="ignore"):
        vis = np.clip((scene - obj) / soft + 1.0, 0.0, 1.0)
    vis = np.where(np.isfinite(obj), np.where(np.isinf(scene), 1.0, vis), 0.0).astype(np.float32)
    if vis.shape[0] >= 2 and vis.shape[1] >= 2 and (vis < 1).any():
        blurred = cv2.blur(vis, (3, 3), borderType=cv2.BORDER_REPLICATE)
        vis = np.where(np.isfinite(obj), blurred, 0.0).astype(np.float32)
    return vis


def composite(image_rgb: np.ndarray, radiance_premult: np.ndarray, mask: np.ndarray, visibility: np.ndarray,
              ratio_rgb: np.ndarray, ev: float = 0.0) -> np.ndarray:
    """Composite an object and its shadow into a uint8 image.

    Args:
        image_rgb: (H, W, 3) uint8 input (LDR, the contract's camera response).
        radiance_premult: (H, W, 3) float32 object radiance x coverage (linear HDR).
        mask: (H, W) float32 final alpha M = coverage x visibility.
        visibility: (H, W) float32 depth-test visibility (M I_obj = visibility x radiance_premult).
        ratio_rgb: (H, W, 3) float32 shadow ratio S (1 = unchanged).
        ev: exposure of the camera response.

    Returns:
        (H, W, 3) uint8; pixels with M == 0 and S == 1 are byte-identical to ``image_rgb``.
    """
    out = image_rgb.copy()
    touched = (mask > 0) | (ratio_rgb < 1).any(axis=2)
    if not touched.any():
        return out
    ys_all, xs_all = np.nonzero(touched)
    for a in range(0, len(ys_all), COMPOSITE_CHUNK_PX):  # per pixel: chunks only bound the float64 buffers
        ys, xs = ys_all[a : a + COMPOSITE_CHUNK_PX], xs_all[a : a + COMPOSITE_CHUNK_PX]
        I = ldr_uint8_to_hdr(image_rgb[ys, xs], ev).astype(np.float64)
        M = mask[ys, xs].astype(np.float64)[:, None]
        obj = visibility[ys, xs].astype(np.float64)[:, None] * radiance_premult[ys, xs]
        edit = obj + (1.0 - M) * I * ratio_rgb[ys, xs]
        out[ys, xs] = hdr_to_ldr_uint8(edit, ev)
    return out


# What each layer of :class:`ObjectLayers` holds outside the object's and the shadow's box.
LAYER_FILL = {"coverage": 0.0, "visibility": 0.0, "mask": 0.0, "depth_m": np.inf, "radiance_premult": 0.0,
              "ratio_rgb": 1.0, "solid_coverage": 0.0, "solid_mask": 0.0}
_RGB_LAYERS = ("radiance_premult", "ratio_rgb")


@dataclass(frozen=True)
class ObjectLayers:
    """The object and its shadow as layers of the image (H, W), before compositing, held only inside ``box``
    (the union of the object's and the shadow's pixel boxes: every pixel outside it holds the layer's
    :data:`LAYER_FILL`). :meth:`crop` gives a layer over any box of the image; the full-frame properties
    (``coverage``, ``mask``, ...) build a new (H, W) array on each access (unless ``box`` is the whole image:
    then they are the held arrays).

    Full-frame float layers of a 1600 x 900 image are 5.8 MB each (35 MB with colour; nine of them were
    69 MB per object before): a car 30 m away has a box of ~1 % of the frame.

    Attributes:
        shape_px: (H, W) of the image.
        box: the union of the object's and the shadow's boxes (everything outside is untouched), or None
            (then every layer is its fill).
        coverage_box: (h, w) float32 object coverage before occlusion, 0..1 (h, w: ``box``'s size).
        visibility_box: (h, w) float32 soft depth test of the object against the scene (0 outside the object box).
        mask_box: (h, w) float32 final object alpha ``coverage x visibility``.
        depth_box: (h, w) float32 camera-z of the object, inf where none.
        radiance_box: (h, w, 3) float32 linear object radiance x coverage.
        ratio_box: (h, w, 3) float32 per-channel shadow ratio S, 1 = unchanged.
        solid_coverage_box, solid_mask_box: (h, w) float32 the object's extent before / after occlusion (its
            glass counts as the object: ``Foreground.solid``), for labels and for occluding other objects.
        scene_depth_m: (H, W) the scene's camera-z depth the object was occluded by (the shadow's veil).
    """

    shape_px: tuple[int, int]
    box: PixelBox | None
    coverage_box: np.ndarray
    visibility_box: np.ndarray
    mask_box: np.ndarray
    depth_box: np.ndarray
    radiance_box: np.ndarray
    ratio_box: np.ndarray
    solid_coverage_box: np.ndarray
    solid_mask_box: np.ndarray
    scene_depth_m: np.ndarray | None = None

    def _stored(self, name: str) -> np.ndarray:
        return getattr(self, {"depth_m": "depth_box", "radiance_premult": "radiance_box",
                              "ratio_rgb": "ratio_box"}.get(name, f"{name}_box"))

    def crop(self, name: str, box: PixelBox) -> np.ndarray:
        """Layer ``name`` (a key of :data:`LAYER_FILL`) over ``box`` (inside the image): float32
        (box.height, box.width[, 3]), the fill outside ``self.box``. A view of the held layer when ``box`` lies
        inside ``self.box`` (a near object's box is the whole frame: no copy of it), else a new array."""
        own = self.box
        if own is not None and own.x0 <= box.x0 and own.y0 <= box.y0 and box.x1 <= own.x1 and box.y1 <= own.y1:
            return self._stored(name)[box.y0 - own.y0 : box.y1 - own.y0, box.x0 - own.x0 : box.x1 - own.x0]
        shape = (box.height, box.width, 3) if name in _RGB_LAYERS else (box.height, box.width)
        out = np.full(shape, LAYER_FILL[name], np.float32)
        if own is None:
            return out
        x0, y0, x1, y1 = max(box.x0, own.x0), max(box.y0, own.y0), min(box.x1, own.x1), min(box.y1, own.y1)
        if x1 > x0 and y1 > y0:
            out[y0 - box.y0 : y1 - box.y0, x0 - box.x0 : x1 - box.x0] = \
                self._stored(name)[y0 - own.y0 : y1 - own.y0, x0 - own.x0 : x1 - own.x0]
        return out

    def full(self, name: str) -> np.ndarray:
        """Layer ``name`` over the whole image: (H, W[, 3]) float32 (see :meth:`crop`)."""
        H, W = self.shape_px
        return self.crop(name, PixelBox(0, 0, W, H))

    coverage = property(lambda self: self.full("coverage"), doc="(H, W) float32")
    visibility = property(lambda self: self.full("visibility"), doc="(H, W) float32")
    mask = property(lambda self: self.full("mask"), doc="(H, W) float32")
    depth_m = property(lambda self: self.full("depth_m"), doc="(H, W) float32, inf where none")
    radiance_premult = property(lambda self: self.full("radiance_premult"), doc="(H, W, 3) float32")
    ratio_rgb = property(lambda self: self.full("ratio_rgb"), doc="(H, W, 3) float32")
    solid_coverage = property(lambda self: self.full("solid_coverage"), doc="(H, W) float32")
    solid_mask = property(lambda self: self.full("solid_mask"), doc="(H, W) float32")


def object_layers(fg: Foreground | None, sh: ShadowMap | None, scene_depth_m: np.ndarray) -> ObjectLayers:
    """Place the box-local foreground and shadow into layers of their union box; occlude the object by
    ``scene_depth_m`` (H, W)."""
    H, W = scene_depth_m.shape
    box = None if fg is None else fg.box
    if sh is not None:
        box = sh.box if box is None else box.union(sh.box)
    size = (0, 0) if box is None else (box.height, box.width)
    layers = {name: np.full(size + ((3,) if name in _RGB_LAYERS else ()), fill, np.float32)
              for name, fill in LAYER_FILL.items()}

    def at(sub: PixelBox) -> tuple[slice, slice]:  # ``sub``'s slices inside ``box``
        return slice(sub.y0 - box.y0, sub.y1 - box.y0), slice(sub.x0 - box.x0, sub.x1 - box.x0)

    if fg is not None:
        sl = at(fg.box)
        vis = depth_visibility(fg.depth_m, scene_depth_m[fg.box.slices])
        layers["coverage"][sl] = fg.alpha
        layers["mask"][sl] = fg.alpha * vis
        solid = fg.alpha if fg.solid is None else np.maximum(fg.solid, fg.alpha)
        layers["solid_coverage"][sl] = solid
        layers["solid_mask"][sl] = solid * vis
        layers["visibility"][sl] = vis
        layers["depth_m"][sl] = fg.depth_m
        layers["radiance_premult"][sl] = fg.radiance_premult
    if sh is not None:
        layers["ratio_rgb"][at(sh.box)] = sh.ratio_rgb
    return ObjectLayers((H, W), box, layers["coverage"], layers["visibility"], layers["mask"], layers["depth_m"],
                        layers["radiance_premult"], layers["ratio_rgb"], layers["solid_coverage"],
                        layers["solid_mask"], scene_depth_m)


@dataclass(frozen=True)
class Composited:
    """Result of :func:`composite_layers`.

    Attributes:
        image: (H, W, 3) uint8 the composite (byte-identical to the input outside ``box``).
        box: the pixel box the composite changed (the layers' box grown by the blurred rim), or None.
        object_radiance_box: (h, w, 3) float32 un-premultiplied linear object radiance inside ``box`` (0 where
            no coverage); :attr:`object_radiance` gives it over the full image (0 outside ``box``).
        shadow_ratio_box: (h, w) float32 luminance of the per-channel ratio inside ``box``, 1 = unchanged;
            :attr:`shadow_ratio` gives it over the full image (1 outside ``box``).
        effects: the blur and noise matched to the image, or None (not matched, or no object pixel to match).
    """

    image: np.ndarray
    box: PixelBox | None
    object_radiance_box: np.ndarray
    shadow_ratio_box: np.ndarray
    effects: CameraEffects | None

    def _full(self, layer: np.ndarray, fill: float) -> np.ndarray:
        return (self.box or PixelBox(0, 0, 0, 0)).paste(layer, self.image.shape[:2], fill)

    @property
    def object_radiance(self) -> np.ndarray:
        """(H, W, 3) float32 un-premultiplied linear object radiance (0 where no coverage); a new array."""
        return self._full(self.object_radiance_box, 0.0)

    @property
    def shadow_ratio(self) -> np.ndarray:
        """(H, W) float32 luminance of the per-channel ratio, 1 = unchanged; a new array."""
        return self._full(self.shadow_ratio_box, 1.0)


def object_drawn(layers: ObjectLayers) -> bool:
    """Whether the object itself adds to any pixel of the composite (its visible alpha, or radiance it shows
    where it is not occluded, e.g. glass all of whose rays went through); False for an object whose shadow
    alone reaches the image."""
    if layers.box is None:
        return False
    if np.any(layers.mask_box > 0):
        return True
    seen = layers.visibility_box > 0
    return bool(np.any(seen) and np.any(layers.radiance_box[seen] != 0))


def composite_layers(image_rgb: np.ndarray, layers: ObjectLayers, camera: PinholeCamera, match_camera: bool,
                     ev: float, rng: np.random.Generator, motion_px: np.ndarray | None = None,
                     jpeg_quality: int | None = None, veil: Veil | None = None) -> Composited:
    """Composite the layers into ``image_rgb`` (H, W, 3) uint8 (with ``match_camera``, seen through the
    image's ``veil`` (haze and veiling glare at the object's depth, :mod:`.veil`), blurred and noised
    like the image around the object, measured locally: blur and noise vary over an image; smeared along
    ``motion_px`` (2,) pixels, the object's image motion during the exposure; its JPEG blocks re-encoded at
    ``jpeg_quality``, the source file's)."""
    H, W = image_rgb.shape[:2]
    image = image_rgb.copy()
    if layers.box is None:
        return Composited(image, None, np.zeros((0, 0, 3), np.float32), np.ones((0, 0), np.float32), None)
    box, effects = layers.box, None
    if match_camera:
        # Blur and noise are measured only for an object with a pixel to match: of an object whose shadow alone
        # reaches the image nothing is blurred or noised (the same bytes without the measurement).
        g = CAMERA_EFFECTS_MARGIN_PX
        if object_drawn(layers):
            effects = estimate_camera_effects(image_rgb[max(box.y0 - g, 0) : box.y1 + g,
                                                        max(box.x0 - g, 0) : box.x1 + g])
        blur_sigma_px = 0.0 if effects is None else effects.blur_sigma_px
        noise_sigma = 0.0 if effects is None else effects.noise_sigma
        kernel = motion_kernel(np.zeros(2) if motion_px is None else motion_px)
        box = box.grown(int(np.ceil(3 * blur_sigma_px)) + kernel.shape[0] // 2, camera)  # the blurred rim
    ub = box.slices
    L = layers
    rad, ratio, mask = L.crop("radiance_premult", box), L.crop("ratio_rgb", box), L.crop("mask", box)
    if not match_camera:
        image[ub] = composite(image_rgb[ub], rad, mask, L.crop("visibility", box), ratio, ev)
    else:  # the veil, blur the visible object layer like the image, composite, then add the image's noise
        seen = rad if veil is None else veil.apply(rad, L.crop("coverage", box), L.crop("depth_m", box))
        obj_b, mask_b = blur_object_layer(seen * L.crop("visibility", box)[..., None], mask, blur_sigma_px)
        del seen
        if kernel.size > 1:  # motion blur: a line kernel along the object's image motion
            smear = lambda a: cv2.filter2D(np.ascontiguousarray(a, np.float32), -1, kernel,  # noqa: E731
                                           borderType=cv2.BORDER_CONSTANT)
            obj_b, mask_b = smear(obj_b), np.clip(smear(mask_b), 0.0, 1.0)
        shadow = ratio
        if veil is not None and L.scene_depth_m is not None:  # the haze in front of the ground is not shadowed
            shadow = veil.shadow_ratio(ratio, image_rgb[ub], L.scene_depth_m[ub], ev)
        image[ub] = composite(image_rgb[ub], obj_b, mask_b, np.ones_like(mask_b), shadow, ev)
        del obj_b, shadow
        sigma = noise_sigma
        if jpeg_quality is not None and effects is not None:  # the re-encoding below removes part of the added
            for _ in range(3):                                 # noise: add more
                sigma = noise_sigma / jpeg_noise_survival(jpeg_quality, sigma)
        image[ub] = add_object_noise(image[ub], mask_b, sigma, rng)
        if jpeg_quality is not None:
            touched = np.zeros((H, W), bool)
            touched[ub] = mask_b > 1.0 / 255.0
            image = jpeg_round_trip(image, touched, jpeg_quality)
    # the outputs inside the changed box (the full frame on access), allocated once the composite's buffers are gone
    cov = L.crop("coverage", box)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        obj_rad = np.where(cov > 0, rad / cov, 0.0).astype(np.float32, copy=False)
    return Composited(image, box, obj_rad, luminance(ratio).astype(np.float32, copy=False), effects)
