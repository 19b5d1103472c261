"""Seen surfaces at image resolution: each input camera's dense depth as a textured triangle mesh.

The VSG volume holds one lobe colour per voxel (1-3 m at 20 m), far coarser than a pixel. This layer keeps
what the cameras saw at their own resolution: every camera's depth map (<= 480 px, :mod:`.observe`)
subsampled every ``GEOMETRY_STEP_PX`` pixels becomes a grid mesh in the volume frame (z up, metres), each
vertex carrying its pixel coordinate (u, v) in that camera's radiance image (linear, the reference
radiometric scale; pixel centres at integer coordinates). Neighbouring pixels are joined; triangles across
depth discontinuities (vertex depths more than ``MAX_DEPTH_RATIO`` apart; ``MAX_GROUND_DEPTH_RATIO`` for
ground triangles -- all three vertices below ``GROUND_HEIGHT_M``, normal within ``GROUND_MAX_TILT_DEG`` of
vertical -- since the ground is continuous but grazing far away) are dropped; pixels without depth are not in
the mesh. A camera's *sky* pixels (``DepthView.sky``) are a grid mesh of their own on a sphere of
``SKY_MESH_RANGE_M`` around its centre: from any point near the cameras, a ray that meets no nearer seen surface
and leaves along a direction a camera saw as sky takes that sky pixel, at the image's resolution and without
parallax (the sky is at infinity), rather than the volume's coarse voxels at a canopy's edge and the sky dome's
cells. (Scene-0916 stride-4 keyframes, six-view forward median PSNR 17.03 -> 17.43 dB.)

A ray query (:meth:`SeenSurfaces.trace`) finds the closest hit in each camera's mesh (Embree); among the
hits within ``SAME_SURFACE_FRACTION`` of the nearest (the same surface seen by several cameras) it takes the
camera that saw it along the direction nearest to the ray's (least parallax; from a camera's own centre its own
pixels), and returns that camera's radiance sampled bilinearly at the interpolated pixel coordinate, from a copy of the
texture blurred by the hit's *reprojection uncertainty*: seen from a point ``b`` metres from the camera that
took it (across the ray: moving along the ray causes no parallax), a surface at distance ``t`` whose depth is known to a fraction ``DEPTH_UNCERTAINTY`` moves by about
``f DEPTH_UNCERTAINTY b / t`` pixels in that camera's image, so that is the Gaussian sigma used (0 from the
camera's own centre: its image exactly; between the precomputed ``BLUR_LEVELS_PX``, linearly). The radiance is a
constant (not a function of the volume's parameters).

Cameras have a *rank*: 0 for the estimate's own cameras, 1 for an earlier keyframe's (:mod:`.multiview`). A ray
takes only hits of the lowest rank that it hits at all: an earlier camera's surfaces fill only what the
cameras of the instant left open (what is now behind or above them), they never cover what those saw; and
what an instant camera saw through (its sky, or farther surfaces) is carved out of them first (:func:`carved`).
An instant camera's sky mesh is a rank-0 hit like its other surfaces: where it saw sky, no earlier surface is taken.
"""

from __future__ import annotations

import functools
import io
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from ..core import InputError, check_shape, transform_points, unproject_depth, write_bytes_atomic
from ..core.raycast import RayScene

GEOMETRY_STEP_PX = 2  # 480 px radiance -> 240 px geometry
MAX_DEPTH_RATIO = 1.3
MAX_GROUND_DEPTH_RATIO = 2.5
GROUND_HEIGHT_M = 0.3  # vertices below this height (volume frame) may be on the ground
GROUND_MAX_TILT_DEG = 25.0
MAX_DEPTH_M = 300.0
T_MIN_M = 0.05  # hits nearer than this to the ray's origin are ignored (a point on the road)
SEEN_SCHEMA = "streetaug.seen_surfaces/1"
DEPTH_UNCERTAINTY = 0.1  # relative error of the densified depth (0.05 / 0.1 / 0.2 tried on scene-0916 keyframes 4, 12, 24)
SAME_SURFACE_FRACTION = 0.05  # hits this much farther than the nearest (+ 0.1 m) are the same surface
BLUR_LEVELS_PX = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0)  # Gaussian sigmas of the texture copies
SEEN_THROUGH_WINDOW_PX = 3  # seen_through: the depth a camera saw is the nearest within this window
# a camera's sky pixels (DepthView.sky) are meshed on a sphere of this radius around its centre: the sky seen at
# the image's resolution, at (practically) infinity -- from anywhere near the cameras a ray that misses every nearer
# seen surface and leaves along a direction a camera saw as sky shows that sky, sharp and without parallax, instead
# of the coarse volume's voxels and the dome's cells
SKY_MESH_RANGE_M = 1.0e4


