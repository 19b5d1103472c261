"""What each camera tells about the scene: its pixels unprojected into the volume frame with their radiance.

Frames: the *volume frame* (z up, metres; see :mod:`.volume`); radiance on the reference camera's radiometric
scale (other cameras' pixels are divided by their exposure ratio). :func:`observe_view` works on a <= 480 px
wide copy of the image: linear HDR pixels, a dense depth (LiDAR densified with the ground plane below the
horizon; without LiDAR a street canyon: the ground and two facades ``CANYON_HALF_WIDTH_M`` either side),
extended *up* each image column to the sky line (vertical facades: non-sky pixels above the highest depth keep
its depth), a sky mask; pixels are unprojected to volume-frame points with their radiance and viewing direction.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy import ndimage

from ...datasets.sample import CameraView
from ..core import (SATURATION_LDR, SATURATION_RADIANCE, PinholeCamera, check_shape, ldr_uint8_to_hdr,
                    transform_points)
from ..core.depth import densify_lidar_depth
from .evidence import WORK_WIDTH as EVIDENCE_WORK_WIDTH
from .evidence import PreparedImage, downscale_image, image_sky_mask, prepare_image
from .seen_surfaces import DEPTH_UNCERTAINTY, MAX_DEPTH_RATIO, DepthView
from .volume import LogGrid

WORK_WIDTH = 480
CANYON_HALF_WIDTH_M = 12.0  # without LiDAR: facades this far either side of the camera's street axis
SATURATED_LDR = 0.97
# the seen-surface mesh continues a column above its highest known depth at the farthest such depth within this
# window (column_tops). Scene-0916 keyframes 0/8/16/24/32, six-view forward mean PSNR: the column's own 17.17 dB,
# 6 deg 17.26, 12 deg 17.25, 24 deg 17.17 (wider costs keyframes 0 and 8: near crowns pushed back). Applied to
# the volume's points as well it gave 17.37 but cost the monocular forward 0.5 dB at keyframe 0 and the other
# cameras 0.25 dB at keyframe 24, so they keep the column's own depth.
MESH_TOP_WINDOW_DEG = 6.0
# only tops this near stand for structure in their neighbours (a column that is ground up to its top has the
# plane's depth there, which grows without bound towards the horizon); one-north's L2 self view 27.95 -> 28.46 dB
TOP_FARTHEST_MAX_M = 150.0
# rows (480 px image, 2 of the mesh's steps) either side of a near top that the farther structure continued above
# it goes on behind it (mesh_backdrop): one-north L2 self view 27.86 -> 27.95 dB, scene-0916 keyframes
# 0/8/16/24/32 self views mean 27.50 -> 27.60 dB, their forward views unchanged (17.26 -> 17.27 dB)
BACKDROP_ROWS = 4
# the seen-surface mesh's relative depth uncertainty (its reprojection blur, :mod:`.seen_surfaces`) per pixel:
# DEPTH_AT_RETURN on a LiDAR return, growing linearly with the distance to the nearest return (480 px image) to
# seen_surfaces.DEPTH_UNCERTAINTY at DEPTH_SPREAD_PX; pixels whose depth is extrapolated (above the LiDAR's
# top, a facade continued up its column) and views without LiDAR keep DEPTH_UNCERTAINTY.
# Scene-0916 even stride-4 keyframes, six-view forward mean PSNR with the view blur below
# (predicted_view.SPREAD_*): 17.56 with DEPTH_UNCERTAINTY everywhere, 17.72 with these. (Without the view blur
# they change nothing: 17.37 -> 17.35.)
DEPTH_AT_RETURN = 0.02
DEPTH_SPREAD_PX = 12.0
SKY_MESH = True  # the sky pixels meshed far away (seen_surfaces.SKY_MESH_RANGE_M)
# LiDAR free space (lidar_passed_through): a pixel's point that a LiDAR beam passed on its way to a farther return
# is empty; what the pixel shows lies farther (densified depth grown over a near object's top: the sky and facades
# above a parked car's roof put on the car). The HDL-32E's rings are LIDAR_RING_DEG apart from
# LIDAR_LOWEST_RING_DEG; its returns are binned per ring and LIDAR_AZIMUTH_BIN_DEG of azimuth.
LIDAR_LOWEST_RING_DEG = -30.67
LIDAR_RING_DEG = 41.33 / 31
LIDAR_N_RINGS = 32
LIDAR_AZIMUTH_BIN_DEG = 0.4
# a return counts as "farther" when beyond the point by this (metres) + this share of the point's range
LIDAR_PASS_MARGIN_M = 0.5
LIDAR_PASS_MARGIN_SHARE = 0.05
LIDAR_PASS_WINDOW_BINS = 3  # azimuth cells either side (+-1.2 deg; the HDL-32E fires every ~0.16-0.35 deg)
LIDAR_FREE_MIN_HEIGHT_M = 0.3  # the ground and kerbs (build.GROUND_SNAP_M) are left to the ground plane
LIDAR_FREE_SPACE = True


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
        depth_view: the whole depth and radiance images (the seen-surface mesh of :mod:`.seen_surfaces`), or None.
        free_points: (M, 3) ``points`` with those a LiDAR beam passed on its way to a farther return moved along
            their rays to that return (:func:`lidar_passed_through`), or None (no LiDAR centre given). The volume
            takes them where the move changes what its centre sees (``build.observed_voxels``).
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
    depth_view: DepthView | None = None
    free_points: np.ndarray | None = None


def lidar_passed_through(points: np.ndarray, lidar_points: np.ndarray,
                         lidar_origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points (M, 3) that a LiDAR beam passed on its way to a farther return: ((M,) bool, (M,) the range
    (metres, from the LiDAR) of the nearest of those farther returns, inf elsewhere), in any one frame (z up for
    the rings' elevation; the LiDAR's returns (N, 3) and centre (3,) in it).

    Each point is looked up in the LiDAR's range image (nearest return per ring and ``LIDAR_AZIMUTH_BIN_DEG``): it
    is free space if its ring's cells within ``LIDAR_PASS_WINDOW_BINS`` of its azimuth hold returns and all of
    them lie farther than the point by ``LIDAR_PASS_MARGIN_M`` + ``LIDAR_PASS_MARGIN_SHARE`` x its range (empty
    cells between them are beams that did not come back: dropouts). Points outside the rings' span, with no
    return in the window (sky, out of range, a black or glass surface the beams did not come back from) or a
    nearer one, are kept.
    """
    o = np.asarray(lidar_origin, np.float64)
    n_az = int(round(360.0 / LIDAR_AZIMUTH_BIN_DEG))

    def cells(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        d = np.asarray(p, np.float64) - o[None]
        r_xy = np.hypot(d[:, 0], d[:, 1])
        el = np.degrees(np.arctan2(d[:, 2], r_xy))
        ring = np.round((el - LIDAR_LOWEST_RING_DEG) / LIDAR_RING_DEG).astype(np.int64)
        az = np.floor(np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0 / LIDAR_AZIMUTH_BIN_DEG).astype(np.int64) % n_az
        near_ring = np.abs(el - (LIDAR_LOWEST_RING_DEG + ring * LIDAR_RING_DEG)) <= 0.5 * LIDAR_RING_DEG
        ok = (ring >= 0) & (ring < LIDAR_N_RINGS) & near_ring
        return np.linalg.norm(d, axis=1), ring, az, ok

    out = np.zeros(len(points), bool)
    behind = np.full(len(points), np.inf)
    if not len(points) or not len(lidar_points):
        return out, behind
    r_l, ring_l, az_l, ok_l = cells(lidar_points)
    nearest = np.full(LIDAR_N_RINGS * n_az, np.inf)
    np.minimum.at(nearest, (ring_l * n_az + az_l)[ok_l], r_l[ok_l])
    r_p, ring_p, az_p, ok_p = cells(points)
    idx = np.flatnonzero(ok_p)
    beyond = r_p[idx] * (1.0 + LIDAR_PASS_MARGIN_SHARE) + LIDAR_PASS_MARGIN_M
    first = np.full(len(idx), np.inf)
    free = np.ones(len(idx), bool)
    for da in range(-LIDAR_PASS_WINDOW_BINS, LIDAR_PASS_WINDOW_BINS + 1):
        r = nearest[ring_p[idx] * n_az + (az_p[idx] + da) % n_az]
        first = np.minimum(first, r)
        free &= r > beyond  # an empty cell (inf) does not object
    free &= np.isfinite(first)
    out[idx] = free
    behind[idx[free]] = first[free]
    return out, behind


def extend_facades(depth_m: np.ndarray, sky: np.ndarray, window_px: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) with each column's non-sky pixels above its highest known depth set to that depth (the
    farthest such depth within ``window_px`` columns, :func:`column_tops`), and the (W,) bool columns whose
    structure reaches the image's top edge (their true top is not seen).

    Vertical-facade prior: for a level camera, a vertical wall has the same camera-z all the way up.
    """
    H, W = depth_m.shape
    has, top, top_depth = column_tops(depth_m, window_px)
    rows = np.arange(H)[:, None]
    above = (rows < top[None, :]) & ~sky & has[None, :]
    # stop at the first sky pixel met going up from the top depth
    sky_above = np.where(sky & (rows < top[None, :]), rows, -1).max(axis=0)
    above &= rows > sky_above[None, :]
    out = depth_m.copy()
    out[above] = np.broadcast_to(top_depth[None, :], depth_m.shape)[above]
    capped = np.isfinite(out[0]) & ~sky[0]
    return out, capped


def column_tops(depth_m: np.ndarray, window_px: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of a depth (H, W): (W,) bool whether it has a finite depth, (W,) the row of its highest one
    (H where none) and (W,) the depth to continue upwards: the largest of the highest depths of the columns
    within ``window_px`` (centred; 1: the column's own).

    What rises above a near object's top (a car's roof, a post, a trunk: they end inside the LiDAR's view) is
    not that object but the facade or canopy behind it, which the neighbouring columns whose structure goes
    higher reach; the farthest top nearby stands for it (``MESH_TOP_WINDOW_DEG``).
    """
    finite = np.isfinite(depth_m)
    H, W = depth_m.shape
    has = finite.any(axis=0)
    top = np.where(has, finite.argmax(axis=0), H)
    top_depth = depth_m[np.minimum(top, H - 1), np.arange(W)]
    if window_px > 1 and has.any():
        # a column that is ground up to its top (the plane's depth grows without bound towards the horizon) is
        # no structure to continue in its neighbours
        candidate = has & (top_depth <= TOP_FARTHEST_MAX_M)
        farthest = ndimage.maximum_filter1d(np.where(candidate, top_depth, -np.inf), int(window_px), mode="nearest")
        top_depth = np.where(has, np.maximum(top_depth, farthest), top_depth)
    return has, top, top_depth


