"""Building the hybrid lighting of a scene from what it offers: images, depth (LiDAR densified), poses, sun, sky.

Frames: everything is built in the *volume frame* (z up, metres; see :mod:`.volume`), radiance on the
reference camera's radiometric scale (other cameras' pixels are divided by their exposure ratio).

Steps (all vectorised):

1. :func:`observe_view` — per camera, on a <= 480 px wide copy of the image: linear HDR pixels, a dense depth
   (LiDAR densified with the ground plane below the horizon; without LiDAR a street canyon: the ground and
   two facades ``CANYON_HALF_WIDTH_M`` either side), extended *up* each
   image column to the sky line (vertical facades: non-sky pixels above the highest depth keep its depth),
   a sky mask; pixels are unprojected to volume-frame points with their radiance and viewing direction.
2. :func:`build_sky_dome` — the parametric sky (sun from the ephemeris, cloud cover and scale fitted to the
   image) as a world-convention equirect map, corrected towards the observed sky: observed sky pixels (and
   non-sky pixels beyond the volume: distant scenery) replace the model where seen; elsewhere the model is
   multiplied by the median observed/model ratio, blended smoothly into the observations' neighbourhood.
3. :func:`build_volume` — VSG voxels:

   * *observed*: voxels holding unprojected pixels: alpha 1, the mean radiance, the mean viewing direction as
     the lobe axis, a broad lobe (near-diffuse surfaces);
   * *the ground continuing*: every voxel below z = 0 is solid;
   * *LiDAR occupancy* in all directions (also outside the cameras' view);
   * *street-canyon prior*: structure columns that touch the ground are filled down to it; columns whose top
     is cut off by the sensors' vertical field of view are raised to the canyon height (median height of the
     structures the cameras saw whole, else ``DEFAULT_CANYON_HEIGHT_M``) — the same height on both sides of
     the street (symmetry) and behind the camera;
   * standing structures thickened away from the centre so that rays cannot step over them;
   * *unobserved surfaces are shaded*: ``a max(n.s, 0) tau_sun + b (1 + n_z) / 2`` (sun + sky, Lambertian) with
     the sun's transmittance ``tau_sun`` traced through the volume itself (cast shadows of buildings on unseen
     ground and facades), normals from the occupancy gradient, and ``a``, ``b`` (albedo/pi x sun / sky
     irradiance, per class ground / structure and channel) fitted to the observed surfaces (:func:`_fit_shading`);
   * *the street continues along its axis* (:mod:`.fill`): an unobserved surface's shading is multiplied by
     the observed/shaded ratio (its material) of the observed surfaces at the same lateral offset from the
     ego's line of travel and the same height, wherever along the street they are (shrunk towards 1 where few
     were observed): the road, kerbs, hedges and facades behind and beside look like those ahead;
   * interior voxels copy the colour of a neighbouring surface voxel (nearest-neighbour lookups may land
     a voxel or two inside).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from scipy import ndimage

from ..core import check_shape, ldr_uint8_to_hdr, luminance, transform_points
from .fill import lateral_offsets_m, street_axis_xy, street_extrusion
from .volume import CH_ALPHA, CH_AXIS, CH_COLOR, CH_SIGMA, N_CHANNELS, HybridLighting, LogGrid, world_envmap_directions

WORK_WIDTH = 480
GROUND_SNAP_M = 0.3  # points below this height are ground (moved into the solid ground layer)
STRUCTURE_MIN_TOP_M = 2.5  # columns reaching higher are structures (walls, trees), lower ones objects
TOUCH_GROUND_M = 1.5  # a column with occupancy below this height stands on the ground: filled down to it
DEFAULT_CANYON_HEIGHT_M = 12.0
CANYON_HALF_WIDTH_M = 12.0  # without LiDAR: facades this far either side of the camera's street axis
LIDAR_MAX_ELEVATION_DEG = 10.7  # nuScenes HDL-32E: -30.67 .. +10.67 deg
SIGMA_SURFACE = 2.0  # lobe sharpness of surfaces (broad: near-diffuse)
SATURATED_LDR = 0.97
EGO_BOX_EGO_M = ((-1.5, 4.0), (-1.2, 1.2), (-0.5, 2.2))  # LiDAR returns inside the ego car are dropped
THICKEN_VOXELS = 2
SKY_GAIN_KAPPA = 2.0  # several cameras: von Mises weight of a camera's sky correction over azimuth (~60 deg wide)
SHADOW_SAMPLES = 48  # samples of the sun-visibility rays that shade unobserved surfaces
STREET_PRIOR_WEIGHT = 3.0  # the shading model counts as this many observed voxels of a street cell (see .fill);
# chosen a priori (a cell needs a few observed voxels to outweigh the model), not fitted to any scene


@dataclass(frozen=True)
class ViewObservation:
    """What one camera tells about the scene, in the volume frame on the reference radiometric scale.

    Attributes:
        channel: camera channel.
        points: (M, 3) float64 unprojected pixels (depth known, inside the scene), volume frame, metres.
        radiance: (M, 3) float32 their linear radiance (reference scale).
        view_dirs: (M, 3) float64 unit directions from the points towards the camera.
        capped: (M,) bool, the point's image column is structure up to the image's top edge.
        far_dirs: (F, 3) float64 unit directions of pixels at infinity (sky; callers add what lies beyond the volume).
        far_radiance: (F, 3) float32 their radiance.
        far_is_sky: (F,) bool, True for sky pixels (False: distant scenery).
        far_saturated: (F,) bool, the pixel is clipped (its radiance is a lower bound).
        camera_centre: (3,) camera centre in the volume frame.
        ego_forward: (3,) unit forward axis of the ego vehicle in the volume frame (the street's direction), or None.
    """

    channel: str
    points: np.ndarray
    radiance: np.ndarray
    view_dirs: np.ndarray
    capped: np.ndarray
    far_dirs: np.ndarray
    far_radiance: np.ndarray
    far_is_sky: np.ndarray
    far_saturated: np.ndarray
    camera_centre: np.ndarray
    ego_forward: np.ndarray | None = None


def extend_facades(depth_m: np.ndarray, sky: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) with each column's non-sky pixels above its highest known depth set to that depth, and
    the (W,) bool columns whose structure reaches the image's top edge (their true top is not seen).

    Vertical-facade prior: for a level camera, a vertical wall has the same camera-z all the way up.
    """
    finite = np.isfinite(depth_m)
    H, W = depth_m.shape
    has = finite.any(axis=0)
    top = np.where(has, finite.argmax(axis=0), H)
    top_depth = depth_m[np.minimum(top, H - 1), np.arange(W)]
    rows = np.arange(H)[:, None]
    above = (rows < top[None, :]) & ~sky & has[None, :]
    # stop at the first sky pixel met going up from the top depth
    sky_above = np.where(sky & (rows < top[None, :]), rows, -1).max(axis=0)
    above &= rows > sky_above[None, :]
    out = depth_m.copy()
    out[above] = np.broadcast_to(top_depth[None, :], depth_m.shape)[above]
    capped = np.isfinite(out[0]) & ~sky[0]
    return out, capped


def canyon_depth(K: np.ndarray, width: int, height: int, T_vol_from_cam: np.ndarray,
                 half_width_m: float = CANYON_HALF_WIDTH_M) -> np.ndarray:
    """Camera-z depth (H, W) float32 of a street canyon without LiDAR: the ground z = 0 and two vertical walls
    at y = +-``half_width_m`` (volume frame, parallel to its x axis), whichever a pixel's ray meets first."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(K).T  # camera z = 1
    T = np.asarray(T_vol_from_cam)
    d = rays @ T[:3, :3].T
    o = T[:3, 3]
    t = np.full(u.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value in ((2, 0.0), (1, half_width_m), (1, -half_width_m)):
            ti = (value - o[axis]) / d[..., axis]
            t = np.where((ti > 0) & np.isfinite(ti), np.minimum(t, ti), t)
    return t.astype(np.float32)  # t along rays with camera z = 1 is the z-depth


def observe_view(view, T_vol_from_cam: np.ndarray, exposure_ratio: float, lidar_points_cam: np.ndarray | None,
                 ground_plane_cam: tuple[np.ndarray, float], work_width: int = WORK_WIDTH,
                 work=None) -> ViewObservation:
    """Unproject one camera's image (see module doc, step 1).

    Args:
        view: a ``CameraView`` (image, K, channel).
        T_vol_from_cam: (4, 4) camera -> volume frame.
        exposure_ratio: this image's scale / the reference scale (pixels are divided by it).
        lidar_points_cam: (N, 3) LiDAR points in this camera's frame, or None.
        ground_plane_cam: (normal (3,), offset d) of the ground ``n . p + d = 0`` in the camera frame.
        work: the L1 fit's prepared image of this view (reused for the sky mask), or None.
    """
    from ..core.depth import densify_lidar_depth
    from .estimate import _prepare, _sky_mask, downscale_image

    image = np.asarray(view.image)
    check_shape(image, ("H", "W", 3), "image")
    small, Ks = downscale_image(image, view.K, work_width)
    h, w = small.shape[:2]
    normal, offset = ground_plane_cam
    up_cam = np.asarray(T_vol_from_cam)[2, :3]  # volume +z in the camera frame
    if work is None:
        work = _prepare(image, view.K, up_cam / np.linalg.norm(up_cam), lidar_points_cam)
    sky = _sky_mask(work)
    if sky.shape != (h, w):
        sky = cv2.resize(sky.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    if lidar_points_cam is not None and len(lidar_points_cam):
        depth = densify_lidar_depth(lidar_points_cam, Ks, w, h, ground_fill=(normal, offset))
    else:
        depth = canyon_depth(Ks, w, h, T_vol_from_cam)
    depth = np.where(sky, np.inf, depth)
    depth, capped_cols = extend_facades(depth, sky)
    hdr = ldr_uint8_to_hdr(small).astype(np.float32) / np.float32(exposure_ratio)
    ldr_max = small.max(axis=-1) / 255.0
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(Ks).T  # z = 1
    near = np.isfinite(depth)
    R = np.asarray(T_vol_from_cam)[:3, :3]
    centre = np.asarray(T_vol_from_cam)[:3, 3]
    p_vol = transform_points(T_vol_from_cam, rays[near] * depth[near][:, None])
    view_dirs = centre[None] - p_vol
    view_dirs /= np.maximum(np.linalg.norm(view_dirs, axis=1, keepdims=True), 1e-9)
    far = ~near
    d_far = rays[far] @ R.T
    d_far /= np.linalg.norm(d_far, axis=1, keepdims=True)
    capped = np.broadcast_to(capped_cols[None, :], (h, w))[near]
    return ViewObservation(
        channel=view.channel, points=p_vol, radiance=hdr[near], view_dirs=view_dirs, capped=capped,
        far_dirs=d_far, far_radiance=hdr[far], far_is_sky=sky[far], far_saturated=ldr_max[far] >= SATURATED_LDR,
        camera_centre=centre, ego_forward=_ego_forward(view, T_vol_from_cam),
    )


def _ego_forward(view, T_vol_from_cam: np.ndarray) -> np.ndarray | None:
    """The ego's forward axis (3,) in the volume frame, or None if the view has no ego pose."""
    T_ge, T_gc = getattr(view, "T_global_from_ego", None), getattr(view, "T_global_from_cam", None)
    if T_ge is None or T_gc is None:
        return None
    R = np.asarray(T_vol_from_cam)[:3, :3] @ np.asarray(T_gc)[:3, :3].T @ np.asarray(T_ge)[:3, :3]
    return R[:, 0]


# ----------------------------------------------------------------------------- sky dome


def build_sky_dome(model_world: np.ndarray, observations: list[ViewObservation], blur_deg: float = 12.0) -> tuple[np.ndarray, dict]:
    """Sky dome (H, W, 3) float32 (world convention, sun excluded): the model corrected by observed pixels at infinity.

    Args:
        model_world: (H, W, 3) parametric sky (+ ground below the horizon) on the reference scale.
        observations: their ``far_*`` pixels are used.
    Returns:
        (dome, stats) with the global sky correction (per channel) and the observed fraction of the dome.
    """
    check_shape(model_world, ("H", "W", 3), "model_world")
    H, W = model_world.shape[:2]
    model = np.maximum(model_world.astype(np.float64), 1e-9)
    dirs = np.concatenate([o.far_dirs for o in observations]) if observations else np.zeros((0, 3))
    rgb = np.concatenate([o.far_radiance for o in observations]) if observations else np.zeros((0, 3))
    is_sky = np.concatenate([o.far_is_sky for o in observations]) if observations else np.zeros(0, bool)
    sat = np.concatenate([o.far_saturated for o in observations]) if observations else np.zeros(0, bool)
    stats = {"observed_fraction": 0.0, "sky_gain_rgb": [1.0, 1.0, 1.0], "observed_pixels": int(len(dirs))}
    if len(dirs) == 0:
        return model_world.astype(np.float32), stats
    lon = np.arctan2(dirs[:, 1], dirs[:, 0])
    lat = np.arcsin(np.clip(dirs[:, 2], -1, 1))
    col = np.clip(((lon / (2 * np.pi) + 0.5) * W).astype(np.int64), 0, W - 1)
    row = np.clip(((0.5 - lat / np.pi) * H).astype(np.int64), 0, H - 1)
    pix = row * W + col
    ok = ~sat
    count = np.bincount(pix[ok], minlength=H * W).astype(np.float64)
    sums = np.stack([np.bincount(pix[ok], rgb[ok, c], minlength=H * W) for c in range(3)], axis=1)
    observed = (count > 0).reshape(H, W)
    mean_obs = (sums / np.maximum(count, 1)[:, None]).reshape(H, W, 3)
    # clipped pixels: the sky is at least that bright there
    floor = np.zeros(H * W)
    if sat.any():
        np.maximum.at(floor, pix[sat], luminance(rgb[sat]))
    floor = floor.reshape(H, W)
    # sky model corrected by the observed/model ratio as a function of elevation (median per dome row over
    # the observed sky pixels, constant beyond the observed rows): the camera's sky (haze, white balance,
    # clouds) differs from the clear-sky model mostly with elevation
    upper = (np.arange(H) + 0.5 < H / 2)[:, None] & np.ones((1, W), bool)
    sel = is_sky & (dirs[:, 2] > 0.02)
    log_gain = np.zeros((H, W, 3))
    gain = np.ones(3)
    if sel.sum() >= 20:
        log_ratio = np.log(np.maximum(rgb[sel], 1e-9) / model.reshape(-1, 3)[pix[sel]])
        # a clipped pixel only says "at least": no correction unless the model is dimmer than the clip level
        log_ratio[sat[sel]] = np.maximum(log_ratio[sat[sel]], 0.0)
        gain = np.exp(np.median(log_ratio, axis=0))
        view = np.concatenate([np.full(len(o.far_dirs), i) for i, o in enumerate(observations)])[sel]
        rows, lon_sel = row[sel], lon[sel]
        per_view = [v for v in range(len(observations)) if (view == v).sum() >= 20]
        if len(per_view) < 2:
            log_gain[:] = _row_log_gains(log_ratio, rows, H)[:, None, :]
        else:
            # several cameras' skies: each corrects the sky around its own azimuth (the sky near the sun, or
            # one camera's haze, is not every direction's)
            col_lon = (np.arange(W) + 0.5) / W * 2 * np.pi - np.pi
            weights = []
            for v in per_view:
                m = view == v
                centre = np.arctan2(np.sin(lon_sel[m]).sum(), np.cos(lon_sel[m]).sum())
                weights.append(m.sum() * np.exp(SKY_GAIN_KAPPA * (np.cos(col_lon - centre) - 1.0)))
                log_gain += _row_log_gains(log_ratio[m], rows[m], H)[:, None, :] * weights[-1][None, :, None]
            log_gain /= np.sum(weights, axis=0)[None, :, None]
    log_gain = np.clip(log_gain, np.log(0.1), np.log(10.0))
    corrected = model * np.where(upper[..., None], np.exp(log_gain), 1.0)
    # blend the observations into their neighbourhood (normalised convolution of the log ratio)
    log_res = np.where(observed[..., None], np.log(np.maximum(mean_obs, 1e-9) / corrected), 0.0)
    sig = blur_deg / 360.0 * W
    wmap = observed.astype(np.float64)
    pad = int(3 * sig) + 1
    wp = np.pad(wmap, ((0, 0), (pad, pad)), mode="wrap")
    rp = np.pad(log_res * wmap[..., None], ((0, 0), (pad, pad), (0, 0)), mode="wrap")
    wb = cv2.GaussianBlur(wp, (0, 0), sig)[:, pad:-pad]
    rb = cv2.GaussianBlur(rp, (0, 0), sig)[:, pad:-pad]
    conf = np.clip(wb / 0.5, 0.0, 1.0)
    smooth = rb / np.maximum(wb, 1e-9)[..., None] * conf[..., None]
    dome = np.where(observed[..., None], mean_obs, corrected * np.exp(smooth))
    lum = np.maximum(luminance(dome), 1e-12)
    dome = dome * np.maximum(1.0, floor / lum)[..., None]
    stats.update(observed_fraction=float(observed.mean()), sky_gain_rgb=gain.tolist())
    return dome.astype(np.float32), stats


def _row_log_gains(log_ratio: np.ndarray, rows: np.ndarray, H: int) -> np.ndarray:
    """(H, 3) log sky correction per dome row: the median log ratio of the rows with >= 5 sky pixels (upper
    half), interpolated between them; beyond the observed rows (towards the zenith, say) the overall median,
    not the last row's: one row of an image's top edge (a glare, a bright cloud) does not speak for the sky
    above it."""
    overall = np.median(log_ratio, axis=0)
    have = np.flatnonzero(np.bincount(rows, minlength=H) >= 5)
    have = have[have < H // 2]
    if not len(have):
        return np.broadcast_to(overall, (H, 3)).copy()
    med = np.array([np.median(log_ratio[rows == r], axis=0) for r in have])
    return np.stack([np.interp(np.arange(H), have, med[:, c], left=overall[c], right=overall[c]) for c in range(3)],
                    axis=1)


def model_sky_world(sun_dir_vol: np.ndarray, turbidity: float, cloud_cover: float, ground_albedo: float, scale: float,
                    height: int = 64, width: int = 256) -> np.ndarray:
    """The parametric sky (+ Lambertian ground below the horizon) as a world-convention map (H, W, 3), sun excluded."""
    from .sky import sky_radiance

    d = world_envmap_directions(height, width).reshape(-1, 3)
    rad = sky_radiance(d, sun_dir_vol, turbidity, cloud_cover, ground_albedo) * scale
    return rad.reshape(height, width, 3).astype(np.float32)


# ----------------------------------------------------------------------------- volume


def structure_heights(top_m: np.ndarray, cam_top_m: np.ndarray, cam_capped: np.ndarray, r_xy_m: np.ndarray,
                      standing: np.ndarray) -> tuple[np.ndarray, dict]:
    """Street-canyon prior on a grid of columns: the height each column's structure is raised to.

    A standing structure (touching the ground) whose top the sensors could not see — at or near the LiDAR's
    upper field-of-view limit and not seen whole by a camera, or reaching the top edge of an image — is
    raised to the median of the heights the cameras saw whole (sky above) that exceed its observed top
    (a conditional median; ``DEFAULT_CANYON_HEIGHT_M`` without such observations).

    Args:
        top_m: (...) observed top height per column (0 where nothing stands), metres above the ground.
        cam_top_m: (...) highest unprojected camera pixel per column (-inf where none).
        cam_capped: (...) bool, some camera pixel of the column comes from an image column cut by the image top.
        r_xy_m: (...) horizontal distance of the column from the volume origin (the LiDAR's position).
        standing: (...) bool, columns whose structure touches the ground.
    Returns:
        (heights (...), stats) with the raised heights (never below ``top_m``).
    """
    lidar_limit = 1.84 + r_xy_m * np.tan(np.radians(LIDAR_MAX_ELEVATION_DEG))
    # a camera saw the top: its highest pixel is the column's top and the image column ends in sky
    seen_whole = standing & ~cam_capped & (cam_top_m >= top_m - 1.0) & (cam_top_m >= STRUCTURE_MIN_TOP_M)
    cut = standing & ~seen_whole & ((top_m >= np.maximum(0.8 * lidar_limit, STRUCTURE_MIN_TOP_M)) | cam_capped)
    seen = np.sort(cam_top_m[seen_whole])
    heights = top_m.copy()
    if cut.any():
        bound = top_m[cut]
        if len(seen) >= 8:
            # conditional median of the seen heights above each bound
            k = np.searchsorted(seen, bound, side="right")
            n_above = len(seen) - k
            mid = np.minimum(k + n_above // 2, len(seen) - 1)
            est = np.where(n_above > 0, seen[mid], 1.25 * bound)
        else:
            est = np.maximum(bound, DEFAULT_CANYON_HEIGHT_M)
        heights[cut] = np.clip(np.maximum(est, bound), 0.0, 80.0)
    stats = {"seen_whole_columns": int(seen_whole.sum()), "raised_columns": int(cut.sum()),
             "median_seen_height_m": float(np.median(seen)) if len(seen) else None}
    return heights, stats


def _shift_outward(mask: np.ndarray, axis: int) -> np.ndarray:
    """Grow ``mask`` by one voxel along ``axis`` away from the grid's centre plane."""
    n = mask.shape[axis]
    c = n // 2
    out = mask.copy()
    hi = [slice(None)] * 3
    lo = [slice(None)] * 3
    # upper half: voxel i gets i - 1
    hi[axis], lo[axis] = slice(c + 1, n), slice(c, n - 1)
    out[tuple(hi)] |= mask[tuple(lo)]
    # lower half: voxel i gets i + 1
    hi[axis], lo[axis] = slice(0, c - 1), slice(1, c)
    out[tuple(hi)] |= mask[tuple(lo)]
    return out


@dataclass(frozen=True)
class DistantSun:
    """The distant light used to shade unobserved surfaces (volume frame, reference scale).

    Attributes:
        sun_dir: (3,) unit vector towards the sun, or None.
        sun_irradiance: (3,) irradiance of the sun facing it (clouds applied).
        sky_irradiance_h: (3,) irradiance of the sky on a horizontal surface.
    """

    sun_dir: np.ndarray | None
    sun_irradiance: np.ndarray
    sky_irradiance_h: np.ndarray


def build_volume(grid: LogGrid, observations: list[ViewObservation], lidar_points_vol: np.ndarray | None,
                 light: DistantSun, sky_world: np.ndarray, ground_albedo: float = 0.15) -> tuple[torch.Tensor, dict]:
    """VSG parameters (X, Y, Z, 8) float32 tensor of a scene (see module doc, step 3), and build statistics."""
    X, Y, Z = grid.shape
    n = grid.n_voxels
    stats: dict = {}
    pts = np.concatenate([o.points for o in observations]) if observations else np.zeros((0, 3))
    rgb = np.concatenate([o.radiance for o in observations]).astype(np.float64) if observations else np.zeros((0, 3))
    vd = np.concatenate([o.view_dirs for o in observations]) if observations else np.zeros((0, 3))
    cap = np.concatenate([o.capped for o in observations]) if observations else np.zeros(0, bool)
    pts = pts.copy()
    is_ground_pt = pts[:, 2] < GROUND_SNAP_M
    pts[is_ground_pt, 2] = -0.05  # into the top ground layer
    flat, inside = grid.flat_index(torch.from_numpy(pts))
    flat, inside = flat.numpy(), inside.numpy()
    flat, rgb, vd = flat[inside], rgb[inside], vd[inside]
    count = np.bincount(flat, minlength=n).astype(np.float64)
    observed = (count > 0).reshape(grid.shape)
    col_sum = np.stack([np.bincount(flat, rgb[:, c], minlength=n) for c in range(3)], axis=1)
    dir_sum = np.stack([np.bincount(flat, vd[:, c], minlength=n) for c in range(3)], axis=1)
    obs_rgb = col_sum / np.maximum(count, 1)[:, None]
    stats["observed_voxels"] = int(observed.sum())

    # occupancy
    occ = observed.copy()
    occ[:, :, : grid.n_below] = True  # the ground continues everywhere
    if lidar_points_vol is not None and len(lidar_points_vol):
        lp = lidar_points_vol[lidar_points_vol[:, 2] >= GROUND_SNAP_M]
        lf, lin = grid.flat_index(torch.from_numpy(np.ascontiguousarray(lp)))
        lf = lf.numpy()[lin.numpy()]
        occ.reshape(-1)[lf] = True
        stats["lidar_voxels"] = int(len(np.unique(lf)))
    above = occ.copy()
    above[:, :, : grid.n_below] = False

    # street-canyon prior: columns
    z_edges = grid.axis_edges()[2]
    z_lo, z_hi = z_edges[:-1], z_edges[1:]
    any_above = above.any(axis=2)
    top_k = np.where(any_above, Z - 1 - np.argmax(above[:, :, ::-1], axis=2), -1)
    top_z = np.where(any_above, z_hi[np.maximum(top_k, 0)], 0.0)
    low_k = np.searchsorted(z_edges, TOUCH_GROUND_M) - 1
    touches = above[:, :, grid.n_below : low_k + 1].any(axis=2)
    structure = any_above & (top_z >= STRUCTURE_MIN_TOP_M)
    centres_xy = grid.voxel_centres()[:, :, 0, :2]
    r_xy = np.linalg.norm(centres_xy, axis=-1)
    cam_top = np.full((X, Y), -np.inf)
    cam_capped = np.zeros((X, Y), bool)
    if len(pts):
        cf = flat // Z
        np.maximum.at(cam_top.reshape(-1), cf, pts[inside, 2])
        cam_capped.reshape(-1)[cf[cap[inside]]] = True
    target_top, canyon = structure_heights(top_z, cam_top, cam_capped, r_xy, structure & touches)
    capped = target_top > top_z + 1e-6
    stats["canyon"] = canyon
    zc = 0.5 * (z_lo + z_hi)
    column_fill = touches[..., None] & (zc[None, None, :] >= 0) & (zc[None, None, :] <= target_top[..., None])
    # overhangs (canopies): fill between the lowest and highest occupied voxel only
    low_occ = np.where(any_above, np.argmax(above, axis=2), Z)
    slab = (any_above & ~touches)[..., None] & (np.arange(Z)[None, None, :] >= low_occ[..., None]) & (
        np.arange(Z)[None, None, :] <= top_k[..., None])
    walls = column_fill & structure[..., None]
    for _ in range(THICKEN_VOXELS):  # only standing structures: canopies and poles keep their size
        walls = _shift_outward(_shift_outward(walls, 0), 1)
    above |= column_fill | slab | walls
    occ = above.copy()
    occ[:, :, : grid.n_below] = True
    stats["occupied_fraction"] = float(occ.mean())
    stats["extruded_columns"] = int(capped.sum())

    # surfaces: occupied voxels with a free 6-neighbour
    free = ~occ
    nb_free = np.zeros_like(occ)
    for a in range(3):
        nb_free |= np.roll(free, 1, axis=a) | np.roll(free, -1, axis=a)
    surface = occ & nb_free
    surface[:, :, : grid.n_below - 1] = False  # deep ground (np.roll wraps the free top layer onto it)

    # normals: minus the metric gradient of the blurred occupancy; ground: up
    blurred = ndimage.gaussian_filter(occ.astype(np.float32), 1.0)
    edges = grid.axis_edges()
    sizes = [np.diff(e) for e in edges]
    g = np.gradient(blurred)
    normal = -np.stack([g[0] / sizes[0][:, None, None], g[1] / sizes[1][None, :, None], g[2] / sizes[2][None, None, :]], -1)
    normal[:, :, : grid.n_below] = (0.0, 0.0, 1.0)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-9)

    # shading model of surfaces
    s_idx = np.flatnonzero(surface.reshape(-1))
    centres = grid.voxel_centres().reshape(-1, 3)
    n_s = normal.reshape(-1, 3)[s_idx]
    size_s = np.stack(np.meshgrid(*sizes, indexing="ij"), -1).reshape(-1, 3)[s_idx]
    p_s = centres[s_idx] + n_s * 0.6 * size_s
    ground_s = s_idx % Z < grid.n_below
    p_s[ground_s, 2] = 0.05
    alpha_t = torch.from_numpy(occ.astype(np.float32))
    params = torch.zeros((X, Y, Z, N_CHANNELS), dtype=torch.float32)
    params[..., CH_ALPHA] = alpha_t
    tau = np.zeros(len(s_idx))
    if light.sun_dir is not None and len(s_idx):
        probe = HybridLighting(torch.from_numpy(sky_world), grid=grid, params=params, n_samples=SHADOW_SAMPLES)
        with torch.no_grad():
            tau = probe.transmittance(p_s, np.repeat(light.sun_dir[None], len(p_s), axis=0)).numpy().astype(np.float64)
        cos_s = np.maximum(n_s @ light.sun_dir, 0.0)
    else:
        cos_s = np.zeros(len(s_idx))
    direct = cos_s * tau  # (S,) fraction of the sun's irradiance each surface receives
    sky_view = (1.0 + n_s[:, 2]) / 2.0  # (S,) fraction of the open sky a surface with this normal sees
    obs_s = observed.reshape(-1)[s_idx]
    shaded = np.zeros((len(s_idx), 3))
    for cls, name, default in ((ground_s, "ground", ground_albedo / np.pi), (~ground_s, "structure", 0.25 / np.pi)):
        coef, how = _fit_shading(direct[cls & obs_s], sky_view[cls & obs_s], obs_rgb[s_idx[cls & obs_s]],
                                 default * light.sun_irradiance, default * light.sky_irradiance_h)
        shaded[cls] = direct[cls, None] * coef[0][None] + sky_view[cls, None] * coef[1][None]
        stats[f"shading_{name}"] = {"sun_rgb": coef[0].tolist(), "sky_rgb": coef[1].tolist(), "from": how}
    # street prior (see .fill): the materials of the observed surfaces continue along the street; an unobserved
    # surface keeps its own shading (sun, shadow, sky) times the observed/shaded ratio of its street cell
    if np.isfinite(STREET_PRIOR_WEIGHT):  # inf: the shading model alone (ablation)
        axis_xy = street_axis_xy(next((o.ego_forward for o in observations if o.ego_forward is not None), None))
        lat_m = lateral_offsets_m(centres[s_idx, :2], axis_xy)
        k_s = s_idx % Z
        unobs = ~obs_s
        # a surface voxel's centre sits up to half its size (plus the walls' thickening) off the surface
        half_w = (0.5 + THICKEN_VOXELS) * size_s[unobs, :2].max(axis=1)
        sums = street_extrusion(lat_m[obs_s], k_s[obs_s], np.concatenate([obs_rgb[s_idx[obs_s]], shaded[obs_s]], 1),
                                lat_m[unobs], k_s[unobs], half_w, np.concatenate([shaded[unobs], shaded[unobs]], 1),
                                STREET_PRIOR_WEIGHT, Z)
        shaded[unobs] *= sums[:, :3] / np.maximum(sums[:, 3:], 1e-9)
        stats["street_axis_xy"] = axis_xy.tolist()
    color = np.zeros((n, 3))
    color[s_idx] = shaded
    obs_idx = np.flatnonzero(observed.reshape(-1))
    color[obs_idx] = obs_rgb[obs_idx]
    axis = np.zeros((n, 3))
    axis[s_idx] = n_s
    vdir = dir_sum[obs_idx] / np.maximum(np.linalg.norm(dir_sum[obs_idx], axis=1, keepdims=True), 1e-9)
    axis[obs_idx] = vdir
    # interior voxels: grow the known colours inwards (rays step at most a voxel or two past a surface);
    # deeper voxels get the mean surface colour
    known = np.zeros(n, bool)
    known[s_idx] = True
    known[obs_idx] = True
    color, axis = _propagate_inwards(color.reshape(*grid.shape, 3), axis.reshape(*grid.shape, 3),
                                     known.reshape(grid.shape), occ, steps=THICKEN_VOXELS + 1)
    flat_p = params.reshape(-1, N_CHANNELS)
    flat_p[:, CH_COLOR] = torch.from_numpy(color.astype(np.float32))
    axis = np.where(np.linalg.norm(axis, axis=1, keepdims=True) > 1e-6, axis, np.array([0.0, 0.0, 1.0]))
    flat_p[:, CH_AXIS] = torch.from_numpy(axis.astype(np.float32))
    flat_p[:, CH_SIGMA] = SIGMA_SURFACE
    stats["surface_voxels"] = int(len(s_idx))
    stats["sun_shadowed_surface_fraction"] = float((tau < 0.5).mean()) if len(tau) else 0.0
    return params, stats


def _fit_shading(direct: np.ndarray, sky_view: np.ndarray, observed_rgb: np.ndarray, default_sun: np.ndarray,
                 default_sky: np.ndarray, min_points: int = 20) -> tuple[tuple[np.ndarray, np.ndarray], str]:
    """Fit ``radiance = a direct + b sky_view`` (a, b: (3,) >= 0, per channel) to observed surfaces.

    ``a`` = albedo/pi x sun irradiance and ``b`` = albedo/pi x sky irradiance of the class, fitted by non-negative
    least squares when the observations contain both sunlit and shadowed surfaces; otherwise ``b`` alone is
    fitted with ``a / b`` from the defaults (the sun/sky ratio of the distant light), or the defaults are used.
    """
    from scipy.optimize import nnls

    n = len(direct)
    if n < min_points:
        return (np.asarray(default_sun, float), np.asarray(default_sky, float)), "defaults (too few observed surfaces)"
    lit = direct > 0.2
    X = np.stack([direct, sky_view], axis=1)
    if lit.sum() >= min_points // 2 and (~lit).sum() >= min_points // 2:
        a, b = np.zeros(3), np.zeros(3)
        for c in range(3):
            a[c], b[c] = nnls(X, observed_rgb[:, c])[0]
        if np.all(b > 0):
            return (a, b), f"fitted to {n} observed surfaces ({int(lit.sum())} sunlit)"
    ratio = np.asarray(default_sun, float) / np.maximum(np.asarray(default_sky, float), 1e-12)
    basis = direct[:, None] * ratio[None] + sky_view[:, None]
    b = np.median(observed_rgb / np.maximum(basis, 1e-12), axis=0)
    return (b * ratio, b), f"scale fitted to {n} observed surfaces, sun/sky ratio of the distant light"


def _propagate_inwards(color: np.ndarray, axis: np.ndarray, known: np.ndarray, occ: np.ndarray,
                       steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Colours/axes (n, 3) of occupied voxels without one, copied from known 6-neighbours ``steps`` times,
    then the mean known colour for the rest. Inputs are (X, Y, Z, 3) and (X, Y, Z) bool."""
    color, axis, known = color.copy(), axis.copy(), known.copy()
    for _ in range(steps):
        todo = occ & ~known
        if not todo.any():
            break
        for a in range(3):
            for shift in (1, -1):
                src = np.roll(known, shift, axis=a)
                take = todo & src
                if take.any():
                    color[take] = np.roll(color, shift, axis=a)[take]
                    axis[take] = np.roll(axis, shift, axis=a)[take]
                    known |= take
                    todo &= ~take
    rest = occ & ~known
    if rest.any() and known.any():
        color[rest] = color[known].mean(axis=0)
        axis[rest] = (0.0, 0.0, 1.0)
    return color.reshape(-1, 3), axis.reshape(-1, 3)


def lidar_points_in_volume(lidar, T_vol_from_global: np.ndarray) -> np.ndarray:
    """LiDAR points (N, 3) in the volume frame, without the returns from the ego car itself."""
    p_ego = transform_points(lidar.T_ego_from_lidar, lidar.points_sensor)
    (x0, x1), (y0, y1), (z0, z1) = EGO_BOX_EGO_M
    ego = (p_ego[:, 0] > x0) & (p_ego[:, 0] < x1) & (p_ego[:, 1] > y0) & (p_ego[:, 1] < y1) & (p_ego[:, 2] > z0) & (p_ego[:, 2] < z1)
    return transform_points(T_vol_from_global @ lidar.T_global_from_lidar, lidar.points_sensor[~ego])
