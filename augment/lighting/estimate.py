"""Lighting estimation: the public entry points and the parametric first level (ephemeris sun + fitted sky).

Levels (see :mod:`.levels`):

* ``L0`` — the paper's "no light" baseline: a constant dome with the image's mean linear radiance.
* ``L1`` — sun direction from the ephemeris (location + timestamp), sky from :mod:`.sky`; its
  ``scale`` (physical -> image units), ``cloud_cover`` (hence sun visibility) are fitted to the image.
* ``L2`` / ``L3`` — L1's sun + a sky dome corrected by the image + a VSG volume near the placement / around
  the camera (:mod:`.multiview`, :mod:`.build`, :mod:`.volume`); :meth:`LightingEstimate.light_at` gives the
  local light at a point. ``auto`` picks the cheapest sufficient level (:mod:`.levels`).

Evidence (computed on a copy of the image downscaled to <= 480 px wide, in linear HDR =
``ldr_uint8_to_hdr``, i.e. the contract's camera response at EV 0):

* **Ground**: grey (low-chroma) pixels whose ray hits the ground plane (camera ``camera_height_m``
  above it, up from the camera pose) 4-40 m away and within 8 m laterally. Their log-luminance is split in two by Otsu's
  threshold; if the split is clearly bimodal (separation ratio eta >= 0.75, both classes >= 8 %,
  contrast >= 1.8) the upper class is "sunlit" and the lower "shadow" and
  ``contrast = lit / shadow``. A horizontal Lambertian ground of albedo ``GROUND_ALBEDO`` has
  ``L_lit = scale * albedo * (E_sun_h + E_sky_h) / pi`` and ``L_shadow = scale * albedo * E_sky_h / pi``,
  so the contrast fixes the sun visibility (cloud cover) and ``L_lit`` the scale.
* **Sky**: pixels at least 3 deg above the horizon, bright, smooth (low gradient), in regions touching
  the top of the image, not saturated. Their blue/red ratio against the model's clear-sky and overcast
  ratios gives a second cloud-cover estimate; their brightness against the model gives ``scale_sky``.
* **Object shadows** (when the sample's annotated boxes are given): the road inside each object's cast
  shadow (its box projected along the sun's rays onto the ground under it) against a ring of road around
  it; the strongest contrast (>= ``OBJECT_SHADOW_MIN_CONTRAST``) proves a visible sun and outranks the
  ground split (a faint one proves nothing: the object may stand in a building's shadow).
* Without ground shadows, the ground median pins the scale; if both the "all sunlit" and "all in
  shadow" readings are possible, the one closer to the sky's scale wins.

The result is on the image's scale: a grey Lambertian object with the road's albedo rendered under
``light_cam`` and passed through ``hdr_to_ldr`` comes out as bright as the sunlit road.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ..core import (
    check_shape,
    ldr_uint8_to_hdr,
    luminance,
    pixel_rays,
    project_points,
    scale_intrinsics,
)
from .light import DistantLight
from .sky import (
    OVERCAST_RGB,
    make_sky_light,
    sky_horizontal_irradiance,
    sky_radiance,
    sun_horizontal_irradiance,
    sun_visibility,
)
from .sun import location_latlon, sun_direction_global, up_direction_camera

GROUND_ALBEDO = 0.15  # assumed road albedo (asphalt 0.1-0.2)
DEFAULT_TURBIDITY = 3.0
DEFAULT_CAMERA_HEIGHT_M = 1.5
ENVMAP_HEIGHT, ENVMAP_WIDTH = 128, 256
SKY_MIN_ELEVATION_DEG = 3.0
# a bright smooth region with LiDAR returns in it is a surface (pale or glass facade), not sky: at least this
# many returns, at least this many per pixel of the region (the sky's own edges catch a stray return or two)
SKY_SURFACE_MIN_HITS = 5
SKY_SURFACE_MIN_DENSITY = 5e-3
SKY_MIN_UNCLIPPED_FRACTION = 0.15
SURFACE_MIN_RANGE_M = 2.0  # nearer returns (the ego car, the camera's own mount) say nothing about the sky
SATURATED_LDR = 0.97
OBJECT_SHADOW_MIN_CONTRAST = 1.5  # an object's shadow at least this marked proves a visible sun
WORK_WIDTH = 480
CAMERA_CLEAR_BLUE_RED = 1.35
CLOUD_GRID = np.linspace(0.0, 1.0, 41)

# Lit/shadow ground contrast above which a night timestamp contradicts the image (sun shadows).
NIGHT_SUSPICIOUS_CONTRAST = 2.5

@dataclass(frozen=True)
class LightingEstimate:
    """The lighting of one image, in its camera frame and on its radiometric scale.

    Attributes:
        light_cam: distant light: environment (camera-frame equirect, sun excluded) + sun, camera frame,
            image units. For L2/L3 this is the sky dome alone (what reaches a point with nothing around it).
        sun_dir_cam: (3,) unit vector towards the sun (camera frame), or None (night / unknown).
        sun_source: "ephemeris" | "image" | "none".
        sun_visibility: 0..1 fraction of the sun getting through clouds (0 when there is no sun).
        level: "L0" | "L1" | "L2" | "L3" (for ``auto``: the level chosen).
        reason: why this level, which evidence was used, which fallbacks were taken.
        params: turbidity, cloud_cover, scale, evidence numbers (JSON-serialisable).
        timing_s: seconds per step.
        hybrid: the sample's :class:`~.volume.HybridLighting` (volume frame, reference scale), L2/L3 only.
        T_vol_from_cam: (4, 4) this camera -> the volume frame (L2/L3 only).
        radiometric_scale: this image's units per unit of ``hybrid`` radiance (its exposure ratio).
    """

    light_cam: DistantLight
    sun_dir_cam: np.ndarray | None
    sun_source: str
    sun_visibility: float
    level: str
    reason: str
    params: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    hybrid: object | None = None
    T_vol_from_cam: np.ndarray | None = None
    radiometric_scale: float = 1.0

    def light_at(self, point_cam: np.ndarray, height: int = ENVMAP_HEIGHT, width: int = ENVMAP_WIDTH) -> DistantLight:
        """The local distant light (camera frame, image scale) at a 3D point (3,) in the camera frame, metres.

        L0/L1: ``light_cam`` at every point. L2/L3: the local environment map of the volume + sky dome seen
        from the point (Eq. 1 over all directions, ``height`` x ``width``) and the sun attenuated by its
        transmittance through the volume from that point. A point inside solid voxels (e.g. on the ground) is
        first moved up to free space.
        """
        p = np.asarray(point_cam, dtype=np.float64)
        check_shape(p, (3,), "point_cam")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"point_cam must be finite, got {p.tolist()}")
        if self.hybrid is None or self.hybrid.params is None:
            return self.light_cam
        T = np.asarray(self.T_vol_from_cam)
        p_vol = self.hybrid.lift_out_of_solid(T[:3, :3] @ p + T[:3, 3])
        from .volume import world_to_frame_envmap  # torch: only with a volume

        env_world = self.hybrid.envmap_at_cached(p_vol, height, width)  # shared by the cameras seeing the point
        env = world_to_frame_envmap(env_world, T[:3, :3], height, width) * np.float32(self.radiometric_scale)
        sun = self.light_cam.sun
        if sun is not None:
            tau = self.hybrid.sun_transmittance(p_vol)
            sun = replace(sun, irradiance_rgb=np.asarray(sun.irradiance_rgb) * tau, visibility=sun.visibility * tau)
        return DistantLight(env.astype(np.float32), sun)


# ----------------------------------------------------------------------------- evidence


@dataclass(frozen=True)
class _Work:
    """The downscaled image and its pixel rays."""

    hdr: np.ndarray  # (h, w, 3) float64 linear
    ldr: np.ndarray  # (h, w, 3) float64 in [0, 1]
    rays_cam: np.ndarray  # (h, w, 3) unit camera-frame rays
    elevation: np.ndarray  # (h, w) rad above the horizon
    K: np.ndarray  # (3, 3) intrinsics of the downscaled image
    surface_uv: np.ndarray | None = None  # (N, 2) pixels of LiDAR returns (surfaces) in this image, or None


def downscale_image(image_rgb: np.ndarray, K: np.ndarray, max_width: int) -> tuple[np.ndarray, np.ndarray]:
    """The image shrunk (area filter) to at most ``max_width`` pixels wide, and its intrinsics."""
    H, W = image_rgb.shape[:2]
    f = min(1.0, max_width / W)
    w, h = max(int(round(W * f)), 8), max(int(round(H * f)), 8)
    small = cv2.resize(np.ascontiguousarray(image_rgb), (w, h), interpolation=cv2.INTER_AREA)
    return small, scale_intrinsics(K, w / W, h / H)


def _prepare(image_rgb: np.ndarray, K: np.ndarray, up_cam: np.ndarray,
             lidar_points_cam: np.ndarray | None = None) -> _Work:
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    check_shape(K, (3, 3), "K")
    small, Ks = downscale_image(image_rgb, K, WORK_WIDTH)
    h, w = small.shape[:2]
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rays = pixel_rays(Ks, np.stack([u.ravel(), v.ravel()], axis=1)).reshape(h, w, 3)
    elevation = np.arcsin(np.clip(rays @ up_cam, -1.0, 1.0))
    surface_uv = None
    if lidar_points_cam is not None:
        pts = np.asarray(lidar_points_cam, dtype=np.float64)
        pts = pts[np.linalg.norm(pts, axis=1) >= SURFACE_MIN_RANGE_M]
        uv, _ = project_points(Ks, pts)
        surface_uv = uv[np.isfinite(uv).all(axis=1)]
    return _Work(ldr_uint8_to_hdr(small).astype(np.float64), small / 255.0, rays, elevation, Ks, surface_uv)


def _box_shadow_evidence(work: _Work, T_cam_from_global: np.ndarray, boxes, sun_dir_global: np.ndarray) -> dict | None:
    """Lit / shadowed road next to annotated objects whose cast shadows follow from their boxes and the sun.

    Each box (4-40 m ahead, >= 1 m tall) casts its shadow on the ground plane under it (its corners projected
    along the sun's rays); the road inside that shadow and in a ring 0.7-2.5 m around it (outside every box's
    shadow and image silhouette) is compared. Returns the largest lit/shadow luminance ratio over objects with >= 12 pixels in both and that
    object's lit road median, or None (sun below ~8 deg, no usable object).
    """
    from shapely.geometry import MultiPoint
    from shapely.ops import unary_union

    if sun_dir_global[2] < np.sin(np.radians(8.0)) or not boxes:
        return None
    h, w = work.hdr.shape[:2]
    lum = luminance(work.hdr)
    lum_ldr = work.ldr.max(axis=-1)
    sun = sun_dir_global / np.linalg.norm(sun_dir_global)
    shadows, silhouettes, items = [], np.zeros((h, w), np.uint8), []
    for box in boxes:
        corners = box.corners()
        if box.wlh[2] < 1.0:
            continue
        c_cam = (T_cam_from_global[:3, :3] @ corners.T).T + T_cam_from_global[:3, 3]
        if np.any(c_cam[:, 2] < 1.0) or not 4.0 <= np.median(c_cam[:, 2]) <= 40.0:
            continue
        z0 = corners[:, 2].min()
        ground = corners - sun[None] * ((corners[:, 2] - z0) / sun[2])[:, None]
        shadow = MultiPoint([tuple(p) for p in ground[:, :2]]).convex_hull
        uv = (c_cam @ work.K.T)[:, :2] / c_cam[:, 2:3]
        hull = cv2.convexHull(np.round(uv).astype(np.int32))
        cv2.fillConvexPoly(silhouettes, hull, 1)
        shadows.append(shadow)
        items.append((shadow, z0))
    if not items:
        return None
    all_shadows = unary_union(shadows)

    def rasterise(poly, z0) -> np.ndarray:
        mask = np.zeros((h, w), np.uint8)
        polys = [poly] if poly.geom_type == "Polygon" else list(getattr(poly, "geoms", []))
        for pg in polys:
            if pg.is_empty or pg.geom_type != "Polygon":
                continue
            for ring, value in [(pg.exterior, 1)] + [(r, 0) for r in pg.interiors]:
                xy = np.asarray(ring.coords)
                pts = np.concatenate([xy, np.full((len(xy), 1), z0)], axis=1)
                pc = (T_cam_from_global[:3, :3] @ pts.T).T + T_cam_from_global[:3, 3]
                if np.any(pc[:, 2] < 0.5):
                    return np.zeros((h, w), bool)
                uv = (pc @ work.K.T)[:, :2] / pc[:, 2:3]
                cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], value)
        return mask > 0

    free = (silhouettes == 0) & (lum_ldr < SATURATED_LDR)
    ratios, lit_values = [], []
    for shadow, z0 in items:
        in_shadow = rasterise(shadow, z0) & free
        ring = shadow.buffer(2.5).difference(shadow.buffer(0.7)).difference(all_shadows)
        lit = rasterise(ring, z0) & free
        if in_shadow.sum() >= 12 and lit.sum() >= 12:
            lit_med = float(np.median(lum[lit]))
            ratios.append(lit_med / max(float(np.median(lum[in_shadow])), 1e-9))
            lit_values.append(lit_med)
    if not ratios:
        return None
    # A visible shadow proves the sun; a faint one does not disprove it (the object may stand in a building's
    # shadow): the strongest contrast is the evidence, with the lit road of that object.
    best = int(np.argmax(ratios))
    return {"objects": len(ratios), "contrast": float(ratios[best]), "lit": float(lit_values[best]),
            "per_object_contrast": [float(r) for r in ratios]}


def _otsu_log(values: np.ndarray) -> tuple[float, float, float, float]:
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


def _ground_evidence(work: _Work, up_cam: np.ndarray, camera_height_m: float) -> dict | None:
    """Sunlit / shadow / median ground luminance, or None when too little ground is visible."""
    cos_down = -(work.rays_cam @ up_cam)  # > 0 for rays going down
    with np.errstate(divide="ignore"):
        dist = np.where(cos_down > 1e-3, camera_height_m / np.maximum(cos_down, 1e-3), np.inf)
    points = work.rays_cam * np.where(np.isfinite(dist), dist, 0.0)[..., None]
    lateral = np.abs(points[..., 0])
    horizontal = np.sqrt(np.maximum(dist**2 - camera_height_m**2, 0.0))
    mask = (horizontal > 4.0) & (horizontal < 40.0) & (lateral < 8.0) & np.isfinite(dist)
    mask &= work.ldr.max(axis=-1) < SATURATED_LDR
    # Roads are grey: drop saturated colours (vegetation, barriers, painted cars).
    chroma = (work.ldr.max(axis=-1) - work.ldr.min(axis=-1)) / np.maximum(work.ldr.max(axis=-1), 1e-3)
    grey = mask & (chroma < 0.25)
    if grey.sum() >= 0.3 * mask.sum():
        mask = grey
    if mask.sum() < 50:
        return None
    lum = np.maximum(luminance(work.hdr[mask]), 1e-6)
    log_lum = np.log(lum)
    eta, w_lo, mu_lo, mu_hi = _otsu_log(log_lum)
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


def _sky_mask(work: _Work) -> np.ndarray:
    return sky_mask(work.ldr, work.elevation, surface_uv=work.surface_uv)


def _sky_evidence(work: _Work, sky_mask: np.ndarray) -> dict | None:
    frac = float(sky_mask.mean())
    if sky_mask.sum() < 30:
        return None
    unsat = sky_mask & (work.ldr.max(axis=-1) < SATURATED_LDR)
    out = {"fraction": frac, "saturated_fraction": float(1.0 - unsat.sum() / sky_mask.sum())}
    # colour and level need a sizeable unclipped part of the sky: a few unclipped pixels of a clipped sky are
    # its horizon haze, not its colour
    if unsat.sum() >= 20 and unsat.sum() >= SKY_MIN_UNCLIPPED_FRACTION * sky_mask.sum():
        rgb = work.hdr[unsat]
        out["mask"] = unsat
        out["median_lum"] = float(np.median(luminance(rgb)))
        out["blue_red"] = float(np.median(rgb[:, 2]) / max(np.median(rgb[:, 0]), 1e-9))
    return out


# ----------------------------------------------------------------------------- fitting


def _cloud_from_contrast(contrast: float, e_sun_h: float, e_sky_h0: float, e_sky_h1: float) -> float:
    """Cloud cover whose model lit/shadow ratio ``1 + E_sun_h vis(c) / E_sky_h(c)`` is closest to ``contrast``."""
    c = CLOUD_GRID
    vis = np.array([sun_visibility(x) for x in c])
    e_sky = (1 - c) * e_sky_h0 + c * e_sky_h1
    model = 1.0 + e_sun_h * vis / np.maximum(e_sky, 1e-12)
    return float(c[np.argmin(np.abs(np.log(model) - np.log(max(contrast, 1.0))))])


def _l1_evidence(work: _Work, up_cam: np.ndarray, sun_dir_cam: np.ndarray, camera_height_m: float,
                 turbidity: float, box_shadows: dict | None = None) -> dict:
    """The image's evidence for L1 (object shadows, ground lit/shadow, sky colour and level) and the model's constants."""
    R_up = _up_rotation(up_cam)
    sun_up = R_up @ sun_dir_cam
    e_sun = float(luminance(sun_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky0 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 0.0)))
    e_sky1 = float(luminance(sky_horizontal_irradiance(sun_up, turbidity, 1.0)))
    ground = _ground_evidence(work, up_cam, camera_height_m)
    sky = _sky_evidence(work, _sky_mask(work))

    # Sky model at the observed sky pixels (for colour and scale).
    sky_clear_lum = sky_over_lum = None
    cloud_sky = None
    if sky is not None and "mask" in sky:
        dirs_up = work.rays_cam[sky["mask"]] @ R_up.T
        m0 = sky_radiance(dirs_up, sun_up, turbidity, 0.0)
        m1 = sky_radiance(dirs_up, sun_up, turbidity, 1.0)
        sky_clear_lum = float(np.median(luminance(m0)))
        sky_over_lum = float(np.median(luminance(m1)))
        br_clear = float(np.median(m0[:, 2]) / max(np.median(m0[:, 0]), 1e-9))
        # Cameras white-balance and desaturate the sky: a clear sky reads blue/red ~1.3-1.6, not the
        # model's ~2; cap the clear reference at CAMERA_CLEAR_BLUE_RED.
        br_ref = min(br_clear, CAMERA_CLEAR_BLUE_RED)
        br_over = float(OVERCAST_RGB[2] / OVERCAST_RGB[0]) - 0.03
        if br_ref - br_over > 0.1:
            cloud_sky = float(np.clip((br_ref - sky["blue_red"]) / (br_ref - br_over), 0.0, 1.0))
        sky = {k: v for k, v in sky.items() if k != "mask"} | {"model_blue_red_clear": br_clear}
    return {"e_sun": e_sun, "e_sky0": e_sky0, "e_sky1": e_sky1, "ground": ground, "sky": sky,
            "sky_clear_lum": sky_clear_lum, "sky_over_lum": sky_over_lum, "cloud_sky": cloud_sky,
            "box_shadows": box_shadows}


def _l1_cloud(ev: dict) -> tuple[float, str, str]:
    """Cloud cover from one image's evidence: (cloud, source, note); source ranks the evidence."""
    e_sun, ground, cloud_sky, sky = ev["e_sun"], ev["ground"], ev["cloud_sky"], ev["sky"]
    if e_sun <= 0:
        return (1.0 if cloud_sky is None else cloud_sky), "night", "sun below the horizon"
    boxes = ev.get("box_shadows")
    if boxes is not None and boxes["contrast"] >= OBJECT_SHADOW_MIN_CONTRAST:
        cloud = _cloud_from_contrast(boxes["contrast"], e_sun, ev["e_sky0"], ev["e_sky1"])
        return cloud, "object_shadows", (f"sun visibility from the road in/out of {boxes['objects']} annotated "
                                         f"objects' predicted shadows (contrast {boxes['contrast']:.2f})")
    if ground is not None and ground["bimodal"]:
        cloud = _cloud_from_contrast(ground["contrast"], e_sun, ev["e_sky0"], ev["e_sky1"])
        return cloud, "ground_contrast", f"sun visibility from ground lit/shadow contrast {ground['contrast']:.2f}"
    if cloud_sky is not None:
        return cloud_sky, "sky_colour", f"cloud cover from sky colour (blue/red {sky['blue_red']:.2f})"
    return 0.5, "assumed", "no shadow or sky-colour evidence: cloud cover 0.5 assumed"