def fill_structure_columns(depth_m: np.ndarray, sky: np.ndarray, window_px: int = 1) -> np.ndarray:
    """Depth (H, W) with every non-sky pixel of unknown depth set to its column's depth to continue upwards
    (:func:`column_tops`).

    For the seen-surface mesh: what :func:`extend_facades` leaves unknown lies above a sky gap (tree crowns
    between patches of sky); at the depth of the structure below it the mesh reproduces it exactly from the
    camera's own centre and approximately from nearby points (the volume can only blur it).
    """
    has, _, top_depth = column_tops(depth_m, window_px)
    fill = ~np.isfinite(depth_m) & ~sky & has[None, :]
    return np.where(fill, np.broadcast_to(top_depth[None, :], depth_m.shape), depth_m)


def depth_uncertainty_map(measured_m: np.ndarray, returns_uv: np.ndarray | None,
                          at_return: float = DEPTH_AT_RETURN, spread_px: float = DEPTH_SPREAD_PX) -> np.ndarray:
    """(H, W) float32 relative depth uncertainty of a camera's mesh depth: ``at_return`` on the pixels of the
    LiDAR returns ``returns_uv`` (N, 2) (pixel coordinates, integer centres), rising linearly with the distance
    to the nearest one to ``DEPTH_UNCERTAINTY`` at ``spread_px``; ``DEPTH_UNCERTAINTY`` where ``measured_m``
    (H, W; the densified LiDAR and ground, inf elsewhere) has no depth (extrapolated) and without returns."""
    H, W = measured_m.shape
    out = np.full((H, W), DEPTH_UNCERTAINTY, np.float32)
    if returns_uv is None or not len(returns_uv):
        return out
    u = np.round(returns_uv[:, 0]).astype(np.int64)
    v = np.round(returns_uv[:, 1]).astype(np.int64)
    ok = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    if not ok.any():
        return out
    free = np.ones((H, W), np.uint8)
    free[v[ok], u[ok]] = 0
    dist = cv2.distanceTransform(free, cv2.DIST_L2, 3)
    grown = at_return + (DEPTH_UNCERTAINTY - at_return) * np.clip(dist / max(spread_px, 1e-6), 0.0, 1.0)
    measured = np.isfinite(measured_m)
    out[measured] = np.minimum(grown[measured], DEPTH_UNCERTAINTY)
    return out


