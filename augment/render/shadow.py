"""The shadow ratio map of Eq. 4: how much light the inserted object takes from the scene around it.

For each scene pixel near the object: its 3D point (from the depth map, or the ground plane where
the depth is unknown), normal = the ground normal, Lambertian.  With ``E = E_sun cos + E_sky``
the unoccluded irradiance (the sky part integrated exactly from the map, the same for every point
since the light is distant)::

    S = 1 - [ (1 - V_sun) E_sun cos  +  sum_{blocked k} (L_k - L_hit,k) cos_k w_k ] / E

* Sun: ``V_sun`` is traced at full resolution where the object's box, projected along the sun onto the
  ground, can fall -- one ray per pixel to the sun's centre, then ``shadow_sun_dirs`` jittered rays
  (sub-pixel position x disc direction) in the pixels at the shadow's edge, so the shadow is as sharp
  as the sun disc makes it and anti-aliased.  The edge pixels include every pixel an edge of a triangle's
  shadow crosses (not deep inside the shadow): the shadow of a spoke, far thinner than a pixel, is
  found and comes out as the fraction of the pixel it darkens.  Sub-pixel positions lie on the
  ground-parallel plane through their pixel's point (a grazing ground pixel is decimetres deep).
* Sky: every ``shadow_factor`` pixels, ``shadow_sky_dirs`` directions in the cone around the object's
  bounding sphere (the only directions it can block; the whole upper hemisphere under it), each
  standing for ``w_k = cone solid angle / N`` -- coarse to fine: on every 4th cell first, in between only
  where those differ (elsewhere interpolated: far from the object the occlusion is smooth over many
  cells) --; smoothed and upsampled; at full resolution where it
  changes fast between cells and within a band around where the object touches the ground (the
  contact shadow of feet, tyres and posts: the sky they hide, not only the sun).
* A blocked ray sees the object's own surface, ``L_hit`` from the one-bounce model of
  :mod:`.bounce` (instead of the paper's constant 0.1): ``A + B S_foot`` with ``S_foot`` the mean
  ratio under the object, solved in closed form from the map itself.

The map is computed only in the image box that can be non-trivial
(:func:`streetaug.augment.render.footprint.shadow_pixel_box`: the footprint grown by a sky-occlusion
radius plus the object's top corners projected along the sun onto the ground).  :class:`GroundShadow` lets the foreground renderer look the map up for
rays that leave the object downwards.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..core import PinholeCamera, camera_dir_to_lonlat, luminance, sample_equirect
from ..lighting.light import DistantLight
from .bounce import BounceLight
from .brdf import row_norm, tangent_frame, to_world
from .footprint import SKY_FADE_START, SUN_FADE_START, PixelBox, edge_pixels, fade_weight, sky_radius_m
from .environment import EnvironmentTables
from .sampling import GOLDEN_ANGLE, sample_cone
from .settings import RenderSettings
from .surface import PreparedAsset

RAY_EPS_M = 0.01
RATIO_SNAP = 5e-4  # ratios this close to 1 are 1 (an eighth of an 8-bit level; the faded tails end there)
SHADOW_CHUNK_RAYS = 250_000  # rays per batch: bounds memory (~55 MB a batch of the sky test; 1M: ~210)


@dataclass(frozen=True)
class ShadowMap:
    """Ratio map over a pixel box.

    Attributes:
        box: the pixels the map covers (:func:`streetaug.augment.render.footprint.shadow_pixel_box`).
        ratio_rgb: (h, w, 3) float32 per-channel ratio S in [0, 1], 1 = unchanged.
        stats: rays cast, pixels evaluated.
        foot_ratio: (3,) mean ratio on the ground under the object (used by the bounce model).
    """

    box: PixelBox
    ratio_rgb: np.ndarray
    stats: dict = field(default_factory=dict)
    foot_ratio: np.ndarray | None = None


@dataclass(frozen=True)
class GroundShadow:
    """The ratio map as seen from the object: how shadowed the ground is where a ray from the object lands.

    Attributes:
        shadow: the ratio map.
        camera: the camera of the image; T_cam_from_object: (4, 4) pose.
        up_obj: (3,) unit ground normal in the object frame (the ground plane passes through the origin).
    """

    shadow: ShadowMap
    camera: PinholeCamera
    T_cam_from_object: np.ndarray
    up_obj: np.ndarray

    def ratio_along(self, origins_obj: np.ndarray, dirs_obj: np.ndarray) -> np.ndarray:
        """(N, 3) ratio S at the ground point each ray (object frame, going down) lands on; 1 off the map."""
        out = np.ones((len(origins_obj), 3), np.float64)
        down = dirs_obj @ self.up_obj
        height = origins_obj @ self.up_obj
        ok = np.flatnonzero((down < -1e-6) & (height > 0))
        if len(ok) == 0:
            return out
        g = origins_obj[ok] + (height[ok] / -down[ok])[:, None] * dirs_obj[ok]
        R, t = self.T_cam_from_object[:3, :3], self.T_cam_from_object[:3, 3]
        g_cam = g @ R.T + t
        uv, z = self.camera.project(g_cam)
        front = z > 1e-3
        u = uv[:, 0] - self.shadow.box.x0
        v = uv[:, 1] - self.shadow.box.y0
        h, w = self.shadow.ratio_rgb.shape[:2]
        inside = front & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
        sel = ok[inside]
        if len(sel):
            uu, vv = u[inside], v[inside]
            xa = np.minimum(np.floor(uu).astype(np.int64), w - 2) if w > 1 else np.zeros(len(uu), np.int64)
            ya = np.minimum(np.floor(vv).astype(np.int64), h - 2) if h > 1 else np.zeros(len(vv), np.int64)
            fx = np.clip(uu - xa, 0.0, 1.0)[:, None]
            fy = np.clip(vv - ya, 0.0, 1.0)[:, None]
            r = self.shadow.ratio_rgb
            xb, yb = np.minimum(xa + 1, w - 1), np.minimum(ya + 1, h - 1)
            out[sel] = (r[ya, xa] * (1 - fx) + r[ya, xb] * fx) * (1 - fy) + (r[yb, xa] * (1 - fx) + r[yb, xb] * fx) * fy
        return out


def car_ambient_radiance(env: EnvironmentTables, mean_albedo: float, up_cam: np.ndarray) -> np.ndarray:
    """Radiance (3,) the object sends along rays it blocks: ``albedo x E_sky(up) / (2 pi)``.

    A matte surface of albedo rho under a sky giving ``E_sky`` on a horizontal plane receives about
    half of it when vertical (the car's sides, which is what the ground around the car sees), so it
    reflects ``rho E_sky / (2 pi)``.  The direct sun is left out: the side facing a shadowed point is
    the side turned away from the sun.
    """
    return mean_albedo * env.sky_irradiance(up_cam) / (2.0 * np.pi)


def render_shadow(camera: PinholeCamera, box: PixelBox | None, depth_m: np.ndarray, light: DistantLight,
                  prep: PreparedAsset, T_cam_from_object: np.ndarray, ground_normal_cam: np.ndarray,
                  settings: RenderSettings, rng: np.random.Generator, bounce: BounceLight) -> ShadowMap | None:
    """The ratio map S over ``box`` (see module docstring); None if there is nothing to do.

    Args:
        camera: the camera of the image; box: its :func:`~streetaug.augment.render.footprint.shadow_pixel_box`.
        depth_m: (H, W) scene camera-z depth in metres, inf/nan/<= 0 where unknown.
        ground_normal_cam: (3,) unit normal of the ground (pointing up), camera frame; the ground plane
            passes through the object's origin.
        bounce: radiance model of the object's surfaces along blocked rays.
    """
    if box is None:
        return None
    n_cam = np.asarray(ground_normal_cam, dtype=np.float64)
    n_cam = n_cam / np.linalg.norm(n_cam)
    geo = _Ground(camera, np.asarray(depth_m), n_cam, T_cam_from_object)
    E_sky = bounce.env.sky_irradiance(n_cam)
    sun = light.sun
    cos_sun = 0.0 if sun is None else float(max(np.dot(sun.direction, n_cam), 0.0))
    E_sun = np.zeros(3) if sun is None else np.asarray(sun.irradiance_rgb, dtype=np.float64) * cos_sun
    E = E_sky + E_sun
    stats: dict = {"rays": {}, "box": box.as_list()}
    if luminance(E) <= 0:
        return ShadowMap(box=box, ratio_rgb=np.ones((box.height, box.width, 3), np.float32), stats=stats)
    E_safe = np.where(E > 0, E, np.inf)
    sky = _sky_occlusion(geo, box, light, prep, bounce, settings, rng, stats, E_safe)
    # -- sun: full resolution where the object's shadow can fall, refined at the shadow's edges.
    sun_def = np.zeros((box.height, box.width, 3), np.float32)
    if cos_sun > 0 and luminance(E_sun) > 0:  # a sun of zero irradiance (overcast) casts no shadow: no rays
        blocked = _sun_blocked(geo, box, light, prep, settings, rng, stats)
        sun_def = (blocked[..., None] * (E_sun / E_safe)[None, None]).astype(np.float32)
    s_foot = _foot_ratio(geo, box, prep, sky, sun_def, E_safe)
    stats["foot_ratio"] = s_foot.tolist()
    ratio = np.clip(1.0 - sky.deficit - sun_def + sky.bounce_gain * s_foot.astype(np.float32)[None, None], 0.0, 1.0)
    ratio = np.where(ratio > 1.0 - RATIO_SNAP, 1.0, ratio).astype(np.float32)
    return ShadowMap(box=box, ratio_rgb=ratio, stats=stats, foot_ratio=s_foot)


@dataclass(frozen=True)
class SkyOcclusion:
    """The sky part of the ratio map (:func:`_sky_occlusion`).

    Attributes:
        uv: (C, 2) float64 pixel positions of the coarse cells (every ``shadow_factor`` pixels).
        valid: (C,) bool cells with a ground point.
        D0, C: (C, 3) float64 per-cell sky deficit ``D0 - C S_foot`` (irradiance units), before the fade to the sky radius.
        deficit, bounce_gain: (h, w, 3) float32 ``D0 / E`` and ``C / E`` over the box, upsampled and
            refined at full resolution where the occlusion changes fast.
    """

    uv: np.ndarray
    valid: np.ndarray
    D0: np.ndarray
    C: np.ndarray
    deficit: np.ndarray
    bounce_gain: np.ndarray


def _sky_occlusion(geo: "_Ground", box: PixelBox, light: DistantLight, prep: PreparedAsset, bounce: BounceLight,
                   settings: RenderSettings, rng: np.random.Generator, stats: dict, E_safe: np.ndarray) -> SkyOcclusion:
    """Sky light the object takes: every ``shadow_factor`` pixels, smoothed and upsampled, then refined."""
    f = settings.shadow_factor
    x0, y0, h, w = box.x0, box.y0, box.height, box.width
    wl, hl = -(-w // f), -(-h // f)
    gx = x0 + f * np.arange(wl) + (f - 1) / 2.0
    gy = y0 + f * np.arange(hl) + (f - 1) / 2.0
    GX, GY = np.meshgrid(gx, gy)
    uv = np.stack([GX.ravel(), GY.ravel()], axis=1)
    p_obj, valid = geo.points_obj(uv)
    D0 = np.zeros((len(uv), 3))
    C = np.zeros((len(uv), 3))
    chunk = max(1, SHADOW_CHUNK_RAYS // settings.shadow_sky_dirs)

    def evaluate(cells: np.ndarray) -> None:
        for a in range(0, len(cells), chunk):
            sel = cells[a : a + chunk]
            D0[sel], C[sel] = _sky_deficit(p_obj[sel], geo.n_obj, light, prep, bounce, settings.shadow_sky_dirs, geo.R,
                                           rng, stats, fade=False)

    _coarse_to_fine_cells(hl, wl, valid, evaluate, D0, C, E_safe, stats)
    stats["grid"] = [int(hl), int(wl)]
    stats["pixels"] = int(valid.sum())

    def upsample(a: np.ndarray) -> np.ndarray:
        low = (a / E_safe).reshape(hl, wl, 3).astype(np.float32)
        if min(hl, wl) >= 3:
            low = cv2.GaussianBlur(low, (3, 3), 0.8, borderType=cv2.BORDER_REPLICATE)
        return cv2.resize(low, (wl * f, hl * f), interpolation=cv2.INTER_LINEAR)[:h, :w]

    sky_def, bounce_gain = upsample(D0), upsample(C)
    # The fade to the sky radius at full resolution, from the cells' distances interpolated (not blurred):
    # the blurred, upsampled deficit ends inside the box instead of bleeding to its edge.
    lo, hi = prep.asset.vertices.min(axis=0), prep.asset.vertices.max(axis=0)
    radius = sky_radius_m(hi[2])
    dist = np.where(valid, _footprint_distance(p_obj, lo, hi), 2.0 * radius).reshape(hl, wl).astype(np.float32)
    dist_px = cv2.resize(dist, (wl * f, hl * f), interpolation=cv2.INTER_LINEAR)[:h, :w]
    fade = fade_weight(dist_px, radius, SKY_FADE_START).astype(np.float32)[..., None]
    sky_def *= fade
    bounce_gain *= fade
    if f > 1:
        low = np.where(valid, luminance(D0 / E_safe), 0.0).reshape(hl, wl).astype(np.float32)
        _refine_sky_edges(geo, box, low, light, prep, bounce, settings, rng, stats, E_safe, sky_def, bounce_gain)
    return SkyOcclusion(uv, valid, D0, C, sky_def, bounce_gain)


def _coarse_to_fine_cells(hl: int, wl: int, valid: np.ndarray, evaluate, D0: np.ndarray, C: np.ndarray,
                          E_safe: np.ndarray, stats: dict) -> None:
    """Fill the sky deficit (D0, C) of the (hl x wl) cell grid, in place, at the resolution it needs.

    The sky a car hides changes over distances like the car's distance from the ground point: far from
    it (most of the pixel box) it is smooth over many cells.  It is evaluated (``evaluate(cell indices)``)
    on every :data:`SKY_COARSE_STEP`-th cell first; within a square of four such nodes whose deficits differ
    by more than :data:`SKY_COARSE_TOL` of E (or that mixes cells with and without a ground point), every
    cell is evaluated, elsewhere the cells are interpolated bilinearly between the nodes.
    """
    S = SKY_COARSE_STEP
    if hl < 2 * S or wl < 2 * S:
        evaluate(np.flatnonzero(valid))
        return
    ry = np.unique(np.r_[np.arange(0, hl, S), hl - 1])
    rx = np.unique(np.r_[np.arange(0, wl, S), wl - 1])
    nodes = (ry[:, None] * wl + rx[None, :]).ravel()
    evaluate(nodes[valid[nodes]])
    lum = luminance(D0[nodes] / E_safe).reshape(len(ry), len(rx))
    ok = valid[nodes].reshape(len(ry), len(rx))
    corners = np.stack([lum[:-1, :-1], lum[:-1, 1:], lum[1:, :-1], lum[1:, 1:]])
    corner_ok = np.stack([ok[:-1, :-1], ok[:-1, 1:], ok[1:, :-1], ok[1:, 1:]])
    refine = (corners.max(axis=0) - corners.min(axis=0) > SKY_COARSE_TOL) | (corner_ok.any(axis=0) & ~corner_ok.all(axis=0))
    qy = np.clip(np.searchsorted(ry, np.arange(hl), side="right") - 1, 0, len(ry) - 2)
    qx = np.clip(np.searchsorted(rx, np.arange(wl), side="right") - 1, 0, len(rx) - 2)
    ty = ((np.arange(hl) - ry[qy]) / (ry[qy + 1] - ry[qy]))[:, None, None]
    tx = ((np.arange(wl) - rx[qx]) / (rx[qx + 1] - rx[qx]))[None, :, None]
    is_node = np.zeros((hl, wl), bool)
    is_node[ry[:, None], rx[None, :]] = True
    # Bilinear between the nodes, in blocks of grid rows (the same values as over the whole grid at once,
    # whose float64 temporaries were ~8 (hl, wl, 3) arrays: ~69 MB for a whole-frame box).
    rows = max(1, SKY_INTERP_CHUNK_CELLS // wl)
    for a in (D0, C):
        g = a[nodes].reshape(len(ry), len(rx), 3)
        for r0 in range(0, hl, rows):
            r = slice(r0, min(r0 + rows, hl))
            top = g[qy[r]][:, qx] * (1 - tx) + g[qy[r]][:, qx + 1] * tx
            bot = g[qy[r] + 1][:, qx] * (1 - tx) + g[qy[r] + 1][:, qx + 1] * tx
            interp = (top * (1 - ty[r]) + bot * ty[r]).reshape(-1, 3)
            del top, bot
            off = ~is_node[r].ravel()
            block = a[r0 * wl : r.stop * wl]  # a view: the block's cells, row-major
            block[off] = np.where(valid[r0 * wl : r.stop * wl][off][:, None], interp[off], 0.0)
    fine = np.flatnonzero((refine[qy][:, qx] & ~is_node).ravel() & valid)
    evaluate(fine)
    stats["sky_cells_evaluated"] = int(valid[nodes].sum() + len(fine))


def _refine_sky_edges(geo: "_Ground", box: PixelBox, low: np.ndarray, light: DistantLight, prep: PreparedAsset,
                      bounce: BounceLight, settings: RenderSettings, rng: np.random.Generator, stats: dict,
                      E_safe: np.ndarray, sky_def: np.ndarray, bounce_gain: np.ndarray) -> None:
    """Where the sky occlusion ``low`` (hl, wl) changes fast between cells (the edge of the ground under
    the object) the upsampled map is too soft: evaluate those pixels at full resolution, in place."""
    f, per_cell = settings.shadow_factor, settings.shadow_sky_dirs
    h, w = box.height, box.width
    k3 = np.ones((3, 3), np.uint8)
    jump = cv2.dilate(low, k3) - cv2.erode(low, k3, borderType=cv2.BORDER_REPLICATE)
    sharp = np.repeat(np.repeat(jump > SKY_REFINE_JUMP, f, axis=0), f, axis=1)[:h, :w]
    contact = _contact_pixels(geo, box, prep)
    if contact is not None:
        sharp |= contact
    ys, xs = np.nonzero(sharp)
    if not len(ys):
        return
    uv_f = np.stack([xs + box.x0, ys + box.y0], axis=1).astype(np.float64)
    p_f, valid_f = geo.points_obj(uv_f)
    sel = np.flatnonzero(valid_f)
    chunk = max(1, SHADOW_CHUNK_RAYS // per_cell)
    for a in range(0, len(sel), chunk):
        part = sel[a : a + chunk]
        d0, c = _sky_deficit(p_f[part], geo.n_obj, light, prep, bounce, per_cell, geo.R, rng, stats)
        sky_def[ys[part], xs[part]] = d0 / E_safe
        bounce_gain[ys[part], xs[part]] = c / E_safe
    _smooth_refined(sky_def, bounce_gain, ys, xs)
    stats["sky_refined_pixels"] = int(len(sel))


def _smooth_refined(sky_def: np.ndarray, bounce_gain: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> None:
    """Per-pixel noise of the refined pixels (rows ``ys``, columns ``xs``) -> a light 5 x 5 blur, in place,
    edge-aware: cross-bilateral on the deficit's luminance (range sigma :data:`REFINE_RANGE_SIGMA`), so the
    step at a tyre's or a sill's edge (ground fully occluded next to ground half open) stays a step and the
    darkness under the object does not bleed out as a band beside it."""
    h, w = sky_def.shape[:2]
    # The bounding rectangle of the refined pixels (+ the 5 x 5 support), filtered by OpenCV, then written back.
    ya, yb = max(int(ys.min()) - 2, 0), min(int(ys.max()) + 3, h)
    xa, xb = max(int(xs.min()) - 2, 0), min(int(xs.max()) + 3, w)
    d_win = np.ascontiguousarray(sky_def[ya:yb, xa:xb], dtype=np.float32)
    c_win = np.ascontiguousarray(bounce_gain[ya:yb, xa:xb], dtype=np.float32)
    guide = np.ascontiguousarray(luminance(d_win), dtype=np.float32)
    for a, win in ((sky_def, d_win), (bounce_gain, c_win)):
        out = cv2.ximgproc.jointBilateralFilter(guide, win, 5, REFINE_RANGE_SIGMA, 1.2, borderType=cv2.BORDER_REPLICATE)
        a[ys, xs] = out[ys - ya, xs - xa]


def _contact_pixels(geo: "_Ground", box: PixelBox, prep: PreparedAsset) -> np.ndarray | None:
    """(h, w) bool over ``box``: ground within :data:`CONTACT_BAND_M` of where the object touches the ground
    (vertices less than :data:`CONTACT_HEIGHT_M` above it: feet, tyres, posts), or None if none.

    The sky occlusion there falls from strong to weak within centimetres (the contact shadow of a foot),
    much faster than the coarse cells every ``shadow_factor`` pixels resolve, so it is evaluated at
    full resolution.  Up to :data:`CONTACT_MAX_POINTS` contact points (a 2 cm grid), one disc each.
    """
    V = prep.asset.vertices
    low = V[V @ geo.n_obj < CONTACT_HEIGHT_M]
    if not len(low):
        return None
    _, first = np.unique(np.round(low[:, :2] / 0.02).astype(np.int64), axis=0, return_index=True)
    pts = low[np.sort(first)]
    if len(pts) > CONTACT_MAX_POINTS:
        pts = pts[np.linspace(0, len(pts) - 1, CONTACT_MAX_POINTS).astype(np.int64)]
    p_cam = pts @ geo.R.T + geo.t
    front = p_cam[:, 2] > 0.3
    if not front.any():
        return None
    uv, z = geo.camera.project(p_cam[front])
    radius = np.ceil(float(geo.camera.K[0, 0]) * CONTACT_BAND_M / z).astype(np.int64) + 1
    mask = np.zeros((box.height, box.width), np.uint8)
    for (x, y), r in zip(np.round(uv - [box.x0, box.y0]).astype(np.int64), radius):
        if -r <= x < box.width + r and -r <= y < box.height + r:
            cv2.circle(mask, (int(x), int(y)), int(r), 1, -1)
    return mask > 0


def _foot_ratio(geo: "_Ground", box: PixelBox, prep: PreparedAsset, sky: SkyOcclusion, sun_def: np.ndarray,
                E_safe: np.ndarray) -> np.ndarray:
    """(3,) mean ratio on the ground under the object, solved in closed form (it closes the bounce model's loop)."""
    foot = geo.footprint(sky.uv, sky.valid, prep)
    if not foot.any():
        return np.full(3, FOOT_RATIO_FALLBACK)
    h, w = box.height, box.width
    cells_yx = (np.clip(np.round(sky.uv[foot, 1] - box.y0).astype(int), 0, h - 1),
                np.clip(np.round(sky.uv[foot, 0] - box.x0).astype(int), 0, w - 1))
    s0 = 1.0 - (sky.D0[foot] / E_safe).mean(axis=0) - sun_def[cells_yx].mean(axis=0)
    c = (sky.C[foot] / E_safe).mean(axis=0)
    return np.clip(s0 / np.maximum(1.0 - c, 1e-3), 0.0, 1.0)


FOOT_RATIO_FALLBACK = 0.15  # mean shadow ratio under a car when its footprint is not in view
CONTACT_HEIGHT_M = 0.03  # vertices this close to the ground plane touch it
CONTACT_BAND_M = 0.1  # ground this close to a contact gets full-resolution sky occlusion
CONTACT_MAX_POINTS = 256
GROUND_SNAP_M = 0.25  # depth-map points this close to the object's ground plane are taken on it ...
GROUND_SNAP_END_M = 0.5  # ... and from this far on as the depth map says (smoothstep between)
REFINE_RANGE_SIGMA = 0.12  # deficit difference (fraction of E) the refined band's smoothing does not cross
SKY_COARSE_STEP = 4  # the sky deficit is first evaluated every this many cells ...
SKY_COARSE_TOL = 0.01  # ... and at every cell where those nodes differ by more than this (fraction of E)
SKY_INTERP_CHUNK_CELLS = 32768  # cells per block of grid rows interpolated between the nodes at once
SKY_ROTATIONS = 128  # the sky spiral of a ground point is rotated by one of this many angles (random per point)
SKY_REFINE_JUMP = 0.08  # sky-occlusion change (fraction of E) between neighbouring cells that asks for full resolution


class _Ground:
    """Ground points seen by pixels: on the ground plane through the object where the depth is unknown or
    within :data:`GROUND_SNAP_M` of that plane, from the depth map where it is far from it (blended between)."""

    def __init__(self, camera: PinholeCamera, depth_m: np.ndarray, n_cam: np.ndarray, T_cam_from_object: np.ndarray) -> None:
        self.camera = camera
        self.depth = depth_m
        self.n_cam = n_cam
        self.R = T_cam_from_object[:3, :3]
        self.t = T_cam_from_object[:3, 3]
        self.n_obj = self.R.T @ n_cam

    def points_obj(self, uv: np.ndarray, depth_uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Object-frame ground points (N, 3) seen through pixel positions uv (N, 2), and which are valid (N,).

        The depth is read at ``depth_uv`` (default: uv rounded).  With ``depth_uv``, a sub-pixel position
        lies on the ground-parallel plane through its pixel's point (a grazing ground pixel spans
        decimetres in depth: sub-pixel samples must spread over them, not share the centre's depth).
        """
        H, W = self.depth.shape
        src = uv if depth_uv is None else depth_uv
        ix = np.clip(np.round(src[:, 0]).astype(int), 0, W - 1)
        iy = np.clip(np.round(src[:, 1]).astype(int), 0, H - 1)
        d = np.asarray(self.depth[iy, ix], dtype=np.float64)
        rays = self.camera.rays(uv, unit=False)  # z = 1
        denom = rays @ self.n_cam
        with np.errstate(divide="ignore", invalid="ignore"):
            z_plane = (self.t @ self.n_cam) / denom
        z_plane = np.where((denom < -1e-9) & (z_plane > 0), z_plane, np.inf)  # rays going down hit the ground
        known = np.isfinite(d) & (d > 0)
        if depth_uv is not None and np.any(known):
            # The pixel's point P0 (its depth along its centre ray), then the sub-pixel ray on the plane
            # n . p = n . P0; kept at the pixel's depth where that plane is seen edge-on.
            h0 = (self.camera.rays(np.asarray(depth_uv, dtype=np.float64), unit=False) @ self.n_cam) * np.where(known, d, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                z_tan = h0 / denom
            d = np.where(known & (denom < -1e-9) & (z_tan > 0) & (z_tan < 2.0 * d), z_tan, d)
        z = np.where(known, d, z_plane)
        # Depth within GROUND_SNAP_M of the object's ground plane is that plane (densified LiDAR depth is off
        # by +-0.2 m in bands between rings: ground points inside the tyres gave a black band, points below
        # them a floating car); blended back to the depth up to GROUND_SNAP_END_M (kerbs, walls, other objects).
        on_plane = known & np.isfinite(z_plane)
        if np.any(on_plane):
            with np.errstate(invalid="ignore"):  # off the plane z or z_plane may be inf: masked out
                to_plane = np.where(on_plane, z_plane - z, 0.0)
            height = np.where(on_plane, np.abs(denom * to_plane), np.inf)
            snap = fade_weight(height, GROUND_SNAP_END_M, GROUND_SNAP_M / GROUND_SNAP_END_M)
            z = np.where(on_plane, z + snap * to_plane, z)
        valid = np.isfinite(z)
        p_cam = rays * np.where(valid, z, 0.0)[:, None]
        return (p_cam - self.t) @ self.R, valid

    def footprint(self, uv: np.ndarray, valid: np.ndarray, prep: PreparedAsset) -> np.ndarray:
        """(N,) bool: valid ground points under the object's box (object-frame x, y inside its extent)."""
        p, _ = self.points_obj(uv)
        V = prep.asset.vertices
        lo, hi = V.min(axis=0), V.max(axis=0)
        return valid & np.all((p[:, :2] >= lo[:2]) & (p[:, :2] <= hi[:2]), axis=1)


def ground_snapped_depth(camera: PinholeCamera, depth_m: np.ndarray, box: PixelBox | None,
                         ground_normal_cam: np.ndarray, T_cam_from_object: np.ndarray) -> np.ndarray:
    """(H, W) float32 scene depth (camera z, m) with the ground near the object's plane put on that plane over ``box``.

    The same rule as the shadow's ground (:data:`GROUND_SNAP_M`, blended out to :data:`GROUND_SNAP_END_M`), so the
    object's occlusion test and its shadow see one ground: densified LiDAR depth is off by +-0.2 m in bands between
    rings, which at a grazing view is metres of depth, and would hide the bottoms of the tyres behind a ground
    that the shadow puts below them. Unknown depth stays unknown; outside ``box`` the map is unchanged.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    if box is None or box.width <= 0 or box.height <= 0:
        return depth
    ys, xs = np.mgrid[box.y0:box.y1, box.x0:box.x1]
    uv = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    n_cam = np.asarray(ground_normal_cam, dtype=np.float64)
    geo = _Ground(camera, depth, n_cam / np.linalg.norm(n_cam), T_cam_from_object)  # it reads float64 per pixel
    p_obj, valid = geo.points_obj(uv)
    z_cam = (p_obj @ geo.R.T + geo.t)[:, 2]
    inside = depth[box.slices].ravel()
    known = np.isfinite(inside) & (inside > 0) & valid
    out = depth.copy()
    out[box.slices] = np.where(known, z_cam, inside).reshape(box.height, box.width).astype(np.float32)
    return out


def _footprint_distance(p_obj: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) horizontal distance (m) of object-frame points (N, 3) from the footprint box [lo, hi] (x, y); 0 under it."""
    gap = np.maximum(np.maximum(lo[None, :2] - p_obj[:, :2], p_obj[:, :2] - hi[None, :2]), 0.0)
    return np.sqrt((gap * gap).sum(axis=1))


def _sky_deficit(p_obj: np.ndarray, n_obj: np.ndarray, light: DistantLight, prep: PreparedAsset, bounce: BounceLight,
                 n_dirs: int, R: np.ndarray, rng: np.random.Generator, stats: dict,
                 fade: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Sky light the object takes from ground points p_obj (P, 3): (D0, C), each (P, 3), the deficit being
    ``D0 - C S_foot`` (irradiance units).  ``n_obj`` (3,) is the ground normal, ``R`` (3, 3) object -> camera.

    Only directions towards the object can be blocked: each point samples ``n_dirs`` directions
    uniformly (a randomly rotated Fibonacci spiral) in the cone around the object's bounding sphere,
    or in the whole upper hemisphere when it is inside the sphere; a direction stands for
    ``cone solid angle / n_dirs`` and counts with its cosine to the ground normal.  With ``fade`` the
    deficit fades to 0 at the sky radius (:func:`~.footprint.sky_radius_m`) from the footprint box, where
    the pixel box ends (the coarse cells are faded after upsampling instead, :func:`_sky_occlusion`).
    """
    P = len(p_obj)
    rays = stats["rays"]
    org = p_obj + RAY_EPS_M * n_obj
    lo, hi = prep.asset.vertices.min(axis=0), prep.asset.vertices.max(axis=0)
    centre, radius = (lo + hi) / 2.0, 0.5 * float(np.linalg.norm(hi - lo)) * 1.001
    to_c = centre[None] - org
    dist = row_norm(to_c)
    inside = dist <= radius
    axis = np.where(inside[:, None], n_obj[None], to_c / np.maximum(dist, 1e-9)[:, None])
    cos_max = np.where(inside, 0.0, np.sqrt(np.clip(1.0 - (radius / np.maximum(dist, 1e-9)) ** 2, 0.0, 1.0)))
    k = (np.arange(n_dirs) + 0.5) / n_dirs
    z = 1.0 - k[None] * (1.0 - cos_max)[:, None]  # (P, N) uniform in solid angle inside the cap
    # Each point's spiral is rotated by one of SKY_ROTATIONS angles: under the object (the whole hemisphere)
    # the direction sets are then a small table, whose sky integrals are computed once (below).
    rot = rng.integers(0, SKY_ROTATIONS, P)
    # Each direction stands for a cell of the cone: use the sky averaged over cells of about that size
    # (a box-filtered map), not a point sample of a possibly spiky panorama.
    env = bounce.env.cell_filtered(n_dirs)
    dirs_all = np.empty((P, n_dirs, 3))
    out = np.flatnonzero(~inside)
    if len(out):
        phi = GOLDEN_ANGLE * np.arange(n_dirs)[None] + (rot[out] * (2 * np.pi / SKY_ROTATIONS))[:, None]
        rr = np.sqrt(np.clip(1.0 - z[out] * z[out], 0.0, 1.0))
        # The spiral in each point's frame (t, b, axis): one tangent frame per point, not per direction.
        t_ax, b_ax = tangent_frame(axis[out])
        dirs_all[out] = ((rr * np.cos(phi))[..., None] * t_ax[:, None] + (rr * np.sin(phi))[..., None] * b_ax[:, None]
                         + z[out][..., None] * axis[out][:, None])
    if inside.any():  # the whole hemisphere: the spirals of the table (one per rotation)
        table, E_hat, table_dirs = bounce.env.cached(
            "hemisphere_sky", (n_dirs, n_obj.tobytes(), R.tobytes()),
            lambda: _hemisphere_sky(env, n_obj, R, n_dirs, z[np.flatnonzero(inside)[0]]))
        dirs_all[inside] = table_dirs[rot[inside]]
    dirs_all = dirs_all.reshape(-1, 3)
    cos_n = dirs_all @ n_obj
    weight_all = np.repeat(2 * np.pi * (1.0 - cos_max) / n_dirs, n_dirs) * np.maximum(cos_n, 0.0)
    live = np.flatnonzero(cos_n > 1e-6)  # directions under the ground see the ground, not the sky
    dirs_obj = dirs_all[live]
    origins = org[live // n_dirs]
    blocked = prep.scene.occluded(origins, dirs_obj)
    rays["shadow_sky"] = rays.get("shadow_sky", 0) + int(len(live))
    D0 = np.zeros((P, 3))
    C = np.zeros((P, 3))
    bi = np.flatnonzero(blocked)
    if len(bi) == 0:
        return D0, C
    hits = prep.scene.intersect(origins[bi], dirs_obj[bi])
    rays["shadow_bounce"] = rays.get("shadow_bounce", 0) + int(len(bi))
    ok = hits.hit
    bi, face = bi[ok], hits.face[ok]
    A, B = bounce.radiance(face, dirs_obj[bi])
    pix = live[bi] // n_dirs
    wgt = weight_all[live[bi]]
    L = np.empty((len(bi), 3))
    hemi = inside[pix]
    if hemi.any():
        L[hemi] = table[rot[pix[hemi]], live[bi[hemi]] % n_dirs]
    if not hemi.all():
        L[~hemi] = sample_equirect(env, *camera_dir_to_lonlat(dirs_obj[bi[~hemi]] @ R.T))
    for k in range(3):
        D0[:, k] = np.bincount(pix, weights=(L[:, k] - A[:, k]) * wgt, minlength=P)
        C[:, k] = np.bincount(pix, weights=B[:, k] * wgt, minlength=P)
    if hemi.any():
        # Under the object the deficit is the blocked share of the sky these directions see (their own sky
        # integral E_hat) times the exact sky irradiance E: a ratio estimator.  A point that sees no sky gets
        # exactly its bounce light, instead of E minus a sampled estimate of E, whose few-per-cent integration
        # error is the whole signal in a deep shadow (blotches, clipped to black).
        scale = bounce.env.sky_irradiance(R @ n_obj)[None] / np.maximum(E_hat[rot], 1e-12)
        D0[inside] *= scale[inside]
        C[inside] *= scale[inside]
    if not fade:
        return D0, C
    # Truncated at the sky radius of the shadow's pixel box, smoothly (no step at the box's edge).
    w = fade_weight(_footprint_distance(p_obj, lo, hi), sky_radius_m(hi[2]), SKY_FADE_START)[:, None]
    return D0 * w, C * w


def _sun_polygon_mask(geo: _Ground, box: PixelBox, light: DistantLight, prep: PreparedAsset) -> np.ndarray | None:
    """(h, w) bool over ``box``: pixels the object's box can shade from the sun (its box projected along
    the sun onto the ground plane), or None when that projection reaches behind the camera."""
    x0, y0, x1, y1 = box.x0, box.y0, box.x1, box.y1
    s_obj = geo.R.T @ np.asarray(light.sun.direction, dtype=np.float64)
    n = geo.n_obj
    corners = prep.box_corners_object
    along = (corners @ n) / max(float(s_obj @ n), 1e-6)
    shadow_pts = corners - along[:, None] * s_obj[None]  # on the plane n . p = 0
    pts_cam = np.concatenate([corners, shadow_pts]) @ geo.R.T + geo.t
    if np.any(pts_cam[:, 2] < 0.3):
        return None
    uv, _ = geo.camera.project(pts_cam)
    hull = cv2.convexHull(np.round((uv - [x0, y0]) * 4).astype(np.int32))  # 2 fractional bits
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=2)
    return cv2.dilate(mask, np.ones((5, 5), np.uint8)) > 0


def _shadow_edge_pixels(geo: _Ground, box: PixelBox, prep: PreparedAsset, s_obj: np.ndarray) -> np.ndarray | None:
    """(h, w) bool over ``box``: pixels the edges of the object's triangles, projected along the sun
    ``s_obj`` (3,) (object frame) onto the ground plane, cross (:func:`.footprint.edge_pixels`); None
    when the projection reaches behind the camera."""
    n = geo.n_obj
    V = prep.asset.vertices
    along = np.maximum(V @ n, 0.0) / max(float(s_obj @ n), 1e-6)
    g_cam = (V - along[:, None] * s_obj[None]) @ geo.R.T + geo.t
    if np.any(g_cam[:, 2] < 0.3):
        return None
    uv, _ = geo.camera.project(g_cam)
    return edge_pixels(uv[prep.faces], box)


def _sun_blocked(geo: _Ground, box: PixelBox, light: DistantLight, prep: PreparedAsset, settings: RenderSettings,
                 rng: np.random.Generator, stats: dict) -> np.ndarray:
    """(h, w) float32 fraction of the sun disc the object hides from each pixel's ground point.

    One ray per pixel towards the sun's centre where the object can cast its shadow, then
    ``shadow_sun_dirs`` jittered rays (sub-pixel position x disc direction) in the pixels at the
    shadow's edge (the penumbra and the anti-aliased boundary).  When the shadow can be longer than
    :data:`~.footprint.SUN_FADE_START` x ``settings.shadow_max_length_m`` (a low sun), a blocked ray counts
    with :func:`~.footprint.fade_weight` of the horizontal distance to what blocks it: the shadow fades
    out smoothly and ends within that length, inside the pixel box.
    """
    x0, y0, h, w = box.x0, box.y0, box.height, box.width
    sun = light.sun
    s_obj = geo.R.T @ np.asarray(sun.direction, dtype=np.float64)
    mask = _sun_polygon_mask(geo, box, light, prep)
    if mask is None:
        mask = np.ones((h, w), bool)
    ys, xs = np.nonzero(mask)
    uv = np.stack([xs + x0, ys + y0], axis=1).astype(np.float64)
    p, valid = geo.points_obj(uv)
    blocked = np.zeros((h, w), np.float32)
    if not valid.any():
        return blocked
    ys, xs, p = ys[valid], xs[valid], p[valid]
    org = p + RAY_EPS_M * geo.n_obj
    fade_m = _sun_fade_length(geo, prep, s_obj, sun.half_angle_rad, settings)
    hit0 = _sun_block_weight(prep, org, np.broadcast_to(s_obj, org.shape), geo.n_obj, fade_m)
    stats["rays"]["shadow_sun"] = stats["rays"].get("shadow_sun", 0) + int(len(org))
    blocked[ys, xs] = hit0
    # Edge pixels: the 3 x 3 neighbourhood is not uniform, or the edge of a triangle's shadow crosses
    # the pixel without the pixel being deep inside the shadow (thin parts: their shadow is thinner
    # than a pixel and the centre rays miss most of it).
    b8 = (blocked > 0).astype(np.uint8)
    k3 = np.ones((3, 3), np.uint8)
    core = cv2.erode(b8, k3, borderType=cv2.BORDER_REPLICATE)
    edge = (cv2.dilate(b8, k3) != core) & mask
    crossed = _shadow_edge_pixels(geo, box, prep, s_obj)
    if crossed is not None:
        edge |= crossed & mask & (core == 0)
    ey, ex = np.nonzero(edge)
    ns = settings.shadow_sun_dirs
    if len(ey) and ns > 1:
        n = int(np.ceil(np.sqrt(ns)))
        g = (np.arange(n) + 0.5) / n - 0.5
        offs = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)[:ns]  # stratified sub-pixel grid
        E_n = len(ey)
        pix_uv = np.stack([ex + x0, ey + y0], axis=1).astype(np.float64)
        sub_uv = (pix_uv[:, None, :] + offs[None] + (rng.random((E_n, len(offs), 2)) - 0.5) / n).reshape(-1, 2)
        depth_uv = np.repeat(pix_uv, len(offs), axis=0)
        sp, svalid = geo.points_obj(sub_uv, depth_uv)
        dirs = sample_cone(s_obj, sun.half_angle_rad, rng.random(len(sub_uv)), rng.random(len(sub_uv)))
        dirs = np.where((dirs @ geo.n_obj > 0)[:, None], dirs, s_obj)
        hit = _sun_block_weight(prep, sp + RAY_EPS_M * geo.n_obj, dirs, geo.n_obj, fade_m) * svalid
        stats["rays"]["shadow_sun"] += int(len(sub_uv))
        blocked[ey, ex] = hit.reshape(E_n, len(offs)).mean(axis=1)
    stats["sun_edge_pixels"] = int(len(ey))
    return blocked


def _sun_fade_length(geo: _Ground, prep: PreparedAsset, s_obj: np.ndarray, half_angle_rad: float,
                     settings: RenderSettings) -> float | None:
    """``settings.shadow_max_length_m`` if the object's sun shadow (disc included) can reach beyond the
    fade's start (:data:`~.footprint.SUN_FADE_START` of it), else None (no fade: plain occlusion rays)."""
    sin_e = float(np.clip(s_obj @ geo.n_obj, -1.0, 1.0))
    elev = np.arcsin(sin_e) - half_angle_rad
    top = float(max((prep.asset.vertices @ geo.n_obj).max(), 0.0))
    reach = np.inf if elev <= 1e-6 else top / np.tan(elev)
    return settings.shadow_max_length_m if reach > SUN_FADE_START * settings.shadow_max_length_m else None


def _sun_block_weight(prep: PreparedAsset, org: np.ndarray, dirs: np.ndarray, n_obj: np.ndarray,
                      fade_m: float | None) -> np.ndarray:
    """(N,) float64 how much each ray towards the sun is blocked: 0/1, or with ``fade_m`` the
    :func:`~.footprint.fade_weight` of the horizontal distance (along the ground) to the nearest hit."""
    if fade_m is None:
        return prep.scene.occluded(org, dirs).astype(np.float64)
    hits = prep.scene.intersect(org, dirs)
    horiz = hits.t * np.sqrt(np.clip(1.0 - (dirs @ n_obj) ** 2, 0.0, 1.0))
    return np.where(hits.hit, fade_weight(np.where(hits.hit, horiz, 0.0), fade_m, SUN_FADE_START), 0.0)


def _hemisphere_sky(env: np.ndarray, n_obj: np.ndarray, R: np.ndarray, n_dirs: int,
                    z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sky seen by the spiral of points inside the object's bounding sphere (the whole hemisphere around
    ``n_obj``), for each of the :data:`SKY_ROTATIONS` rotations: radiance (SKY_ROTATIONS, n_dirs, 3) of the
    cell-filtered map ``env`` along each direction, the sky irradiance (SKY_ROTATIONS, 3) they estimate
    (each standing for ``2 pi / n_dirs`` sr, with its cosine ``z`` (n_dirs,)), and the directions
    (SKY_ROTATIONS, n_dirs, 3), object frame."""
    phi = GOLDEN_ANGLE * np.arange(n_dirs)[None] + (np.arange(SKY_ROTATIONS) * (2 * np.pi / SKY_ROTATIONS))[:, None]
    rr = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))[None]
    local = np.stack([rr * np.cos(phi), rr * np.sin(phi), np.broadcast_to(z[None], phi.shape)], axis=2).reshape(-1, 3)
    dirs = to_world(local, np.broadcast_to(n_obj, local.shape))
    L = sample_equirect(env, *camera_dir_to_lonlat(dirs @ R.T)).reshape(SKY_ROTATIONS, n_dirs, 3)
    return L, np.einsum("rkc,k->rc", L, 2 * np.pi / n_dirs * z), dirs.reshape(SKY_ROTATIONS, n_dirs, 3)