def _l1_solve(ev: dict, cloud: float | None = None, cloud_note: str | None = None):
    """Returns (cloud_cover, scale, evidence dict, list of reason strings); ``cloud`` overrides the image's own."""
    e_sun, e_sky0, e_sky1 = ev["e_sun"], ev["e_sky0"], ev["e_sky1"]
    ground, sky = ev["ground"], ev["sky"]
    sky_clear_lum, sky_over_lum = ev["sky_clear_lum"], ev["sky_over_lum"]
    evidence: dict = {"ground": ground, "sky": sky}
    notes: list[str] = []
    boxes = ev.get("box_shadows")
    evidence["object_shadows"] = boxes
    if cloud is None:
        cloud, source, note = _l1_cloud(ev)
        notes.append(note)
    else:
        notes.append(cloud_note or f"cloud cover {cloud:.2f} given")

    vis = sun_visibility(cloud)
    e_sky_c = (1 - cloud) * e_sky0 + cloud * e_sky1
    e_lit = e_sun * vis + e_sky_c
    scale_sky = None
    if sky_clear_lum is not None:
        model_sky = (1 - cloud) * sky_clear_lum + cloud * sky_over_lum
        scale_sky = sky["median_lum"] / max(model_sky, 1e-12)
    scale_lit = scale_shadow = None
    if ground is not None:
        scale_lit = np.pi * ground["lit"] / (GROUND_ALBEDO * e_lit)
        scale_shadow = np.pi * ground["shadow"] / (GROUND_ALBEDO * e_sky_c)
    if boxes is not None and boxes["contrast"] >= OBJECT_SHADOW_MIN_CONTRAST and e_sun * vis > 0.5 * e_sky_c:
        scale = np.pi * boxes["lit"] / (GROUND_ALBEDO * e_lit)
        notes.append("scale from the sunlit road next to the objects")
    elif ground is not None and ground["bimodal"]:
        scale = scale_lit
        notes.append("scale from the sunlit ground")
    elif ground is not None:
        scale = scale_lit
        if scale_sky is not None and e_sun * vis > 0.5 * e_sky_c:
            if abs(np.log(scale_shadow / scale_sky)) < abs(np.log(scale_lit / scale_sky)):
                scale = scale_shadow
                notes.append("ground read as in shadow (closer to the sky's scale)")
        notes.append("scale from the ground median")
    elif scale_sky is not None:
        scale = scale_sky
        notes.append("no ground visible: scale from the sky")
    else:
        scale = None
    evidence.update(
        scale_from_ground_lit=scale_lit, scale_from_ground_shadow=scale_shadow, scale_from_sky=scale_sky,
        model_sun_horizontal=e_sun * vis, model_sky_horizontal=e_sky_c,
    )
    return cloud, scale, evidence, notes