def mesh_depth(depth_m: np.ndarray, sky: np.ndarray, window_px: int) -> np.ndarray:
    """The seen-surface mesh's depth (H, W) float32 from the known depth (LiDAR, ground; inf elsewhere): every
    non-sky pixel above a column's highest known depth at the farthest such depth within ``window_px`` columns
    (:func:`extend_facades` up to the first sky pixel, then :func:`fill_structure_columns` above sky gaps)."""
    extended, _ = extend_facades(depth_m, sky, window_px)
    return fill_structure_columns(extended, sky, window_px).astype(np.float32)


def mesh_backdrop(depth_m: np.ndarray, sky: np.ndarray, window_px: int, rows: int = BACKDROP_ROWS) -> np.ndarray:
    """(H, W) float32 the backdrop of :func:`mesh_depth`: in the columns whose structure continues upwards
    farther than their own highest known depth (by more than the mesh's depth-ratio test allows), that farther
    depth over ``rows`` rows either side of the highest known one (non-sky); inf elsewhere. The mesh breaks
    between the near top and the farther structure; behind the near top the backdrop closes the gap (from the
    camera's own centre it is hidden, from elsewhere the farther structure shows there)."""
    H, W = depth_m.shape
    has, top, own = column_tops(depth_m)
    _, _, farther = column_tops(depth_m, window_px)
    raised = has & (farther > own * MAX_DEPTH_RATIO)
    r = np.arange(H)[:, None]
    band = raised[None, :] & (np.abs(r - top[None, :]) <= rows) & ~sky
    return np.where(band, np.broadcast_to(farther[None, :], (H, W)), np.inf).astype(np.float32)