@dataclass(frozen=True)
class DepthView:
    """One camera's depth and radiance images, what its mesh is built from.

    Attributes:
        channel: camera channel.
        depth_m: (h, w) float32 camera-z depth, inf where unknown (sky).
        radiance: (h, w, 3) float32 linear radiance, reference scale.
        K: (3, 3) intrinsics of these images.
        T_vol_from_cam: (4, 4) camera -> volume frame.
        backdrop_depth_m: (h, w) float32 a second surface behind the first (inf where none), or None: where a
            near object's top meets the farther structure that continues above it, that structure goes on a
            few rows down behind the object, so that no gap opens between the two (see :mod:`.observe`).
        rank: 0 for a camera of the estimate's instant, 1 for an earlier keyframe's (see module doc).
        depth_uncertainty: (h, w) float32 each pixel's relative depth error (of ``depth_m``; the backdrop's is
            ``DEPTH_UNCERTAINTY``), or None: ``DEPTH_UNCERTAINTY`` everywhere (see module doc).
        sky: (h, w) bool the camera's sky pixels (depth inf in ``depth_m``), meshed at ``SKY_MESH_RANGE_M`` from
            its centre, or None: no sky mesh.
    """

    channel: str
    depth_m: np.ndarray
    radiance: np.ndarray
    K: np.ndarray
    T_vol_from_cam: np.ndarray
    backdrop_depth_m: np.ndarray | None = None
    rank: int = 0
    depth_uncertainty: np.ndarray | None = None
    sky: np.ndarray | None = None