def _up_rotation(up_cam: np.ndarray) -> np.ndarray:
    from .sky import rotation_up_from_frame

    return rotation_up_from_frame(up_cam, np.array([0.0, 0.0, 1.0]))


def _l0_light(hdr: np.ndarray) -> tuple[DistantLight, np.ndarray]:
    mean = hdr.reshape(-1, 3).mean(axis=0)
    env = np.broadcast_to(mean.astype(np.float32), (ENVMAP_HEIGHT, ENVMAP_WIDTH, 3)).copy()
    return DistantLight(env, None), mean


def _clean(obj):
    """JSON-friendly copy (numpy scalars -> floats, dicts/lists recursively)."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


# ----------------------------------------------------------------------------- public API


def estimate_lighting(view, location: str | None, level: str = "L1", *, lidar=None, boxes=None,
                      query_point_cam: np.ndarray | None = None) -> LightingEstimate:
    """Lighting of a ``CameraView`` (camera frame, image scale).

    Args:
        view: a :class:`streetaug.datasets.sample.CameraView` (image, K, poses, timestamp_us).
        location: the log's location (e.g. ``singapore-onenorth``) for the ephemeris; None if unknown.
        level: "L0" (constant dome of the image's mean radiance), "L1" (ephemeris sun + fitted sky),
            "L2" / "L3" (+ VSG volume near the placement / full volume), "auto" (see :mod:`.levels`).
        lidar: optional ``LidarSweep`` of the same sample (L2/L3 geometry; without it the ground plane and
            vertical facades alone).
        boxes: optional annotated ``Box`` objects (global frame) of the sample: the road in and out of their
            predicted shadows is evidence of the sun's visibility.
        query_point_cam: (3,) the placement (camera frame, metres) that L2 centres on and ``auto`` judges;
            default: the ground 15 m straight ahead.
    """
    from .levels import check_level

    check_level(level)
    if level in ("L2", "L3", "auto"):
        from .multiview import estimate_views_lighting

        return estimate_views_lighting([view], location, level, lidar=lidar, boxes=boxes,
                                       query_point_cam=query_point_cam).for_view(view)
    t0 = time.perf_counter()
    image = np.asarray(view.image)
    timing = {"decode": time.perf_counter() - t0}
    if level == "L0":
        return _estimate_l0(image, timing)
    fit = _l1_view_evidence(view, location, timing, boxes, lidar)
    return _l1_estimate(fit, timing)


def _estimate_l0(image: np.ndarray, timing: dict) -> LightingEstimate:
    t1 = time.perf_counter()
    light, mean = _l0_light(ldr_uint8_to_hdr(image))
    timing["fit"] = time.perf_counter() - t1
    timing["total"] = time.perf_counter() - t1
    return LightingEstimate(
        light, None, "none", 0.0, "L0", "L0: constant dome of the image's mean linear radiance",
        {"mean_radiance_rgb": mean.tolist()}, timing,
    )


@dataclass(frozen=True)
class _ViewL1:
    """One view's L1 inputs: geometry, ephemeris and image evidence (``ev`` None without a sun position)."""

    view: object
    location: str | None
    up_cam: np.ndarray
    camera_height_m: float
    sun_pos: object | None
    sun_dir_cam: np.ndarray | None
    fallback: str
    work: _Work | None
    ev: dict | None
    t_start: float


def _l1_view_evidence(view, location: str | None, timing: dict, boxes=None, lidar=None) -> _ViewL1:
    t0 = time.perf_counter()
    image = np.asarray(view.image)
    up_cam = up_direction_camera(view)
    cam_z = float(view.T_global_from_cam[2, 3] - view.T_global_from_ego[2, 3])
    camera_height_m = cam_z if 0.5 <= cam_z <= 4.0 else DEFAULT_CAMERA_HEIGHT_M
    sun_pos = None
    fallback = ""
    if location is None:
        fallback = "no location: ephemeris unavailable"
    elif view.timestamp_us is None or view.timestamp_us <= 0:
        fallback = "no timestamp: ephemeris unavailable"
    else:
        try:
            location_latlon(location)
            sun_pos = sun_direction_global(location, view.timestamp_us)
        except ValueError as exc:
            fallback = f"ephemeris unavailable ({exc})"
    if sun_pos is None:
        return _ViewL1(view, location, up_cam, camera_height_m, None, None, fallback, None, None, t0)
    R_cam_from_global = np.asarray(view.T_cam_from_global)[:3, :3]
    sun_dir_cam = R_cam_from_global @ sun_pos.direction_global
    sun_dir_cam = sun_dir_cam / np.linalg.norm(sun_dir_cam)
    lidar_cam = None if lidar is None else lidar.points_in(np.asarray(view.T_cam_from_global))
    work = _prepare(image, view.K, up_cam, lidar_cam)
    timing["prepare"] = time.perf_counter() - t0
    t2 = time.perf_counter()
    box_shadows = _box_shadow_evidence(work, np.asarray(view.T_cam_from_global), boxes, sun_pos.direction_global) \
        if boxes else None
    ev = _l1_evidence(work, up_cam, sun_dir_cam, camera_height_m, DEFAULT_TURBIDITY, box_shadows)
    timing["evidence"] = time.perf_counter() - t2
    return _ViewL1(view, location, up_cam, camera_height_m, sun_pos, sun_dir_cam, fallback, work, ev, t0)


def _l1_estimate(fit: _ViewL1, timing: dict, cloud: float | None = None, cloud_note: str | None = None) -> LightingEstimate:
    """The L1 estimate of one view from its evidence (``cloud`` overrides the view's own cloud cover)."""
    if fit.sun_pos is None:
        est = _estimate_diffuse(np.asarray(fit.view.image), fit.view.K, fit.up_cam, fit.camera_height_m,
                                fit.t_start, timing)
        return replace(est, reason=f"{fit.fallback}; {est.reason}")
    if fit.sun_pos.elevation_deg <= 0.0:
        return _night_estimate(fit, timing)
    t2 = time.perf_counter()
    up_cam, sun_dir_cam, sun_pos, work = fit.up_cam, fit.sun_dir_cam, fit.sun_pos, fit.work
    cloud, scale, evidence, notes = _l1_solve(fit.ev, cloud, cloud_note)
    night = sun_pos.elevation_deg <= 0.0
    if scale is None:
        mean_lum = float(luminance(work.hdr.reshape(-1, 3).mean(axis=0)))
        R_up = _up_rotation(up_cam)
        e = luminance(sky_horizontal_irradiance(R_up @ sun_dir_cam, DEFAULT_TURBIDITY, cloud))
        scale = np.pi * mean_lum / (GROUND_ALBEDO * max(float(e), 1e-12))
        notes.append("neither ground nor sky usable: scale from the image mean")
    timing["fit"] = time.perf_counter() - t2
    t3 = time.perf_counter()
    light = make_sky_light(
        sun_dir_cam, up_cam, DEFAULT_TURBIDITY, cloud, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, float(scale)
    )
    timing["envmap"] = time.perf_counter() - t3
    timing["total"] = time.perf_counter() - fit.t_start
    location = fit.location
    if night:
        reason = f"L1: sun {sun_pos.elevation_deg:.1f} deg below the horizon (night/twilight): no sun, dim sky; "
        source, sun_out, visibility = "none", None, 0.0
    else:
        reason = f"L1: sun from the ephemeris ({location}, elevation {sun_pos.elevation_deg:.1f} deg); "
        source, sun_out, visibility = "ephemeris", sun_dir_cam, sun_visibility(cloud)
    params = {
        "turbidity": DEFAULT_TURBIDITY,
        "cloud_cover": cloud,
        "scale": float(scale),
        "ground_albedo_assumed": GROUND_ALBEDO,
        "camera_height_m": fit.camera_height_m,
        "up_camera": up_cam.tolist(),
        "sky_sun_direction_camera": sun_dir_cam.tolist(),
        "sun_elevation_deg": sun_pos.elevation_deg,
        "sun_azimuth_deg": sun_pos.azimuth_deg,
        "location": location,
        "evidence": evidence,
    }
    return LightingEstimate(light, sun_out, source, visibility, "L1", reason + "; ".join(notes), _clean(params), timing)


def _night_estimate(fit: _ViewL1, timing: dict) -> LightingEstimate:
    """Sun below the horizon: no sun; the light is diffuse (twilight sky, street lights), so an
    overcast-shaped dome scaled to the image's ground, like the no-metadata path.

    A clear-sky model with the sun below the horizon is the wrong shape here, and fitting its tiny
    irradiance to the image's ground would blow the scale up.  When the image nevertheless shows hard
    sun shadows on the ground, the timestamp (or the location) is probably wrong: the reason says so.
    """
    est = _estimate_diffuse(np.asarray(fit.view.image), fit.view.K, fit.up_cam, fit.camera_height_m,
                            fit.t_start, timing)
    ground = (fit.ev or {}).get("ground") or {}
    how = est.reason.rsplit("; ", 1)[-1]
    reason = (f"L1: sun {fit.sun_pos.elevation_deg:.1f} deg below the horizon (night/twilight): no sun, diffuse "
              f"sky; {how}")
    if ground.get("bimodal") and ground.get("contrast", 1.0) >= NIGHT_SUSPICIOUS_CONTRAST:
        reason += (f"; the ground shows sun-like shadows (lit/shadow contrast {ground['contrast']:.1f}) although "
                   f"the ephemeris puts the sun below the horizon: check the timestamp and location")
    params = dict(est.params, sun_elevation_deg=fit.sun_pos.elevation_deg, sun_azimuth_deg=fit.sun_pos.azimuth_deg,
                  location=fit.location)
    return replace(est, reason=reason, params=_clean(params))


def _estimate_diffuse(image, K, up_cam, camera_height_m, t0, timing) -> LightingEstimate:
    """No reliable sun: an overcast-shaped sky whose ground irradiance matches the image's ground."""
    t1 = time.perf_counter()
    work = _prepare(image, np.asarray(K, dtype=np.float64), up_cam)
    ground = _ground_evidence(work, up_cam, camera_height_m)
    sky = _sky_evidence(work, _sky_mask(work))
    # A nominal sun at 45 deg only sets the overcast sky's level; the overcast sky has no azimuth.
    sun_up = np.array([0.0, np.cos(np.pi / 4), np.sin(np.pi / 4)])
    e_sky = float(luminance(sky_horizontal_irradiance(sun_up, DEFAULT_TURBIDITY, 1.0)))
    if ground is not None:
        scale = np.pi * ground["median"] / (GROUND_ALBEDO * e_sky)
        how = "scale from the ground median"
    elif sky is not None and "median_lum" in sky:
        zen = e_sky * 9.0 / (7.0 * np.pi)
        scale = sky["median_lum"] / zen
        how = "scale from the sky"
    else:
        scale = np.pi * float(luminance(work.hdr.reshape(-1, 3).mean(axis=0))) / (GROUND_ALBEDO * e_sky)
        how = "scale from the image mean"
    R_up = _up_rotation(up_cam)
    sun_cam = R_up.T @ sun_up
    light = make_sky_light(sun_cam, up_cam, DEFAULT_TURBIDITY, 1.0, GROUND_ALBEDO, ENVMAP_HEIGHT, ENVMAP_WIDTH, scale)
    timing["fit"] = time.perf_counter() - t1
    timing["total"] = time.perf_counter() - t1
    reason = (
        "L1 without metadata: no reliable sun (the learned sky predictor is not implemented yet), "
        f"diffuse overcast-shaped sky; {how}"
    )
    params = {
        "turbidity": DEFAULT_TURBIDITY, "cloud_cover": 1.0, "scale": float(scale),
        "ground_albedo_assumed": GROUND_ALBEDO, "camera_height_m": camera_height_m,
        "up_camera": np.asarray(up_cam).tolist(), "sky_sun_direction_camera": sun_cam.tolist(), "evidence": {"ground": ground, "sky": sky and {k: v for k, v in sky.items() if k != "mask"}},
    }
    return LightingEstimate(light, None, "none", 0.0, "L1", reason, _clean(params), timing)


def estimate_lighting_from_image(image_rgb: np.ndarray, K: np.ndarray, level: str = "L1") -> LightingEstimate:
    """Lighting of an image without metadata: camera assumed level (up = -y, horizon at the principal
    point row), 1.5 m above the ground; no sun (``sun_source="none"``), diffuse sky scaled to the image.

    L2/L3/auto add a volume built from the image alone: the ground plane and vertical facades standing on it.
    """
    from .levels import check_level

    image_rgb = np.asarray(image_rgb)
    check_shape(image_rgb, ("H", "W", 3), "image_rgb")
    if image_rgb.dtype != np.uint8:
        raise ValueError(f"image_rgb must be uint8 RGB, got dtype {image_rgb.dtype}")
    check_level(level)
    if level == "L0":
        return _estimate_l0(image_rgb, {})
    if level in ("L2", "L3", "auto"):
        from .multiview import estimate_views_lighting

        view = image_only_view(image_rgb, K)
        return estimate_views_lighting([view], None, level).for_view(view)
    return _estimate_learned_sky(image_rgb, np.asarray(K, dtype=np.float64))


def _estimate_learned_sky(image_rgb: np.ndarray, K: np.ndarray) -> LightingEstimate:
    """L1 without metadata: the learned image -> sky-vector predictor (:mod:`.skynet`), its sky refined on the
    visible sky pixels, the ground below the horizon from the road.  The sun is reported only when the
    predictor is confident (visibility and a tight direction cone); otherwise a diffuse sky, said so."""
    from .skynet.predict import estimate_sky_light

    t0 = time.perf_counter()
    up_cam = np.array([0.0, -1.0, 0.0])
    work = _prepare(image_rgb, K, up_cam)
    ground = _ground_evidence(work, up_cam, DEFAULT_CAMERA_HEIGHT_M)
    mask = _sky_mask(work)
    small = np.clip(np.round(work.ldr * 255.0), 0, 255).astype(np.uint8)
    ground_rgb = None if ground is None else np.full(3, ground["median"])
    light, pred, _ = estimate_sky_light(small, work.K, up_cam, sky_mask=mask if mask.sum() >= 20 else None,
                                        ground_radiance=ground_rgb, height=ENVMAP_HEIGHT, width=ENVMAP_WIDTH)
    total = time.perf_counter() - t0
    source = "image" if pred.confident else "none"
    sun_dir = np.asarray(pred.sun_dir_cam, dtype=np.float64) if pred.confident else None
    reason = (f"L1 without metadata: learned sky predictor ({pred.reason}); "
              + ("sky refined on the visible sky pixels" if mask.sum() >= 20 else "no sky visible: sky not refined"))
    params = {"sun_visibility_raw": float(pred.visibility_raw), "camera_height_m": DEFAULT_CAMERA_HEIGHT_M,
              "up_camera": up_cam.tolist(), "evidence": {"ground": ground, "sky_pixels": int(mask.sum())}}
    return LightingEstimate(light, sun_dir, source, float(pred.sun_visibility) if pred.confident else 0.0, "L1",
                            reason, _clean(params), {"total": total})


def image_only_view(image_rgb: np.ndarray, K: np.ndarray, camera_height_m: float = DEFAULT_CAMERA_HEIGHT_M):
    """A ``CameraView`` for an image without metadata: level camera ``camera_height_m`` above the ground,
    looking along ego +x, at the global origin, no timestamp (0)."""
    from streetaug.datasets.sample import CameraView

    from ..core import make_transform

    H, W = image_rgb.shape[:2]
    T_ego_from_cam = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                                    [0.0, 0.0, camera_height_m])
    return CameraView("IMAGE", "", "", np.asarray(K, dtype=np.float64), W, H, T_ego_from_cam, np.eye(4), 0,
                      _load_image=lambda: image_rgb)