def top_window_px(K: np.ndarray, window_deg: float) -> int:
    """The column window (odd, >= 1 px) of ``window_deg`` degrees at the image centre of intrinsics K."""
    n = int(round(float(K[0][0]) * np.radians(window_deg)))
    return max(n | 1, 1)


def canyon_depth(K: np.ndarray, width: int, height: int, T_vol_from_cam: np.ndarray,
                 half_width_m: float = CANYON_HALF_WIDTH_M) -> np.ndarray:
    """Camera-z depth (H, W) float32 of a street canyon without LiDAR: the ground z = 0 and two vertical walls
    at y = +-``half_width_m`` (volume frame, parallel to its x axis), whichever a pixel's ray meets first."""
    rays = PinholeCamera(K, width, height).rays(unit=False)  # camera z = 1
    T = np.asarray(T_vol_from_cam)
    d = rays @ T[:3, :3].T
    o = T[:3, 3]
    t = np.full((height, width), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value in ((2, 0.0), (1, half_width_m), (1, -half_width_m)):
            ti = (value - o[axis]) / d[..., axis]
            t = np.where((ti > 0) & np.isfinite(ti), np.minimum(t, ti), t)
    return t.astype(np.float32)  # t along rays with camera z = 1 is the z-depth


def row_norms(v: np.ndarray) -> np.ndarray:
    """(N, 1) the lengths of vectors (N, 3): ``np.linalg.norm(v, axis=1, keepdims=True)``'s numbers (its sum of
    squares in the same order), without numpy's slow reduction over an axis of length 3."""
    sq = v * v
    return np.sqrt((sq[:, 0] + sq[:, 1]) + sq[:, 2])[:, None]


def first_level_at(ldr: float) -> int:
    """The first 8-bit level ``k`` with ``k / 255.0 >= ldr`` (256: none)."""
    ok = np.arange(256, dtype=np.float64) / 255.0 >= ldr
    return int(np.argmax(ok)) if ok.any() else 256


def clipped_radiance(small: np.ndarray, level_max: np.ndarray, exposure_ratio: float) -> np.ndarray:
    """(h, w, 3) float32 linear radiance of a uint8 image (h, w, 3) on the reference scale: clipped pixels
    (``level_max`` (h, w), the largest channel, at or above ``SATURATION_LDR``) at the radiance where the response
    saturates (a lower bound, :func:`.core.response.clipped_to_lower_bound`), divided by ``exposure_ratio``.

    The same numbers as ``(clipped_to_lower_bound(ldr_uint8_to_hdr(small), small / 255.0) / exposure_ratio)
    .astype(np.float32)``, from a table of the 2 x 3 x 256 values they can take."""
    hdr = ldr_uint8_to_hdr(np.arange(256, dtype=np.uint8)).astype(np.float64)
    table = (np.stack([np.broadcast_to(hdr, (3, 256)), np.minimum(hdr[None, :], SATURATION_RADIANCE[:, None])])
             / exposure_ratio).astype(np.float32)
    clipped = (level_max >= first_level_at(SATURATION_LDR)).astype(np.intp)
    return table.reshape(-1)[clipped[..., None] * 768 + np.arange(3) * 256 + small]


def observe_view(view: CameraView, T_vol_from_cam: np.ndarray, exposure_ratio: float, lidar_points_cam: np.ndarray | None,
                 ground_plane_cam: tuple[np.ndarray, float], work_width: int = WORK_WIDTH,
                 work: PreparedImage | None = None, lidar_origin_cam: np.ndarray | None = None) -> ViewObservation:
    """Unproject one camera's image (see module doc, step 1).

    Args:
        view: a ``CameraView`` (image, K, channel).
        T_vol_from_cam: (4, 4) camera -> volume frame.
        exposure_ratio: this image's scale / the reference scale (pixels are divided by it).
        lidar_points_cam: (N, 3) LiDAR points in this camera's frame, or None.
        ground_plane_cam: (normal (3,), offset d) of the ground ``n . p + d = 0`` in the camera frame.
        work: the L1 fit's prepared image of this view (reused for the sky mask), or None.
        lidar_origin_cam: (3,) the LiDAR's centre in this camera's frame, or None: the pixels whose point a LiDAR
            beam passed on its way to a farther return (:func:`lidar_passed_through`) show what it came back from:
            ``free_points`` has them there, along their rays; ``points`` and the seen-surface mesh keep them.
    """
    image = np.asarray(view.image)
    check_shape(image, ("H", "W", 3), "image")
    if work is not None and work.rgb_uint8 is not None and work_width == EVIDENCE_WORK_WIDTH:
        small, Ks = work.rgb_uint8, work.K  # the L1 fit's downscale of the same image at the same width
    else:
        small, Ks = downscale_image(image, view.K, work_width)
    h, w = small.shape[:2]
    normal, offset = ground_plane_cam
    up_cam = np.asarray(T_vol_from_cam)[2, :3]  # volume +z in the camera frame
    if work is None:
        work = prepare_image(image, view.K, up_cam / np.linalg.norm(up_cam), lidar_points_cam)
    sky = image_sky_mask(work)
    if sky.shape != (h, w):
        sky = cv2.resize(sky.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    returns_uv = None
    if lidar_points_cam is not None and len(lidar_points_cam):
        depth = densify_lidar_depth(lidar_points_cam, Ks, w, h, ground_fill=(normal, offset))
        front = np.asarray(lidar_points_cam, np.float64)
        front = front[front[:, 2] > 0.5]
        returns_uv = front[:, :2] / front[:, 2:3] @ np.asarray(Ks)[:2, :2].T + np.asarray(Ks)[:2, 2]
    else:
        depth = canyon_depth(Ks, w, h, T_vol_from_cam)
    depth = np.where(sky, np.inf, depth)
    measured = depth
    window = top_window_px(Ks, MESH_TOP_WINDOW_DEG)
    depth, capped_cols = extend_facades(measured, sky)
    # clipped pixels at the radiance where the response saturates (a lower bound), not its far tail
    level_max = np.maximum(np.maximum(small[..., 0], small[..., 1]), small[..., 2])  # (h, w) uint8
    hdr = clipped_radiance(small, level_max, exposure_ratio)
    rays = PinholeCamera(Ks, w, h).rays(unit=False)  # z = 1
    near = np.isfinite(depth)
    R = np.asarray(T_vol_from_cam)[:3, :3]
    centre = np.asarray(T_vol_from_cam)[:3, 3]
    p_vol = transform_points(T_vol_from_cam, rays[near] * depth[near][:, None])
    free_points = None
    if lidar_origin_cam is not None and lidar_points_cam is not None and LIDAR_FREE_SPACE:
        lidar_vol = transform_points(T_vol_from_cam, np.asarray(lidar_points_cam, np.float64))
        origin_vol = transform_points(T_vol_from_cam, np.asarray(lidar_origin_cam, np.float64)[None])[0]
        passed, behind_m = lidar_passed_through(p_vol, lidar_vol, origin_vol)
        passed &= p_vol[:, 2] > LIDAR_FREE_MIN_HEIGHT_M
        free_points = p_vol.copy()
        if passed.any():  # the pixel shows what the beam came back from: there along its ray
            r_p = np.linalg.norm(p_vol[passed] - origin_vol[None], axis=1)
            free_points[passed] = centre[None] + (p_vol[passed] - centre[None]) * (behind_m[passed] / r_p)[:, None]
    view_dirs = centre[None] - p_vol
    view_dirs /= np.maximum(row_norms(view_dirs), 1e-9)
    far = ~near
    d_far = rays[far] @ R.T
    d_far /= row_norms(d_far)
    capped = np.broadcast_to(capped_cols[None, :], (h, w))[near]
    return ViewObservation(
        channel=view.channel, points=p_vol, radiance=hdr[near], view_dirs=view_dirs, capped=capped,
        far_dirs=d_far, far_radiance=hdr[far], far_is_sky=sky[far], far_saturated=level_max[far] >= first_level_at(SATURATED_LDR),
        camera_centre=centre, ego_forward=ego_forward_vol(view, T_vol_from_cam), free_points=free_points,
        depth_view=DepthView(view.channel, mesh_depth(measured, sky, window), hdr, Ks,
                             np.asarray(T_vol_from_cam, np.float64),
                             mesh_backdrop(measured, sky, window),
                             depth_uncertainty=depth_uncertainty_map(measured, returns_uv),
                             sky=sky if SKY_MESH else None),
    )


def ego_forward_vol(view: CameraView, T_vol_from_cam: np.ndarray) -> np.ndarray:
    """The ego's forward axis (3,) in the volume frame (the street's direction)."""
    T_ge, T_gc = view.T_global_from_ego, view.T_global_from_cam
    R = np.asarray(T_vol_from_cam)[:3, :3] @ np.asarray(T_gc)[:3, :3].T @ np.asarray(T_ge)[:3, :3]
    return R[:, 0]



def restrict_to_grid(obs: ViewObservation, grid: LogGrid) -> ViewObservation:
    """Move the points outside the grid's box to the observation's pixels "at infinity" (distant scenery)."""
    lo, hi = grid.bounds()
    p = obs.points
    inside = ((p[:, 0] >= lo[0]) & (p[:, 0] <= hi[0]) & (p[:, 1] >= lo[1]) & (p[:, 1] <= hi[1])
              & (p[:, 2] >= lo[2]) & (p[:, 2] <= hi[2]))
    if inside.all():
        return obs
    d = obs.points[~inside] - obs.camera_centre
    d /= np.maximum(row_norms(d), 1e-9)
    n_out = int((~inside).sum())
    return replace(
        obs, points=obs.points[inside], radiance=obs.radiance[inside], view_dirs=obs.view_dirs[inside],
        capped=obs.capped[inside], far_dirs=np.concatenate([obs.far_dirs, d]),
        free_points=None if obs.free_points is None else obs.free_points[inside],
        far_radiance=np.concatenate([obs.far_radiance, obs.radiance[~inside]]),
        far_is_sky=np.concatenate([obs.far_is_sky, np.zeros(n_out, bool)]),
        far_saturated=np.concatenate([obs.far_saturated, np.zeros(n_out, bool)]),
    )