def seen_through(view: DepthView, by: list[DepthView], margin: float = MAX_DEPTH_RATIO,
                 window_px: int = SEEN_THROUGH_WINDOW_PX) -> np.ndarray:
    """(h, w) bool: the pixels of ``view`` whose surface point another camera of ``by`` saw through -- it lands
    inside that camera's image, in front of it, nearer by more than ``margin`` than every depth it saw within
    ``window_px`` (its sky, inf, is beyond every point; the window spares edges a pixel's misregistration
    would cut). An earlier keyframe's surface that the instant's cameras see through has moved or was never
    there (a sky pixel taken for structure)."""
    h, w = view.depth_m.shape
    finite = np.isfinite(view.depth_m)
    out = np.zeros((h, w), bool)
    if not finite.any():
        return out
    vv, uu = np.nonzero(finite)
    p_cam = unproject_depth(view.K, np.stack([uu, vv], axis=1).astype(np.float64), view.depth_m[finite])
    p_vol = transform_points(np.asarray(view.T_vol_from_cam, np.float64), p_cam)
    through = np.zeros(len(p_vol), bool)
    for other in by:
        q = transform_points(np.linalg.inv(np.asarray(other.T_vol_from_cam, np.float64)), p_vol)
        oh, ow = other.depth_m.shape
        nearest = cv2.erode(np.minimum(other.depth_m, 1e9).astype(np.float32), np.ones((window_px, window_px), np.uint8))
        z = q[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.round(other.K[0][0] * q[:, 0] / z + other.K[0][2])
            v = np.round(other.K[1][1] * q[:, 1] / z + other.K[1][2])
        inside = (z > 0.5) & (u >= 0) & (u <= ow - 1) & (v >= 0) & (v <= oh - 1)
        k = np.flatnonzero(inside)
        seen = nearest[v[k].astype(np.int64), u[k].astype(np.int64)]
        through[k] |= z[k] * margin < seen
    out[vv, uu] = through
    return out


def carved(view: DepthView, by: list[DepthView]) -> DepthView:
    """``view`` without the pixels the cameras ``by`` saw through (:func:`seen_through`): inf depth, in its
    backdrop too."""
    cut = seen_through(view, by)
    if not cut.any():
        return view
    back = view.backdrop_depth_m
    return replace(view, depth_m=np.where(cut, np.inf, view.depth_m).astype(np.float32),
                   backdrop_depth_m=None if back is None else np.where(cut, np.inf, back).astype(np.float32))


def depth_mesh(view: DepthView, step: int = GEOMETRY_STEP_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A view's depth as a grid mesh: (vertices (V, 3) volume frame, faces (F, 3) int64, pixel uv (V, 2)).

    Vertices sit at every ``step``-th pixel (rows and columns); a quad's two triangles are kept where all three
    vertices have a finite depth and pass the depth-ratio test (see module doc). The backdrop (if any) is a
    second grid mesh of the same pixels, appended.
    """
    v, f, uv, _ = depth_mesh_uncertain(view, step)
    return v, f, uv


def depth_mesh_uncertain(view: DepthView, step: int = GEOMETRY_STEP_PX) -> tuple[np.ndarray, ...]:
    """:func:`depth_mesh` and each vertex's relative depth uncertainty (V,) float32 (the view's
    ``depth_uncertainty`` at its pixel; ``DEPTH_UNCERTAINTY`` without one and on the backdrop)."""
    unc = view.depth_uncertainty
    if unc is not None:
        check_shape(np.asarray(unc), view.depth_m.shape, "depth_uncertainty")
    parts = [_grid_mesh(view, view.depth_m, step, unc)]
    if view.backdrop_depth_m is not None:
        parts.append(_grid_mesh(view, view.backdrop_depth_m, step, None))
    if view.sky is not None:
        parts.append(_sky_mesh(view, step))
    if len(parts) == 1:
        return parts[0]
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] + o for p, o in zip(parts, offsets)]),
            np.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts]))


def _sky_mesh(view: DepthView, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The grid mesh of the view's sky pixels at ``SKY_MESH_RANGE_M`` (:func:`sky_depth`), built over the rows
    that hold sky only (from a multiple of ``step``: the same vertices as a mesh of the whole image)."""
    depth = sky_depth(view)
    rows = np.flatnonzero(np.isfinite(depth).any(axis=1))
    if not len(rows):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 2)), np.zeros(0, np.float32)
    r0, r1 = rows[0] // step * step, rows[-1] + 1
    K = np.array(view.K, np.float64)
    K[1, 2] -= r0
    v, f, uv, u = _grid_mesh(replace(view, K=K), depth[r0:r1], step, None, max_depth_m=np.inf)
    return v, f, uv + np.array([0.0, r0]), u


def sky_depth(view: DepthView, range_m: float = SKY_MESH_RANGE_M) -> np.ndarray:
    """(h, w) float64 camera-z depth of the view's sky pixels (``view.sky``) on the sphere of ``range_m`` around
    its centre (inf elsewhere and where ``depth_m`` is finite: a seen surface is never sky)."""
    sky = np.asarray(view.sky, bool)
    check_shape(sky, view.depth_m.shape, "sky")
    h, w = sky.shape
    K = np.asarray(view.K, np.float64)
    x = (np.arange(w) - K[0, 2]) / K[0, 0]
    y = (np.arange(h) - K[1, 2]) / K[1, 1]
    z_per_range = 1.0 / np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)  # camera z of a unit-length ray
    return np.where(sky & ~np.isfinite(view.depth_m), range_m * z_per_range, np.inf)


