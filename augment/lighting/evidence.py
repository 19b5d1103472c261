"""Evidence from one image for the lighting: the downscaled linear image, its ground, its sky, object shadows.

All on a copy of the image downscaled to <= ``WORK_WIDTH`` px wide, in linear HDR (``ldr_uint8_to_hdr``, the
contract's camera response at EV 0); rays are camera-frame unit vectors (OpenCV), ``up_cam`` the gravity up in
the camera frame.

* **Ground** (:func:`ground_evidence`): grey (low-chroma) pixels whose ray hits the ground plane (camera
  ``camera_height_m`` above it) 4-40 m away and within 8 m laterally. Their log-luminance is split in two by
  Otsu's threshold; if the split is clearly bimodal (separation ratio eta >= 0.75, both classes >= 8 %,
  contrast >= 1.8) the upper class is "sunlit" and the lower "shadow".
* **Sky** (:func:`sky_mask`, :func:`sky_evidence`): pixels at least 3 deg above the horizon, bright, smooth (low
  gradient), in regions touching the top of the image, not saturated; their median level and blue/red ratio.
* **Object shadows** (:func:`box_shadow_evidence`): the road inside each annotated object's cast shadow (its box
  projected along the sun's rays onto the ground under it) against a ring of road around it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numpy as np
import shapely
from shapely.ops import unary_union

from ...datasets.sample import Box
from ..core import (PinholeCamera, check_shape, clipped_to_lower_bound, ldr_uint8_to_hdr, luminance, project_points,
                    scale_intrinsics)

WORK_WIDTH = 480
SKY_MIN_ELEVATION_DEG = 3.0
# a bright smooth region with LiDAR returns in it is a surface (pale or glass facade), not sky: at least this
# many returns, at least this many per pixel of the region (the sky's own edges catch a stray return or two)
SKY_SURFACE_MIN_HITS = 5
SKY_SURFACE_MIN_DENSITY = 5e-3
SKY_MIN_UNCLIPPED_FRACTION = 0.15
SURFACE_MIN_RANGE_M = 2.0  # nearer returns (the ego car, the camera's own mount) say nothing about the sky
SATURATED_LDR = 0.97


@dataclass(frozen=True)
class PreparedImage:
    """The downscaled image and its pixel rays.

    Attributes:
        hdr: (h, w, 3) float64 linear radiance (image scale).
        ldr: (h, w, 3) float64 in [0, 1].
        rays_cam: (h, w, 3) unit camera-frame rays of the pixel centres.
        elevation: (h, w) rad of each ray above the horizon.
        K: (3, 3) intrinsics of the downscaled image.
        surface_uv: (N, 2) pixels of LiDAR returns (surfaces) in this image, or None.
        rgb_uint8: (h, w, 3) uint8 the downscaled image itself (:func:`downscale_image` of the input at
            ``WORK_WIDTH``), or None; later stages at the same width reuse it instead of downscaling again.
    """

    hdr: np.ndarray
    ldr: np.ndarray
    rays_cam: np.ndarray
    elevation: np.ndarray
    K: np.ndarray
    surface_uv: np.ndarray | None = None
    rgb_uint8: np.ndarray | None = None

    @cached_property
    def ldr_max(self) -> np.ndarray:
        """(h, w) the largest channel of ``ldr`` (computed once)."""
        return np.maximum(np.maximum(self.ldr[..., 0], self.ldr[..., 1]), self.ldr[..., 2])

    @cached_property
    def clipped(self) -> np.ndarray:
        """(h, w) bool, some channel is at or above ``SATURATED_LDR`` (its radiance is a lower bound)."""
        return self.ldr_max >= SATURATED_LDR

    @cached_property
    def sky(self) -> np.ndarray:
        """(h, w) bool :func:`sky_mask` with the default thresholds, LiDAR surfaces excluded (computed once)."""
        mask = sky_mask(self.ldr, self.elevation, surface_uv=self.surface_uv)
        mask.flags.writeable = False
        return mask


def downscale_image(image_rgb: np.ndarray, K: np.ndarray, max_width: int) -> tuple[np.ndarray, np.ndarray]:
    """The image shrunk (area filter) to at most ``max_width`` pixels wide, and its intrinsics."""
    H, W = image_rgb.shape[:2]
    f = min(1.0, max_width / W)
    w, h = max(int(round(W * f)), 8), max(int(round(H * f)), 8)
    small = cv2.resize(np.ascontiguousarray(image_rgb), (w, h), interpolation=cv2.INTER_AREA)
    return small, scale_intrinsics(K, w / W, h / H)


_UINT8_TO_LDR = np.arange(256, dtype=np.float64) / 255.0  # each uint8 level as an LDR float (a table: no division)


@lru_cache(maxsize=16)
def _pixel_rays(K_bytes: bytes, w: int, h: int) -> np.ndarray:
    """(h, w, 3) read-only unit rays of a pinhole camera (intrinsics as ``K.tobytes()``), cached: a camera's
    images share them."""
    rays = PinholeCamera(np.frombuffer(K_bytes, np.float64).reshape(3, 3).copy(), w, h).rays()
    rays.flags.writeable = False
    return rays


def prepare_image(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray,
                  lidar_points_cam: np.ndarray | None = None) -> PreparedImage:
    """The image downscaled to ``WORK_WIDTH``, linearised, with its rays and the pixels LiDAR returns land on.

    Args:
        image_rgb: (H, W, 3) uint8 RGB.
        K: (3, 3) intrinsics of ``image_rgb``.
        up_cam: (3,) unit gravity up, camera frame.
        lidar_points_cam: (N, 3) LiDAR points in this camera's frame (metres), or None.
    """
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    check_shape(K, (3, 3), "K")
    small, Ks = downscale_image(image_rgb, K, WORK_WIDTH)
    h, w = small.shape[:2]
    rays = _pixel_rays(np.ascontiguousarray(Ks, np.float64).tobytes(), w, h)
    elevation = np.arcsin(np.clip(rays @ up_cam, -1.0, 1.0))
    surface_uv = None
    if lidar_points_cam is not None:
        pts = np.asarray(lidar_points_cam, dtype=np.float64)
        pts = pts[np.linalg.norm(pts, axis=1) >= SURFACE_MIN_RANGE_M]
        uv, _ = project_points(Ks, pts)
        surface_uv = uv[np.isfinite(uv).all(axis=1)]
    small.flags.writeable = False
    return PreparedImage(ldr_uint8_to_hdr(small).astype(np.float64), _UINT8_TO_LDR[small], rays, elevation, Ks,
                         surface_uv, small)


def box_shadow_evidence(work: PreparedImage, T_cam_from_global: np.ndarray, boxes: list[Box],
                        sun_dir_global: np.ndarray) -> dict | None:
    """Lit / shadowed road next to annotated objects whose cast shadows follow from their boxes and the sun.

    Each box (4-40 m ahead, >= 1 m tall) casts its shadow on the ground plane under it (its corners projected
    along the sun's rays); the road inside that shadow and in a ring 0.7-2.5 m around it (outside every box's
    shadow and image silhouette) is compared.

    Returns None (sun below ~8 deg, no usable object) or, over the objects with >= 12 pixels in both:
    ``objects`` (count), ``contrast`` and ``lit`` (the largest lit/shadow luminance ratio and that object's
    lit road median), and per object ``per_object_contrast``, ``per_object_lit`` and ``per_object_token`` (the
    box's annotation token: an object seen by several cameras is one object).
    """
    if sun_dir_global[2] < np.sin(np.radians(8.0)) or not boxes:
        return None
    h, w = work.hdr.shape[:2]
    lum = luminance(work.hdr)
    sun = sun_dir_global / np.linalg.norm(sun_dir_global)
    shadows, silhouettes, items = [], np.zeros((h, w), np.uint8), []
    R, t = T_cam_from_global[:3, :3], T_cam_from_global[:3, 3]
    for box in boxes:
        if box.wlh[2] < 1.0:
            continue
        # every corner's depth is within half the box's diagonal of its centre's: far outside the depth window
        # (no corner can pass the test below) the corners are not worked out
        depth, reach = float(R[2] @ box.center + t[2]), 0.5 * float(np.linalg.norm(box.wlh))
        if depth + reach < 4.0 or depth - reach > 40.0:
            continue
        corners = box.corners()
        c_cam = (R @ corners.T).T + t
        if np.any(c_cam[:, 2] < 1.0) or not 4.0 <= np.median(c_cam[:, 2]) <= 40.0:
            continue
        z0 = corners[:, 2].min()
        ground = corners - sun[None] * ((corners[:, 2] - z0) / sun[2])[:, None]
        shadow = shapely.multipoints(ground[:, :2]).convex_hull
        uv = (c_cam @ work.K.T)[:, :2] / c_cam[:, 2:3]
        hull = cv2.convexHull(np.round(uv).astype(np.int32))
        cv2.fillConvexPoly(silhouettes, hull, 1)
        shadows.append(shadow)
        items.append((shadow, z0, box.token))
    if not items:
        return None
    all_shadows = unary_union(shadows)

    free = (silhouettes == 0) & ~work.clipped
    ratios, lit_values, tokens = [], [], []
    for shadow, z0, token in items:  # each region rasterised in its own window of the image (its pixels' box)
        mask, win = _rasterise_ground_window(shadow, z0, T_cam_from_global, work.K, (h, w))
        in_shadow = mask & free[win]
        if in_shadow.sum() < 12:
            continue
        ring = shadow.buffer(2.5).difference(shadow.buffer(0.7)).difference(all_shadows)
        mask, lit_win = _rasterise_ground_window(ring, z0, T_cam_from_global, work.K, (h, w))
        lit = mask & free[lit_win]
        if lit.sum() >= 12:
            shadow_med = max(float(np.median(lum[win][in_shadow])), 1e-9)
            lit_med = float(np.median(lum[lit_win][lit]))
            ratios.append(lit_med / shadow_med)
            lit_values.append(lit_med)
            tokens.append(token)
    if not ratios:
        return None
    # The strongest contrast (and its lit road) is kept for the callers that want the single best object;
    # the decision (parametric.cloud_from_evidence) uses the per-object lists.
    best = int(np.argmax(ratios))
    return {"objects": len(ratios), "contrast": float(ratios[best]), "lit": float(lit_values[best]),
            "per_object_contrast": [float(r) for r in ratios], "per_object_lit": [float(v) for v in lit_values], "per_object_token": tokens}


def _rasterise_ground_window(poly, z0: float, T_cam_from_global: np.ndarray, K: np.ndarray,
                             shape: tuple[int, int]) -> tuple[np.ndarray, tuple[slice, slice]]:
    """:func:`_rasterise_ground` in the window of the image that can hold its pixels: (the window's mask (hw, ww)
    bool, the window (rows, columns) as slices of the image); every pixel outside it is False. The same pixels
    as the whole image's mask (the integer vertices are shifted by the window's corner: the fill is the same)."""
    empty = (np.zeros((0, 0), bool), (slice(0, 0), slice(0, 0)))
    rings = []
    polys = [poly] if poly.geom_type == "Polygon" else list(getattr(poly, "geoms", []))
    for pg in polys:
        if pg.is_empty or pg.geom_type != "Polygon":
            continue
        for ring, value in [(pg.exterior, 1)] + [(r, 0) for r in pg.interiors]:
            xy = np.asarray(ring.coords)
            pts = np.concatenate([xy, np.full((len(xy), 1), z0)], axis=1)
            pc = (T_cam_from_global[:3, :3] @ pts.T).T + T_cam_from_global[:3, 3]
            if np.any(pc[:, 2] < 0.5):
                return empty
            uv = (pc @ K.T)[:, :2] / pc[:, 2:3]
            rings.append((np.round(uv).astype(np.int32), value))
    if not rings:
        return empty
    h, w = shape
    outer = np.concatenate([uv for uv, value in rings if value == 1])
    c0, r0 = np.clip(outer.min(axis=0), 0, [w, h])
    c1, r1 = np.clip(outer.max(axis=0).astype(np.int64) + 1, 0, [w, h])
    if c1 <= c0 or r1 <= r0:
        return empty
    mask = np.zeros((int(r1 - r0), int(c1 - c0)), np.uint8)
    shift = np.array([c0, r0], np.int32)
    for uv, value in rings:
        cv2.fillPoly(mask, [uv - shift], value)
    return mask > 0, (slice(int(r0), int(r1)), slice(int(c0), int(c1)))


def _rasterise_ground(poly, z0: float, T_cam_from_global: np.ndarray, K: np.ndarray,
                      shape: tuple[int, int]) -> np.ndarray:
    """(h, w) bool pixels of a shapely (multi)polygon on the ground plane z = ``z0`` (global frame), holes
    excluded; all False if a vertex is behind (or within 0.5 m of) the camera."""
    mask = np.zeros(shape, np.uint8)
    polys = [poly] if poly.geom_type == "Polygon" else list(getattr(poly, "geoms", []))
    for pg in polys:
        if pg.is_empty or pg.geom_type != "Polygon":
            continue
        for ring, value in [(pg.exterior, 1)] + [(r, 0) for r in pg.interiors]:
            xy = np.asarray(ring.coords)
            pts = np.concatenate([xy, np.full((len(xy), 1), z0)], axis=1)
            pc = (T_cam_from_global[:3, :3] @ pts.T).T + T_cam_from_global[:3, 3]
            if np.any(pc[:, 2] < 0.5):
                return np.zeros(shape, bool)
            uv = (pc @ K.T)[:, :2] / pc[:, 2:3]
            cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], value)
    return mask > 0


def otsu_log(values: np.ndarray) -> tuple[float, float, float, float]:
    """Otsu split of log values: (eta, weight of the lower class, mean lo, mean hi) (log domain)."""
    hist, edges = np.histogram(values, bins=64)
    centres = 0.5 * (edges[:-1] + edges[1:])
    p = hist / max(hist.sum(), 1)
    w0 = np.cumsum(p)
    m = np.cumsum(p * centres)
    mt = m[-1]
    w1 = 1.0 - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        sb = (mt * w0 - m) ** 2 / (w0 * w1)
    sb[~np.isfinite(sb)] = 0.0
    k = int(np.argmax(sb))
    var = float(p @ (centres - mt) ** 2)
    eta = float(sb[k] / var) if var > 0 else 0.0
    thr = edges[k + 1]
    lo, hi = values[values < thr], values[values >= thr]
    if len(lo) == 0 or len(hi) == 0:
        return 0.0, 0.0, float(np.median(values)), float(np.median(values))
    return eta, len(lo) / len(values), float(np.median(lo)), float(np.median(hi))


def ground_evidence(work: PreparedImage, up_cam: np.ndarray, camera_height_m: float) -> dict | None:
    """Sunlit / shadow / median ground luminance, or None when too little ground is visible."""
    cos_down = -(work.rays_cam @ up_cam)  # > 0 for rays going down
    down = cos_down > 1e-3
    dist = camera_height_m / np.maximum(cos_down, 1e-3)  # along the ray to the ground (rays going down)
    lateral = np.abs(work.rays_cam[..., 0] * dist)
    horizontal = np.sqrt(np.maximum(dist**2 - camera_height_m**2, 0.0))
    # Clipped pixels stay in, at the saturation level (a lower bound, above every unclipped value): the sunlit
    # road's brightest part clips first, and leaving it out would lower the lit median as the exposure rises;
    # kept, the medians are exact while fewer than half of a class is clipped (censored medians).
    mask = down & (horizontal > 4.0) & (horizontal < 40.0) & (lateral < 8.0)
    # Roads are grey: drop saturated colours (vegetation, barriers, painted cars).
    ldr = work.ldr
    ldr_min = np.minimum(np.minimum(ldr[..., 0], ldr[..., 1]), ldr[..., 2])
    chroma = (work.ldr_max - ldr_min) / np.maximum(work.ldr_max, 1e-3)
    grey = mask & (chroma < 0.25)
    if grey.sum() >= 0.3 * mask.sum():
        mask = grey
    if mask.sum() < 50:
        return None
    lum = np.maximum(luminance(clipped_to_lower_bound(work.hdr[mask], ldr[mask])), 1e-6)
    log_lum = np.log(lum)
    eta, w_lo, mu_lo, mu_hi = otsu_log(log_lum)
    contrast = float(np.exp(mu_hi - mu_lo))
    bimodal = eta >= 0.75 and 0.08 <= w_lo <= 0.92 and contrast >= 1.8
    return {
        "pixels": int(mask.sum()),
        "median": float(np.median(lum)),
        "lit": float(np.exp(mu_hi)) if bimodal else float(np.median(lum)),
        "shadow": float(np.exp(mu_lo)) if bimodal else float(np.median(lum)),
        "contrast": contrast if bimodal else 1.0,
        "otsu_eta": eta,
        "shadow_fraction": float(w_lo) if bimodal else 0.0,
        "bimodal": bool(bimodal),
    }


def sky_mask(ldr: np.ndarray, elevation: np.ndarray, min_elevation_deg: float = SKY_MIN_ELEVATION_DEG,
             min_lum: float = 0.3, bright_percentile: float = 50.0, max_grad: float = 0.12,
             surface_uv: np.ndarray | None = None) -> np.ndarray:
    """(h, w) bool: bright, smooth pixels above ``min_elevation_deg`` in regions that touch the top of the image.

    ``ldr`` (h, w, 3) floats in [0, 1]; ``elevation`` (h, w) rad of each pixel's ray above the horizon.
    Bright = luminance >= max(``min_lum``, the ``bright_percentile`` of the pixels above the horizon);
    smooth = blurred Sobel gradient < ``max_grad``. ``surface_uv`` (N, 2): pixels where LiDAR returns land;
    a region holding ``SKY_SURFACE_MIN_HITS`` of them (and ``SKY_SURFACE_MIN_DENSITY`` per pixel) is a pale
    or glass facade, not sky.
    """
    lum_ldr = luminance(ldr)
    gx = cv2.Sobel(lum_ldr, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(lum_ldr, cv2.CV_64F, 0, 1, ksize=3)
    grad = cv2.GaussianBlur(np.hypot(gx, gy), (5, 5), 0)
    above = elevation > np.radians(min_elevation_deg)
    if not above.any():
        return above
    bright = lum_ldr >= max(min_lum, float(np.percentile(lum_ldr[above], bright_percentile)))
    candidate = (above & bright & (grad < max_grad)).astype(np.uint8)
    n, labels = cv2.connectedComponents(candidate, connectivity=4)
    top_labels = np.unique(labels[0][candidate[0] > 0])
    top_labels = top_labels[top_labels > 0]
    if surface_uv is not None and len(surface_uv) and len(top_labels):
        h, w = labels.shape
        iu, iv = np.round(surface_uv[:, 0]).astype(np.int64), np.round(surface_uv[:, 1]).astype(np.int64)
        inside = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
        hits = np.bincount(labels[iv[inside], iu[inside]], minlength=n)
        size = np.bincount(labels.ravel(), minlength=n)
        surface = (hits >= SKY_SURFACE_MIN_HITS) & (hits >= SKY_SURFACE_MIN_DENSITY * size)
        top_labels = top_labels[~surface[top_labels]]
    return np.isin(labels, top_labels) & (candidate > 0)


def image_sky_mask(work: PreparedImage) -> np.ndarray:
    """(h, w) bool :func:`sky_mask` of a prepared image with the default thresholds (LiDAR surfaces excluded);
    computed once per image (``work.sky``), read-only."""
    return work.sky


def sky_evidence(work: PreparedImage, sky_mask: np.ndarray) -> dict | None:
    """The sky's fraction of the image and saturated fraction; with enough unclipped sky its median luminance
    (``median_lum``), blue/red ratio and the unclipped pixels (``mask``); None with fewer than 30 sky pixels."""
    frac = float(sky_mask.mean())
    if sky_mask.sum() < 30:
        return None
    unsat = sky_mask & ~work.clipped
    out = {"fraction": frac, "saturated_fraction": float(1.0 - unsat.sum() / sky_mask.sum())}
    # colour and level need a sizeable unclipped part of the sky: a few unclipped pixels of a clipped sky are
    # its horizon haze, not its colour
    if unsat.sum() >= 20 and unsat.sum() >= SKY_MIN_UNCLIPPED_FRACTION * sky_mask.sum():
        rgb = work.hdr[unsat]
        out["mask"] = unsat
        out["median_lum"] = float(np.median(luminance(rgb)))
        out["blue_red"] = float(np.median(rgb[:, 2]) / max(np.median(rgb[:, 0]), 1e-9))
    return out

