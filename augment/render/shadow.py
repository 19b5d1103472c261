"""The shadow ratio map of Eq. 4: how much light the inserted object takes from the scene around it.

For each scene pixel near the object: its 3D point (from the depth map, or the ground plane where
the depth is unknown), normal = the ground normal, Lambertian.  With ``E = E_sun cos + E_sky``
the unoccluded irradiance (the sky part integrated exactly from the map, the same for every point
since the light is distant)::

    S = 1 - [ (1 - V_sun) E_sun cos  +  sum_{blocked k} (L_k - L_amb) cos_k 2pi/N ] / E

``V_sun`` is the visible fraction of jittered sun-disc directions (penumbra), the sum runs over the
blocked directions of an N-direction Fibonacci lattice on the upper hemisphere (randomly rotated
per pixel, so banding turns into noise that the smoothing removes), and blocked rays see ``L_amb``,
the radiance the car itself sends back (:func:`car_ambient_radiance`) instead of the paper's 0.1.

The map is computed only in the image box that can be non-trivial -- the footprint grown by a
sky-occlusion radius plus the object's top corners projected along the sun onto the ground (clamped
to ``shadow_max_length_m``) -- every ``shadow_factor`` pixels, then smoothed and upsampled.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..conventions import luminance, project_points
from ..lighting.light import DistantLight
from .brdf import to_world
from .geometry import PreparedAsset
from .sampling import fibonacci_hemisphere, sample_cone, sky_irradiance
from .settings import RenderSettings
from .shade import lookup_equirect

SKY_RADIUS_PER_HEIGHT = 2.0  # sky occlusion beyond ~2 object heights is below a few per cent
RAY_EPS_M = 0.01
SHADOW_CHUNK_RAYS = 1_000_000  # rays per batch: bounds memory


@dataclass(frozen=True)
class ShadowMap:
    """Ratio map over a pixel box.

    Attributes:
        x0, y0: top-left pixel of the box.
        ratio_rgb: (h, w, 3) float32 per-channel ratio S in [0, 1], 1 = unchanged.
        stats: rays cast, pixels evaluated.
    """

    x0: int
    y0: int
    ratio_rgb: np.ndarray
    stats: dict = field(default_factory=dict)


def car_ambient_radiance(light: DistantLight, mean_albedo: float, up_cam: np.ndarray) -> np.ndarray:
    """Radiance (3,) the object sends along rays it blocks: ``albedo x E_sky(up) / (2 pi)``.

    A matte surface of albedo rho under a sky giving ``E_sky`` on a horizontal plane receives about
    half of it when vertical (the car's sides, which is what the ground around the car sees), so it
    reflects ``rho E_sky / (2 pi)``.  The direct sun is left out: the side facing a shadowed point is
    the side turned away from the sun.
    """
    return mean_albedo * sky_irradiance(light.envmap, up_cam) / (2.0 * np.pi)


def shadow_pixel_box(K: np.ndarray, width: int, height: int, T_cam_from_object: np.ndarray, prep: PreparedAsset,
                     light: DistantLight, settings: RenderSettings) -> tuple[int, int, int, int] | None:
    """End-exclusive pixel box (x0, y0, x1, y1) where the ratio map can differ from 1, or None."""
    V = prep.asset.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    h_obj = float(max(hi[2], 0.0))
    r = SKY_RADIUS_PER_HEIGHT * h_obj + 0.3
    ground = np.array([[x, y, 0.0] for x in (lo[0] - r, hi[0] + r) for y in (lo[1] - r, hi[1] + r)])
    pts = [ground]
    if light.sun is not None:
        s = T_cam_from_object[:3, :3].T @ np.asarray(light.sun.direction, dtype=np.float64)
        if s[2] > 1e-3:
            horiz = -s[:2] / s[2] * h_obj
            length = np.linalg.norm(horiz)
            if length > settings.shadow_max_length_m:
                horiz *= settings.shadow_max_length_m / length
            m = 0.3 + h_obj * np.tan(light.sun.half_angle_rad) * length / max(h_obj, 1e-6)
            pts.append(np.array([[x + horiz[0] + dx, y + horiz[1] + dy, 0.0]
                                 for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for dx in (-m, m) for dy in (-m, m)]))
    pts = np.concatenate(pts)
    pts_cam = pts @ T_cam_from_object[:3, :3].T + T_cam_from_object[:3, 3]
    front = pts_cam[:, 2] > 0.3
    if not front.any():
        return None
    uv, _ = project_points(K, pts_cam[front])
    x0, y0 = np.floor(uv.min(axis=0)).astype(int) - 2
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 3
    if not front.all():  # the region reaches behind the camera: extend to the bottom and the sides
        x0, x1, y1 = 0, width, height
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)
    if x1 <= x0 or y1 <= y0:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def render_shadow(K: np.ndarray, width: int, height: int, depth_m: np.ndarray, light: DistantLight, prep: PreparedAsset,
                  T_cam_from_object: np.ndarray, ground_normal_cam: np.ndarray, settings: RenderSettings,
                  rng: np.random.Generator, ambient_rgb: np.ndarray) -> ShadowMap | None:
    """The ratio map S over :func:`shadow_pixel_box` (see module docstring); None if there is nothing to do.

    Args:
        depth_m: (H, W) scene camera-z depth in metres, inf/nan/<= 0 where unknown.
        ground_normal_cam: (3,) unit normal of the ground (pointing up), camera frame; the ground plane
            passes through the object's origin.
        ambient_rgb: (3,) radiance of rays blocked by the object.
    """
    box = shadow_pixel_box(K, width, height, T_cam_from_object, prep, light, settings)
    if box is None:
        return None
    x0, y0, x1, y1 = box
    f = settings.shadow_factor
    wl, hl = -(-(x1 - x0) // f), -(-(y1 - y0) // f)
    gx = x0 + f * np.arange(wl) + (f - 1) / 2.0
    gy = y0 + f * np.arange(hl) + (f - 1) / 2.0
    GX, GY = np.meshgrid(gx, gy)
    uv = np.stack([GX.ravel(), GY.ravel()], axis=1)
    ix = np.clip(np.round(uv[:, 0]).astype(int), 0, width - 1)
    iy = np.clip(np.round(uv[:, 1]).astype(int), 0, height - 1)
    d = np.asarray(depth_m, dtype=np.float64)[iy, ix]
    n_cam = np.asarray(ground_normal_cam, dtype=np.float64)
    n_cam = n_cam / np.linalg.norm(n_cam)
    origin_cam = T_cam_from_object[:3, 3]
    # Ground-plane fallback where the depth is unknown.
    Kinv = np.linalg.inv(K)
    rays = np.einsum("ij,kj->ik", np.concatenate([uv, np.ones((len(uv), 1))], axis=1), Kinv)  # z = 1
    denom = np.einsum("ij,j->i", rays, n_cam)
    with np.errstate(divide="ignore", invalid="ignore"):
        z_plane = (origin_cam @ n_cam) / denom
    z_plane = np.where((denom < -1e-9) & (z_plane > 0), z_plane, np.inf)  # rays going down hit the ground
    z = np.where(np.isfinite(d) & (d > 0), d, z_plane)
    valid = np.isfinite(z)
    ratio = np.ones((len(uv), 3))
    E_sky = sky_irradiance(light.envmap, n_cam)
    sun = light.sun
    cos_sun = 0.0 if sun is None else float(max(np.dot(sun.direction, n_cam), 0.0))
    E_sun = np.zeros(3) if sun is None else np.asarray(sun.irradiance_rgb, dtype=np.float64) * cos_sun
    E = E_sky + E_sun
    stats = {"rays": {}, "pixels": int(valid.sum()), "grid": [int(hl), int(wl)], "box": [x0, y0, x1, y1]}
    if valid.any() and luminance(E) > 0:
        per_cell = settings.shadow_sky_dirs + (settings.shadow_sun_dirs if cos_sun > 0 else 0)
        chunk = max(1, SHADOW_CHUNK_RAYS // per_cell)
        all_sel = np.flatnonzero(valid)
        for a in range(0, len(all_sel), chunk):
            sel = all_sel[a : a + chunk]
            ratio[sel] = _ratio_cells(sel, uv, rays, z, depth_m, Kinv, width, height, f, n_cam, origin_cam,
                                      T_cam_from_object, light, prep, settings, rng, ambient_rgb, E, E_sun, cos_sun, stats)
    low = ratio.reshape(hl, wl, 3).astype(np.float32)
    if min(hl, wl) >= 3:
        low = cv2.GaussianBlur(low, (3, 3), 0.8, borderType=cv2.BORDER_REPLICATE)
    full = cv2.resize(low, (wl * f, hl * f), interpolation=cv2.INTER_LINEAR)[: y1 - y0, : x1 - x0]
    full = np.where(full > 1.0 - 1e-4, 1.0, full).astype(np.float32)
    return ShadowMap(x0=x0, y0=y0, ratio_rgb=full, stats=stats)


def _ratio_cells(sel, uv, rays, z, depth_m, Kinv, width, height, f, n_cam, origin_cam, T_cam_from_object, light,
                 prep, settings, rng, ambient_rgb, E, E_sun, cos_sun, stats) -> np.ndarray:
    """Ratio (len(sel), 3) of the low-resolution cells ``sel`` (one memory-bounded chunk of :func:`render_shadow`)."""
    sun = light.sun
    R = T_cam_from_object[:3, :3]
    p_cam = rays[sel] * z[sel, None]
    p_obj = np.einsum("ij,jk->ik", p_cam - origin_cam, R)  # R^T (p - t)
    n_obj = R.T @ n_cam
    P = len(sel)
    org = p_obj + RAY_EPS_M * n_obj
    deficit = np.zeros((P, 3))
    # -- sun: jittered directions in the disc, from jittered points over each cell's footprint
    #    (a box filter of the sharp sun-shadow edge: no staircase after upsampling).
    if cos_sun > 0:
        ns = settings.shadow_sun_dirs
        sun_obj = R.T @ np.asarray(sun.direction, dtype=np.float64)
        dirs = sample_cone(sun_obj, sun.half_angle_rad, rng.random(P * ns), rng.random(P * ns))
        dirs = np.where((np.einsum("ij,j->i", dirs, n_obj) > 0)[:, None], dirs, sun_obj)
        sub_uv = np.repeat(uv[sel], ns, axis=0) + (rng.random((P * ns, 2)) - 0.5) * f
        sub_rays = np.einsum("ij,kj->ik", np.concatenate([sub_uv, np.ones((len(sub_uv), 1))], axis=1), Kinv)
        sx = np.clip(np.round(sub_uv[:, 0]).astype(int), 0, width - 1)
        sy = np.clip(np.round(sub_uv[:, 1]).astype(int), 0, height - 1)
        sd = np.asarray(depth_m[sy, sx], dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            sz_plane = (origin_cam @ n_cam) / np.einsum("ij,j->i", sub_rays, n_cam)
        sz = np.where(np.isfinite(sd) & (sd > 0), sd, sz_plane)
        sz = np.where(np.isfinite(sz) & (sz > 0), sz, np.repeat(z[sel], ns))  # fall back to the cell centre
        sub_org = np.einsum("ij,jk->ik", sub_rays * sz[:, None] - origin_cam, R) + RAY_EPS_M * n_obj
        blocked = prep.scene.occluded(sub_org, dirs)
        stats["rays"]["shadow_sun"] = stats["rays"].get("shadow_sun", 0) + int(P * ns)
        deficit += blocked.reshape(P, ns).mean(axis=1)[:, None] * E_sun[None]
    # -- sky: randomly rotated Fibonacci lattice around the ground normal.
    N = settings.shadow_sky_dirs
    lattice = fibonacci_hemisphere(N)  # (N, 3) z-up
    phi = rng.random(P) * 2 * np.pi
    c, s_ = np.cos(phi)[:, None], np.sin(phi)[:, None]
    lx = c * lattice[None, :, 0] - s_ * lattice[None, :, 1]
    ly = s_ * lattice[None, :, 0] + c * lattice[None, :, 1]
    local = np.stack([lx, ly, np.broadcast_to(lattice[None, :, 2], lx.shape)], axis=2).reshape(-1, 3)
    dirs_obj = to_world(local, n_obj)
    blocked = prep.scene.occluded(np.repeat(org, N, axis=0), dirs_obj)
    stats["rays"]["shadow_sky"] = stats["rays"].get("shadow_sky", 0) + int(P * N)
    bi = np.flatnonzero(blocked)
    if len(bi):
        # Each lattice direction stands for a 2 pi / N sr cell: use the sky averaged over cells of
        # that size (a box-filtered map), not a point sample of a possibly spiky panorama.
        L = lookup_equirect(_cell_filtered_env(light.envmap, N), np.einsum("ij,kj->ik", dirs_obj[bi], R))
        w = local[bi, 2] * (2 * np.pi / N)
        contrib = (L - ambient_rgb[None]) * w[:, None]
        pix = bi // N
        for k in range(3):
            deficit[:, k] += np.bincount(pix, weights=contrib[:, k], minlength=P)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = 1.0 - deficit / np.where(E > 0, E, np.inf)[None]
    return np.clip(r, 0.0, 1.0)


def _cell_filtered_env(envmap: np.ndarray, n_dirs: int) -> np.ndarray:
    """The map box-filtered to about the angular size of one of ``n_dirs`` hemisphere lattice cells."""
    cell_rad = np.sqrt(2 * np.pi / n_dirs)
    width = int(2 ** np.round(np.log2(2 * np.pi / cell_rad)))
    width = int(np.clip(width, 8, envmap.shape[1]))
    if width >= envmap.shape[1]:
        return envmap
    return cv2.resize(np.asarray(envmap, dtype=np.float32), (width, max(width // 2, 1)), interpolation=cv2.INTER_AREA)