def _grid_mesh(view: DepthView, depth_m: np.ndarray, step: int, uncertainty: np.ndarray | None,
               max_depth_m: float = MAX_DEPTH_M) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`depth_mesh_uncertain` of one depth image (h, w) of ``view`` with its relative uncertainty (h, w)
    (None: ``DEPTH_UNCERTAINTY``); depths beyond ``max_depth_m`` are left out."""
    depth = np.asarray(depth_m, dtype=np.float64)
    check_shape(depth, ("H", "W"), "depth_m")
    rows = np.arange(0, depth.shape[0], step)
    cols = np.arange(0, depth.shape[1], step)
    u, v = np.meshgrid(cols.astype(np.float64), rows.astype(np.float64))
    d = depth[np.ix_(rows, cols)]
    unc = (np.full(d.size, DEPTH_UNCERTAINTY, np.float32) if uncertainty is None
           else np.asarray(uncertainty, np.float32)[np.ix_(rows, cols)].reshape(-1))
    d = np.where(d <= max_depth_m, d, np.inf)
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    finite = np.isfinite(d).reshape(-1)
    p_cam = unproject_depth(view.K, uv, np.where(finite, d.reshape(-1), 0.0))
    vertices = transform_points(np.asarray(view.T_vol_from_cam, np.float64), p_cam)
    h, w = d.shape
    idx = np.arange(h * w).reshape(h, w)
    a, b, c, e = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, e], 1)])
    # only the faces whose three vertices have a depth are tested further (the others are never kept)
    # (the reductions over a face's three vertices are written out: the same numbers, without numpy's slow
    # reductions over an axis of length 3)
    faces = faces[finite[faces[:, 0]] & finite[faces[:, 1]] & finite[faces[:, 2]]]
    fd = d.reshape(-1)[faces]
    f0, f1, f2 = fd[:, 0], fd[:, 1], fd[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.maximum(np.maximum(f0, f1), f2) / np.minimum(np.minimum(f0, f1), f2)
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    sq = normal * normal
    length = np.sqrt((sq[:, 0] + sq[:, 1]) + sq[:, 2])  # = np.linalg.norm(normal, axis=1)
    flat = np.abs(normal[:, 2]) >= np.cos(np.radians(GROUND_MAX_TILT_DEG)) * length
    low = tri[..., 2] < GROUND_HEIGHT_M
    ground = low[:, 0] & low[:, 1] & low[:, 2] & flat
    ok = ratio <= np.where(ground, MAX_GROUND_DEPTH_RATIO, MAX_DEPTH_RATIO)
    faces = faces[ok]
    is_used = np.zeros(len(vertices), bool)
    is_used[faces] = True
    used = np.flatnonzero(is_used)  # = np.unique(faces), without the sort
    remap = np.full(len(vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces], uv[used], unc[used]


@dataclass(frozen=True)
class SeenSurfaces:
    """All input cameras' depth meshes, textured by their radiance images (see module doc).

    Attributes:
        vertices: (V, 3) float32 volume-frame positions, metres.
        faces: (F, 3) int32 vertex indices.
        pixel_uv: (V, 2) float32 each vertex's pixel coordinate in its camera's texture.
        face_camera: (F,) int16 index of the camera that owns each face.
        textures: (C, h, w, 3) float32 linear radiance per camera (reference scale; zero-padded to one size).
        channels: (C,) camera channels.
        camera_centres: (C, 3) float64 each camera's centre, volume frame.
        focal_px: (C,) float64 each texture's focal length, pixels.
        rank: (C,) int8 each camera's rank (see module doc), or None: all 0.
        vertex_uncertainty: (V,) float32 each vertex's relative depth uncertainty (the blur's, see module doc),
            or None: ``DEPTH_UNCERTAINTY`` everywhere.
    """

    vertices: np.ndarray
    faces: np.ndarray
    pixel_uv: np.ndarray
    face_camera: np.ndarray
    textures: np.ndarray
    channels: tuple[str, ...]
    camera_centres: np.ndarray
    focal_px: np.ndarray
    rank: np.ndarray | None = None
    vertex_uncertainty: np.ndarray | None = None

    def __post_init__(self) -> None:
        check_shape(self.vertices, ("V", 3), "vertices")
        check_shape(self.faces, ("F", 3), "faces")
        check_shape(self.pixel_uv, (len(self.vertices), 2), "pixel_uv")
        check_shape(self.face_camera, (len(self.faces),), "face_camera")
        check_shape(self.textures, (len(self.channels), "h", "w", 3), "textures")
        check_shape(self.camera_centres, (len(self.channels), 3), "camera_centres")
        check_shape(self.focal_px, (len(self.channels),), "focal_px")
        if self.rank is not None:
            check_shape(self.rank, (len(self.channels),), "rank")
        if self.vertex_uncertainty is not None:
            check_shape(self.vertex_uncertainty, (len(self.vertices),), "vertex_uncertainty")
        if len(self.faces) == 0:
            raise ValueError("SeenSurfaces: no faces (use None for no seen surfaces)")

    @staticmethod
    def from_views(views: list[DepthView], step: int = GEOMETRY_STEP_PX) -> "SeenSurfaces | None":
        """The meshes of ``views`` in one layer, or None when no view has a face."""
        verts, faces, uvs, owner, kept, uncs = [], [], [], [], [], []
        offset = 0
        for view in views:
            v, f, uv, unc = depth_mesh_uncertain(view, step)
            if not len(f):
                continue
            verts.append(v)
            uncs.append(unc)
            faces.append(f + offset)
            uvs.append(uv)
            owner.append(np.full(len(f), len(kept), np.int16))
            kept.append(view)
            offset += len(v)
        if not kept:
            return None
        h = max(v.radiance.shape[0] for v in kept)
        w = max(v.radiance.shape[1] for v in kept)
        tex = np.zeros((len(kept), h, w, 3), np.float32)
        for i, view in enumerate(kept):
            r = np.asarray(view.radiance, np.float32)
            tex[i, : r.shape[0], : r.shape[1]] = r
        return SeenSurfaces(np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32),
                            np.concatenate(uvs).astype(np.float32), np.concatenate(owner), tex,
                            tuple(v.channel for v in kept),
                            np.array([np.asarray(v.T_vol_from_cam, np.float64)[:3, 3] for v in kept]),
                            np.array([0.5 * (v.K[0][0] + v.K[1][1]) for v in kept], np.float64),
                            np.array([v.rank for v in kept], np.int8),
                            np.concatenate(uncs).astype(np.float32)
                            if any(v.depth_uncertainty is not None for v in kept) else None)

    @functools.cached_property
    def scenes(self) -> list[tuple[RayScene, np.ndarray]]:
        """Per camera: its mesh as a ray scene and the scene's face indices into :attr:`faces`."""
        out = []
        for c in range(len(self.channels)):
            idx = np.flatnonzero(self.face_camera == c)
            f = self.faces[idx]
            lo, hi = int(f.min()), int(f.max()) + 1  # a camera's vertices are contiguous (see from_views)
            out.append((RayScene(self.vertices[lo:hi], f - lo), idx))
        return out

    @functools.cached_property
    def blurred(self) -> np.ndarray:
        """(L, C, h, w, 3) float32 the textures blurred by each of ``BLUR_LEVELS_PX``."""
        out = np.empty((len(BLUR_LEVELS_PX), *self.textures.shape), np.float32)
        for i, sigma in enumerate(BLUR_LEVELS_PX):
            for c, tex in enumerate(self.textures):
                out[i, c] = tex if sigma == 0 else _gaussian(tex, sigma)
        return out

    def trace(self, origins: np.ndarray, dirs: np.ndarray, t_min: float = T_MIN_M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest seen surface along rays from origins (N, 3) along unit dirs (N, 3), volume frame.

        Returns (hit (N,) bool, t (N,) metres (inf on a miss), radiance (N, 3) float32 (0 on a miss)).
        """
        hit, t, rgb, _ = self.trace_spread(origins, dirs, t_min)
        return hit, t, rgb

    def trace_spread(self, origins: np.ndarray, dirs: np.ndarray,
                     t_min: float = T_MIN_M) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`trace` and each hit's reprojection uncertainty as an angle (N,) float64 radians (0 on a miss):
        how far the hit surface may lie from where the ray meets it, seen from the ray's origin, ``relative depth
        uncertainty x baseline across the ray / t`` (the texture blur's sigma is this times the source camera's
        focal length; a view rendered from the origin is uncertain by this times its own)."""
        origins = np.asarray(origins, np.float64)
        dirs = np.asarray(dirs, np.float64)
        n = len(origins)
        t_all = np.full((len(self.scenes), n), np.inf)
        face_all = np.full((len(self.scenes), n), -1, np.int64)
        bary_all = np.zeros((len(self.scenes), n, 2))
        for c, (scene, idx) in enumerate(self.scenes):
            h = scene.intersect(origins, dirs, t_min)
            t_all[c], bary_all[c] = h.t, h.bary
            face_all[c, h.hit] = idx[h.face[h.hit]]
        if self.rank is not None and np.ptp(self.rank) > 0:  # only the lowest rank a ray hits
            ranks = np.asarray(self.rank, np.int64)[:, None]
            lowest = np.where(np.isfinite(t_all), ranks, np.iinfo(np.int64).max).min(axis=0)
            t_all = np.where(ranks > lowest[None, :], np.inf, t_all)
        t_near = t_all.min(axis=0)
        best = np.argmin(t_all, axis=0)
        if len(self.scenes) > 1:
            same = t_all <= t_near * (1.0 + SAME_SURFACE_FRACTION) + 0.1
            # a ray with one camera's surface at the nearest distance keeps it (argmin); of several, the camera
            # that sees it most head-on
            m = np.flatnonzero(np.isfinite(t_near) & (same.sum(axis=0) > 1))
            if len(m):
                sm, o, dm = same[:, m], origins[m], dirs[m]
                with np.errstate(invalid="ignore", divide="ignore"):
                    to_hit = o[None] + np.where(sm, t_all[:, m], 0.0)[..., None] * dm[None] - self.camera_centres[:, None]
                    cos = (to_hit * dm[None]).sum(-1) / np.maximum(np.linalg.norm(to_hit, axis=-1), 1e-9)
                best[m] = np.argmax(np.where(sm, cos, -np.inf), axis=0)
        rows = np.arange(n)
        hit = np.isfinite(t_near)
        t_best, face_best, bary_best = t_all[best, rows], face_all[best, rows], bary_all[best, rows]
        rgb = np.zeros((n, 3), np.float32)
        spread = np.zeros(n)
        k = np.flatnonzero(hit)
        if len(k):
            face = face_best[k]
            tri = self.faces[face]
            bu, bv = bary_best[k, :1], bary_best[k, 1:]
            uv = (1 - bu - bv) * self.pixel_uv[tri[:, 0]] + bu * self.pixel_uv[tri[:, 1]] + bv * self.pixel_uv[tri[:, 2]]
            if self.vertex_uncertainty is None:
                rel = DEPTH_UNCERTAINTY
            else:
                vu = self.vertex_uncertainty
                rel = ((1 - bu - bv) * vu[tri[:, 0], None] + bu * vu[tri[:, 1], None] + bv * vu[tri[:, 2], None])[:, 0]
            cam = self.face_camera[face].astype(np.int64)
            b = origins[k] - self.camera_centres[cam]
            baseline = np.linalg.norm(b - (b * dirs[k]).sum(axis=1, keepdims=True) * dirs[k], axis=1)  # across the ray
            spread[k] = rel * baseline / np.maximum(t_best[k], 1.0)
            sigma = self.focal_px[cam] * spread[k]
            levels = np.asarray(BLUR_LEVELS_PX)
            hi = np.clip(np.searchsorted(levels, sigma), 1, len(levels) - 1)
            w_hi = np.clip((sigma - levels[hi - 1]) / (levels[hi] - levels[hi - 1]), 0.0, 1.0)[:, None]
            rgb[k] = ((1 - w_hi) * bilinear(self.blurred, (hi - 1) * len(self.channels) + cam, uv)
                      + w_hi * bilinear(self.blurred, hi * len(self.channels) + cam, uv))
        return hit, t_best, rgb, spread

    @property
    def n_faces(self) -> int:
        return int(len(self.faces))

    # ------------------------------------------------------------------ files

    def save(self, path: str | Path) -> None:
        """Write the layer as one npz (float16 textures; loads with ``allow_pickle=False``)."""
        buf = io.BytesIO()
        np.savez_compressed(buf, schema=np.array(SEEN_SCHEMA), vertices=self.vertices, faces=self.faces,
                            pixel_uv=self.pixel_uv, face_camera=self.face_camera,
                            textures=np.clip(self.textures, 0.0, 65504.0).astype(np.float16),
                            channels=np.array(self.channels, dtype=str), camera_centres=self.camera_centres,
                            focal_px=self.focal_px,
                            rank=np.zeros(len(self.channels), np.int8) if self.rank is None else self.rank,
                            **({} if self.vertex_uncertainty is None
                               else {"vertex_uncertainty": self.vertex_uncertainty.astype(np.float16)}))
        write_bytes_atomic(path, buf.getvalue())

    @staticmethod
    def load(path: str | Path) -> "SeenSurfaces":
        """Read what :meth:`save` wrote (``InputError`` naming the file on bad input)."""
        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["schema"]) != SEEN_SCHEMA:
                    raise InputError(f"{path}: schema {str(z['schema'])!r}, expected {SEEN_SCHEMA!r}")
                return SeenSurfaces(z["vertices"].astype(np.float32), z["faces"].astype(np.int32),
                                    z["pixel_uv"].astype(np.float32), z["face_camera"].astype(np.int16),
                                    z["textures"].astype(np.float32), tuple(str(c) for c in z["channels"]),
                                    z["camera_centres"].astype(np.float64), z["focal_px"].astype(np.float64),
                                    z["rank"].astype(np.int8) if "rank" in z.files else None,
                                    z["vertex_uncertainty"].astype(np.float32) if "vertex_uncertainty" in z.files
                                    else None)
        except (OSError, KeyError, ValueError) as e:
            raise InputError(f"{path}: cannot read the seen surfaces ({e}); expected arrays schema, vertices, "
                             "faces, pixel_uv, face_camera, textures, channels, camera_centres, focal_px") from None


def _gaussian(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur (h, w, 3) float32; wide kernels (sigma >= 4 px) on a copy shrunk 2x / 4x (same result
    to within the shrinking's own blur, a few times cheaper)."""
    h, w = image.shape[:2]
    f = 1 if sigma_px < 4 else (2 if sigma_px < 8 else 4)
    if f == 1 or min(h, w) < 8 * f:
        return cv2.GaussianBlur(image, (0, 0), sigma_px, borderType=cv2.BORDER_REPLICATE)
    small = cv2.resize(image, (max(w // f, 1), max(h // f, 1)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), sigma_px / f, borderType=cv2.BORDER_REPLICATE)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def bilinear(textures: np.ndarray, camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup (N, 3) in textures (..., h, w, 3) (leading axes flattened) of image index camera (N,)
    at pixel coordinates uv (N, 2) (pixel centres at integers; clamped to the image)."""
    h, w = textures.shape[-3:-1]
    textures = textures.reshape(-1, h, w, 3)
    x = np.clip(uv[:, 0], 0.0, w - 1.0)
    y = np.clip(uv[:, 1], 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2 if w > 1 else 0)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2 if h > 1 else 0)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    texels = textures.reshape(-1, 3)  # one flat index per corner: the same texels as t[camera, y, x]
    base = np.asarray(camera, np.int64) * (h * w)
    r0, r1 = base + y0 * w, base + y1 * w

    def at(flat: np.ndarray) -> np.ndarray:
        return texels.take(flat, axis=0)

    top = at(r0 + x0) * (1 - fx) + at(r0 + x1) * fx
    bottom = at(r1 + x0) * (1 - fx) + at(r1 + x1) * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)
