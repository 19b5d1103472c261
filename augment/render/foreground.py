"""Foreground rendering: camera rays through the object's pixels, G-buffer, Monte Carlo shading, denoising.

Pipeline (all vectorised, rays in big Embree batches)::

    object pixel box -> n x n jittered camera samples (+ k x k more in silhouette pixels -- mixed
      coverage, or crossed by a projected triangle edge: thin parts -- and 2 x 2 at material
      boundaries and shading discontinuities the first pass does not resolve: a step, not a gradient,
      :func:`unresolved_shading`; of each pixel's k x k extra samples only k carry the Monte Carlo
      residual, :func:`residual_strata`: a sub-pixel sample needs a share of the pixel's light samples)
      -> ray-mesh hits (object frame) -> surface at the hits (:mod:`.surface`)
      -> shading (:mod:`.shade`): sun + environment, self-occlusion, one bounce, the ground's shadow
      -> glass: reflection on the glass + the continued ray (dark interior or what lies behind)
      -> per-pixel premultiplied radiance, coverage alpha, camera-z depth
      -> G-buffer-guided cross-bilateral denoising of the Monte Carlo residual only.

Camera rays are intersected and looked up :data:`TRACE_CHUNK_RAYS` at a time and summed per pixel as they go
(:class:`PixelSums`); their hits are shaded in the batches one :func:`.shade.shade` call would make
(:class:`_ShadeQueue`), so the render is the unchunked one and its memory does not grow with the pixel box.

With :data:`INNER_RESIDUAL` False the 2 x 2 extra samples of inner edges (material boundaries, shading
discontinuities) shade only the sharp noise-free part (sun, control variates, mirror reflection) and their
pixels take the Monte Carlo residual from the first pass: foreground CPU -22 % on scene-0916 inserts, but
-1.9 dB on the Mitsuba reference's forest car (region 36.7 -> 36.0 dB), so it is off by default.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..core import PinholeCamera, invert_transform, luminance
from .brdf import BRDFParams, mirror_albedo, mirror_fresnel, reflect, row_norm
from .footprint import PixelBox, edge_pixels
from . import shade as shade_module
from .shade import RAY_EPS_M, ShadingContext, shade
from .surface import SurfaceHits, surface_at_hits

EDGE_LIGHT_SAMPLES = {"sun_samples": 1, "env_samples": 0, "brdf_samples": 1}  # per extra edge sample
INNER_RESIDUAL = True  # False: inner edge samples sharpen the smooth part only (residual from the first pass; see below)
SHADING_EDGE_REL = 0.15  # relative jump of the noise-free radiance that marks a pixel for more samples
DENOISE_RADIUS_PX = 6
DENOISE_SIGMA_PX = 3.5
DENOISE_DEPTH_SCALE_PER_M = 0.15  # guide units per metre of depth (0.5 m ~ one normal sigma)


@dataclass(frozen=True)
class Foreground:
    """The rendered object over its pixel box.

    Attributes:
        box: the object's pixel box in the image (every array below is ``(box.height, box.width, ...)``).
        radiance_premult: (h, w, 3) float32 linear radiance x coverage (premultiplied).
        alpha: (h, w) float32 coverage in [0, 1] (glass that shows the scene behind lowers it).
        depth_m: (h, w) float32 camera-frame z of the nearest hit, inf where the object is absent.
        stats: rays cast per stage and sample counts.
        solid: (h, w) float32 the share of the pixel's camera samples that hit the object (glass counts: the
            object's extent in the image for labels and for occluding other objects), or None (= ``alpha``).
    """

    box: PixelBox
    radiance_premult: np.ndarray
    alpha: np.ndarray
    depth_m: np.ndarray
    stats: dict = field(default_factory=dict)
    solid: np.ndarray | None = None


def render_foreground(camera: PinholeCamera, box: PixelBox | None, ctx: ShadingContext,
                      T_cam_from_object: np.ndarray) -> Foreground | None:
    """Render the object over its pixel ``box`` (see module docstring); None if it is off-screen.

    Args:
        camera: the camera of the image.
        box: the object's :func:`~streetaug.augment.render.footprint.object_pixel_box`, or None.
        ctx: the shading context (light, prepared asset, bounce, ground shadow, settings, random generator).
        T_cam_from_object: (4, 4) pose.
    """
    if box is None:
        return None
    settings = ctx.settings
    w, h = box.width, box.height
    ys, xs = np.divmod(np.arange(w * h), w)
    n = settings.aa_grid
    sums = PixelSums.empty(w * h, T_cam_from_object[2, :3])
    _cast(ctx, camera, T_cam_from_object, *_jittered_samples(xs + box.x0, ys + box.y0, n, ctx.rng), sums)
    counts = np.full(w * h, n * n, dtype=np.float64)
    silhouette, inner = _refine_masks(sums, w, h, n, _crossed_pixels(camera, box, ctx, T_cam_from_object))
    n_edge = 0
    # The extra samples are there for coverage and sharp shading edges; each pixel averages k x k of
    # them, so each needs fewer light samples (EDGE_LIGHT_SAMPLES instead of the preset's).
    ctx.settings = dataclasses.replace(settings, **{k: min(getattr(settings, k), v) for k, v in EDGE_LIGHT_SAMPLES.items()})
    for edge, k, residual in ((silhouette, settings.edge_grid, True), (inner, min(settings.edge_grid, 2), INNER_RESIDUAL)):
        edge_ids = np.flatnonzero(edge.ravel())
        if len(edge_ids) == 0 or k <= 1:
            continue
        uv2, pix2 = _jittered_samples(xs[edge_ids] + box.x0, ys[edge_ids] + box.y0, k, ctx.rng)
        # A sample covering 1 / k^2 of the pixel needs 1 / k^2 of its light samples: the Monte Carlo residual
        # comes from k of the k^2 (one per row and column of the strata), the others shade the sharp part.
        carries = np.tile(residual_strata(k), len(edge_ids)) if residual else np.zeros(len(uv2), bool)
        for part, res in ((carries, True), (~carries, False)):
            if part.any():
                ctx.residual = res
                _cast(ctx, camera, T_cam_from_object, uv2[part], edge_ids[pix2[part]], sums)
        counts[edge_ids] += k * k
        n_edge += len(uv2)
    ctx.settings, ctx.residual = settings, True
    return _resolve_pixels(sums, counts, box, T_cam_from_object[:3, :3], settings.denoise, ctx, n_edge)


def residual_strata(k: int) -> np.ndarray:
    """(k^2,) bool over the k x k strata of :func:`_jittered_samples` (row-major): the k that carry the Monte Carlo
    residual, one in each row and column (a rook pattern, stratified over the pixel)."""
    gy, gx = np.divmod(np.arange(k * k), k)
    return gx == (gy * (k - 1)) % k


def _cast(ctx: ShadingContext, camera: PinholeCamera, T_cam_from_object: np.ndarray, uv: np.ndarray,
          pixel: np.ndarray, sums: "PixelSums") -> None:
    """Trace camera rays through pixel positions uv (N, 2) (their box pixels ``pixel`` (N,)) into ``sums``."""
    R = T_cam_from_object[:3, :3]
    eye_obj = invert_transform(T_cam_from_object)[:3, 3]
    _trace(ctx, lambda sl: (eye_obj, camera.rays(uv[sl]) @ R), len(uv), pixel, sums)  # camera -> object frame


def _crossed_pixels(camera: PinholeCamera, box: PixelBox, ctx: ShadingContext, T_cam_from_object: np.ndarray) -> np.ndarray | None:
    """(h, w) bool: pixels of ``box`` the object's projected triangle edges cross (:func:`.footprint.edge_pixels`),
    or None when the object reaches behind the camera (no projection)."""
    R, t = T_cam_from_object[:3, :3], T_cam_from_object[:3, 3]
    v_cam = ctx.prep.asset.vertices @ R.T + t
    if np.any(v_cam[:, 2] <= 1e-3):
        return None
    uv, _ = camera.project(v_cam)
    return edge_pixels(uv[ctx.prep.faces], box)


def _refine_masks(first: "PixelSums", w: int, h: int, n: int,
                  crossed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(silhouette, inner), each (h, w) bool: pixels that get more camera samples after the first pass.

    Silhouette pixels (mixed coverage or next to one, or crossed by a projected triangle edge
    ``crossed`` (h, w) where not every neighbour is fully covered: geometry thinner than the first
    pass's sample spacing, spokes and wires, is found there even where every first sample missed it);
    inside the object, material boundaries (window frames, tyres, lights) and shading discontinuities
    (creases between flat faces, self-shadow edges: the noise-free part of the first pass jumps by
    more than SHADING_EDGE_REL between neighbours).
    """
    nhit = first.solid.reshape(h, w)
    any_hit = (nhit > 0).astype(np.uint8)
    all_hit = (nhit == n * n).astype(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    reach = cv2.dilate(any_hit, kernel) > 0
    if crossed is not None:
        reach |= crossed
    silhouette = reach & ~(cv2.erode(all_hit, kernel, borderType=cv2.BORDER_REPLICATE) > 0)
    mat = first.material.astype(np.float32).reshape(h, w)
    inner = (cv2.dilate(mat, kernel) != cv2.erode(mat, kernel, borderType=cv2.BORDER_REPLICATE)) & ~silhouette
    smooth_lum = np.log(np.maximum(luminance(first.smooth).reshape(h, w) / (n * n), 1e-4)).astype(np.float32)
    inner |= (unresolved_shading(smooth_lum) > np.log1p(SHADING_EDGE_REL)) & (mat >= 0) & ~silhouette
    return silhouette, inner


def unresolved_shading(log_lum: np.ndarray) -> np.ndarray:
    """(h, w) largest second difference ``|L(x - e) + L(x + e) - 2 L(x)|`` of ``log_lum`` (h, w) over the four
    pixel axes (horizontal, vertical, diagonals): what more samples inside the pixel would change.

    A step between two pixels gives the step at both (as the 3 x 3 range did), a gradient the pixels resolve
    gives 0 (more samples of a linear ramp average to its centre value): reflections of the environment and
    highlights sweeping smoothly over a near car's panels no longer ask for supersampling, edges still do.
    """
    L = np.pad(log_lum, 1, mode="reflect", reflect_type="odd")  # linear extrapolation: a ramp stays a ramp
    c = L[1:-1, 1:-1]
    out = np.zeros_like(c)
    for (ay, ax), (by, bx) in (((1, 0), (1, 2)), ((0, 1), (2, 1)), ((0, 0), (2, 2)), ((0, 2), (2, 0))):
        a = L[ay:ay + c.shape[0], ax:ax + c.shape[1]]
        b = L[by:by + c.shape[0], bx:bx + c.shape[1]]
        np.maximum(out, np.abs(a + b - 2.0 * c), out=out)
    return out


def _resolve_pixels(sums: "PixelSums", counts: np.ndarray, box: PixelBox, R: np.ndarray, denoise: bool,
                    ctx: ShadingContext, n_edge: int) -> Foreground:
    """Average the samples per pixel (radiance, alpha), nearest depth, G-buffer; denoise the residual."""
    w, h = box.width, box.height
    P = w * h
    # The residual: mean over the samples that carry one (inner edge samples only sharpen the smooth part).
    rad_px = np.concatenate([sums.smooth / counts[:, None],
                             sums.noisy / np.maximum(sums.carried, 1e-12)[:, None]], axis=1)
    alpha_px = sums.alpha / counts
    solid_px = sums.solid / counts
    depth_px = sums.depth_m
    # G-buffer per pixel (mean first-hit normal, a first-hit material) for the denoiser.
    n_px = sums.normal / np.maximum(row_norm(sums.normal)[:, None], 1e-9)
    m_px = sums.material
    smooth_px, noisy_px = rad_px[:, :3], rad_px[:, 3:]
    if denoise:
        # Only the Monte Carlo residual is filtered (widely); the control variates' expectations and
        # the sun keep their full sharpness.  Guide: camera-frame normal, material, depth.
        n_cam = n_px @ R.T
        noisy_px = denoise_radiance(noisy_px.reshape(h, w, 3), alpha_px.reshape(h, w), n_cam.reshape(h, w, 3),
                                    m_px.reshape(h, w), depth_m=depth_px.reshape(h, w),
                                    radius=DENOISE_RADIUS_PX, sigma_px=DENOISE_SIGMA_PX).reshape(P, 3)
    rad_px = smooth_px + noisy_px
    stats = {"rays": dict(ctx.rays), "raycast_s": ctx.raycast_s, "pixels": int(P), "camera_samples": int(sums.samples),
             "edge_samples": int(n_edge), "box": box.as_list()}
    return Foreground(
        box=box,
        radiance_premult=rad_px.reshape(h, w, 3).astype(np.float32),
        alpha=np.clip(alpha_px, 0.0, 1.0).reshape(h, w).astype(np.float32),
        depth_m=depth_px.reshape(h, w).astype(np.float32),
        stats=stats,
        solid=np.clip(solid_px, 0.0, 1.0).reshape(h, w).astype(np.float32),
    )


def _trace(ctx: ShadingContext, rays_obj, N: int, pixel: np.ndarray, sums: "PixelSums") -> None:
    """Follow N camera rays (object frame) through glass and add them to ``sums`` (pixels ``pixel`` (N,)).

    ``rays_obj(sl)`` gives the (origin (3,), unit directions (n, 3)) of the rays ``sl`` (a slice). Rays are
    intersected and their surfaces looked up :data:`TRACE_CHUNK_RAYS` at a time, and shaded through a
    :class:`_ShadeQueue` in the batches an unchunked :func:`.shade.shade` call makes (same random numbers,
    same image): memory is bounded by the chunk, not by the object's pixel box.
    """
    radiance = np.zeros((N, 6))
    escaped = np.zeros(N)
    hit_first = np.zeros(N, bool)
    n_rays = N  # rays at this glass depth: all at depth 0, then those that went on through glass
    for depth in range(ctx.settings.max_glass_depth):
        queue = _ShadeQueue(ctx, radiance)
        going = []
        for a in range(0, n_rays, TRACE_CHUNK_RAYS):
            sl = slice(a, a + TRACE_CHUNK_RAYS)
            if depth == 0:
                eye, d = rays_obj(sl)
                o, idx, tp = np.broadcast_to(eye, d.shape), np.arange(a, a + len(d)), None
            else:
                o, d, idx, tp = o_next[sl], d_next[sl], active[sl], tp_next[sl]
            going.append(_trace_chunk(ctx, o, d, idx, tp, depth, pixel, sums, hit_first, escaped, queue))
        queue.flush()
        going = [g for g in going if len(g[0])]
        if not going:
            break
        active, o_next, d_next, tp_next = (np.concatenate(x) for x in zip(*going))
        n_rays = len(active)
    # Whatever still travels after the last surface is absorbed by the (dark) interior.
    alpha = np.where(hit_first, 1.0 - escaped, 0.0)
    sums.add_shading(pixel, radiance, alpha, ctx.residual)


TRACE_CHUNK_RAYS = 32_768  # camera rays per intersection / surface batch (bounds the foreground's memory)
_NONE_GOING = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))


def _trace_chunk(ctx: ShadingContext, o: np.ndarray, d: np.ndarray, idx: np.ndarray, tp_in: np.ndarray | None,
                 depth: int, pixel: np.ndarray, sums: "PixelSums", hit_first: np.ndarray, escaped: np.ndarray,
                 queue: "_ShadeQueue") -> tuple[np.ndarray, ...]:
    """One chunk of one glass depth of :func:`_trace`: rays ``idx`` (n,) from ``o`` along ``d`` (n, 3) with
    throughput ``tp_in`` (n, 3) (None at depth 0: 1). Returns the rays going on (idx, origins, dirs, throughput)."""
    t0 = time.perf_counter()
    hits = ctx.prep.scene.intersect(np.ascontiguousarray(o), d)
    ctx.count("camera" if depth == 0 else "glass", len(o), time.perf_counter() - t0)
    miss = ~hits.hit
    if depth > 0:
        escaped[idx[miss]] += tp_in[miss].mean(axis=1)
    hit = np.flatnonzero(hits.hit)
    if depth == 0:
        hit_first[idx] = np.isfinite(hits.t)
        sums.add_first_hits(pixel[idx], hits.t, d, hit)
    if len(hit) == 0:
        return _NONE_GOING
    ids = idx[hit]
    dh = d[hit]
    p = o[hit] + hits.t[hit, None] * dh
    surf = surface_at_hits(ctx.prep, hits.face[hit], hits.bary[hit], dh)
    if depth == 0:
        sums.add_first_surface(pixel[ids], surf)
    tp = np.ones((len(hit), 3)) if tp_in is None else tp_in[hit]
    _shade_hits(ctx, surf, p, -dh, hits.face[hit], tp, ids, queue, inside_glass=depth > 0)
    # Glass continues with its transmission (1 - opacity)(1 - F) tinted by the base colour.
    cont = np.flatnonzero(surf.opacity < 1.0)
    if len(cont) == 0:
        return _NONE_GOING
    params = surf.params
    nv = np.clip(np.einsum("ij,ij->i", surf.normal[cont], -dh[cont]), 0.0, 1.0)
    F = mirror_fresnel(nv, params.take(cont))  # smooth glass: the pane's Fresnel, as its reflection (brdf.py)
    tint = np.sqrt(np.clip(params.base_color[cont], 0.0, 1.0))
    tp_next = tp[cont] * (1.0 - surf.opacity[cont])[:, None] * (1.0 - F) * tint
    return ids[cont], p[cont] - RAY_EPS_M * surf.geometric_normal[cont], dh[cont], tp_next


@dataclass
class PixelSums:
    """Camera samples summed per pixel of the box (P pixels), filled in place as rays are traced.

    Attributes:
        smooth, noisy: (P, 3) float64 summed premultiplied radiance, smooth part and Monte Carlo residual
            (the residual only over samples that carry one, ``carried`` (P,) of them).
        alpha: (P,) summed coverage; solid: (P,) number of samples that hit the object.
        depth_m: (P,) camera z of the nearest hit (inf where none).
        normal: (P, 3) summed first-hit shading normals (object frame); material: (P,) int64 a first-hit
            material (the last sample's that hit), -1 where none.
        samples: camera samples added.
    """

    smooth: np.ndarray
    noisy: np.ndarray
    carried: np.ndarray
    alpha: np.ndarray
    solid: np.ndarray
    depth_m: np.ndarray
    normal: np.ndarray
    material: np.ndarray
    cam_z_obj: np.ndarray
    samples: int = 0

    @staticmethod
    def empty(P: int, cam_z_obj: np.ndarray) -> "PixelSums":
        """Sums over P pixels with no sample yet; ``cam_z_obj`` (3,) is the camera's z axis in the object frame."""
        z = np.zeros
        return PixelSums(z((P, 3)), z((P, 3)), z(P), z(P), z(P), np.full(P, np.inf), z((P, 3)), np.full(P, -1, np.int64),
                         np.asarray(cam_z_obj, np.float64))

    def add_first_hits(self, pixel: np.ndarray, t: np.ndarray, dirs_obj: np.ndarray, hit: np.ndarray) -> None:
        """Camera rays of pixels ``pixel`` (n,) along ``dirs_obj`` (n, 3) with first-hit distances ``t`` (n,)
        (inf = miss), ``hit`` the indices of the hits: coverage count and nearest camera z."""
        P = len(self.solid)
        self.samples += len(pixel)
        self.solid += np.bincount(pixel, weights=np.isfinite(t), minlength=P)
        z = t[hit] * np.einsum("ij,j->i", dirs_obj[hit], self.cam_z_obj)
        np.minimum.at(self.depth_m, pixel[hit], z)

    def add_first_surface(self, pixel: np.ndarray, surf: SurfaceHits) -> None:
        """The G-buffer of first hits in pixels ``pixel`` (n,): summed normal, last material."""
        P = len(self.solid)
        for c in range(3):
            self.normal[:, c] += np.bincount(pixel, weights=surf.normal[:, c], minlength=P)
        self.material[pixel] = surf.material

    def add_shading(self, pixel: np.ndarray, radiance: np.ndarray, alpha: np.ndarray, residual: bool) -> None:
        """Shaded samples of pixels ``pixel`` (N,): radiance (N, 6) (smooth, residual), alpha (N,); the residual
        counts only if the samples carry it (``residual``)."""
        P = len(self.solid)
        for c in range(3):
            self.smooth[:, c] += np.bincount(pixel, weights=radiance[:, c], minlength=P)
        if residual:
            self.carried += np.bincount(pixel, minlength=P)
            for c in range(3):
                self.noisy[:, c] += np.bincount(pixel, weights=radiance[:, 3 + c], minlength=P)
        self.alpha += np.bincount(pixel, weights=alpha, minlength=P)


class _ShadeQueue:
    """Front-face hits waiting to be shaded, shaded in the batches of :func:`.shade.shade` (each batch draws its
    own random numbers: shading n points as one call or as batches of that size is the same computation)."""

    def __init__(self, ctx: ShadingContext, radiance: np.ndarray) -> None:
        s = ctx.settings
        self.ctx, self.radiance, self.parts, self.n = ctx, radiance, [], 0
        self.batch = max(1, shade_module.SHADE_CHUNK_RAYS // max(1, s.sun_samples + s.env_samples + s.brdf_samples))

    def add(self, idx: np.ndarray, tp: np.ndarray, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
            params: BRDFParams, emission: np.ndarray, cv_scale: np.ndarray | None) -> None:
        """Queue points ``p`` (m, 3) of rays ``idx`` (m,) with throughput ``tp`` (m, 3); shade full batches."""
        self.parts.append((idx, tp, p, n_s, n_g, v, params, emission, cv_scale))
        self.n += len(idx)
        while self.n >= self.batch:
            self._shade(self.batch)

    def flush(self) -> None:
        """Shade whatever is queued."""
        if self.n:
            self._shade(self.n)

    def _shade(self, m: int) -> None:
        """Shade the first ``m`` queued points; keep the rest queued."""
        cols = [np.concatenate(c) if i not in (6, 8) else c for i, c in enumerate(zip(*self.parts))]
        self.parts = []  # the queued copies go: only the concatenated ones stay alive while shading
        params = _concat_params(cols[6])
        cv_scale = None if cols[8][0] is None else np.concatenate(cols[8])
        idx, tp, p, n_s, n_g, v, emission = (cols[i] for i in (0, 1, 2, 3, 4, 5, 7))
        smooth, noisy = shade(self.ctx, p[:m], n_s[:m], n_g[:m], v[:m], params.take(slice(0, m)),
                              None if cv_scale is None else cv_scale[:m])
        self.radiance[idx[:m], :3] += tp[:m] * (smooth + emission[:m])
        self.radiance[idx[:m], 3:] += tp[:m] * noisy
        self.n -= m
        if self.n:
            self.parts = [(idx[m:], tp[m:], p[m:], n_s[m:], n_g[m:], v[m:], params.take(slice(m, None)), emission[m:],
                           None if cv_scale is None else cv_scale[m:])]


def _concat_params(parts: list[BRDFParams]) -> BRDFParams:
    """The BRDF parameters of ``parts`` one after the other."""
    def cat(name):
        arrays = [getattr(q, name) for q in parts]
        return None if arrays[0] is None else np.concatenate(arrays)

    return BRDFParams(*(cat(f) for f in ("base_color", "metallic", "roughness", "specular", "clearcoat",
                                         "retroreflective", "flake")))


def _shade_hits(ctx: ShadingContext, surf: SurfaceHits, p: np.ndarray, v: np.ndarray, face: np.ndarray, tp: np.ndarray,
                idx: np.ndarray, queue: _ShadeQueue, inside_glass: bool) -> None:
    """Add the radiance of hits (``surf`` at points ``p``, towards ``v``) x throughput ``tp`` to rays ``idx``
    (``queue.radiance``; front faces through the shading ``queue``).

    Seen through glass (``inside_glass``), the opaque interior (seats, dashboard) gets the interior light
    ``ctx.interior_rgb`` (the sky through the windows, :data:`~.insert.INTERIOR_SKY_FRACTION`) x its base colour,
    brighter on faces that look up (``interior_shading``), not the full light transport: it is dark, seen through
    tinted glass, and shading it fully cost a third of a car's render for no visible difference at 10-40 m.
    Metal behind glass (a lamp's reflector behind its lens, :data:`MIRROR_BEHIND_GLASS_METALLIC`) shows the
    environment's mirror image, as chrome does outside (:func:`_mirror_behind_glass`), not the cabin's light.
    """
    radiance = queue.radiance
    if inside_glass:  # the interior's opaque front faces: cheap light; glass (a far window) is shaded fully
        metal = surf.params.metallic >= MIRROR_BEHIND_GLASS_METALLIC
        opaque_front = surf.front & ~(surf.opacity < 1.0)
        opaque = np.flatnonzero(opaque_front & ~metal)
        if len(opaque):
            shading = interior_shading(surf.normal[opaque], OBJECT_UP)
            radiance[idx[opaque], :3] += tp[opaque] * (
                surf.params.base_color[opaque] * ctx.interior_rgb[None] * shading[:, None] + surf.emission[opaque])
        _mirror_behind_glass(ctx, surf, v, tp, idx, radiance, np.flatnonzero(opaque_front & metal))
        surf_front = surf.front & (surf.opacity < 1.0)
    else:
        surf_front = surf.front
    # Front faces: full shading (glass: diffuse scaled by opacity, specular reflection kept).
    fr = np.flatnonzero(surf_front)
    if len(fr):
        pr = surf.params.take(fr)
        op = surf.opacity[fr]
        pr = BRDFParams(pr.base_color * op[:, None], pr.metallic, pr.roughness, pr.specular, pr.clearcoat,
                        pr.retroreflective, pr.flake)
        scale = None if ctx.bounce is None else ctx.bounce.face_sky_visibility(face[fr])
        queue.add(idx[fr], tp[fr], p[fr], surf.normal[fr], surf.geometric_normal[fr], v[fr], pr, surf.emission[fr], scale)
    # Back faces (inside the car): opaque ones seen through glass show the dark interior; seen
    # directly (through a hole of an open mesh, e.g. a hollow tyre) they get no light at all.
    if inside_glass:
        inner = np.flatnonzero(~surf.front & ~(surf.opacity < 1.0))
        if len(inner):
            radiance[idx[inner], :3] += tp[inner] * surf.params.base_color[inner] * ctx.interior_rgb[None]


OBJECT_UP = np.array([0.0, 0.0, 1.0])
MIRROR_BEHIND_GLASS_METALLIC = 0.5  # opaque faces behind glass at least this metallic mirror the environment


def _mirror_behind_glass(ctx: ShadingContext, surf: SurfaceHits, v: np.ndarray, tp: np.ndarray, idx: np.ndarray,
                         radiance: np.ndarray, sel: np.ndarray) -> None:
    """Add to ``radiance`` (rows ``idx[sel]``) the mirror image of the environment on metal seen through glass (a
    lamp's reflector behind its lens): the lobe's mirror albedo x the full-resolution map at the mirror direction
    (the shader's smooth mirror term, unoccluded), x the throughput ``tp`` twice: the light comes in through the
    same lens it leaves by.  Plus the face's emission x ``tp``."""
    if len(sel) == 0:
        return
    pr = surf.params.take(sel)
    n, vv = surf.normal[sel], v[sel]
    n_v = np.clip(np.einsum("ij,ij->i", n, vv), 0.0, 1.0)
    r_cam = reflect(vv, n) @ ctx.R_cam_from_obj.T
    alb = mirror_albedo(n_v, pr, np.ones(len(sel)))  # the lobe taken as a mirror
    L = shade_module.lookup_envmap(ctx.env.pyramid[0], r_cam)
    radiance[idx[sel], :3] += tp[sel] * (tp[sel] * alb * L + surf.emission[sel])


def interior_shading(normal: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N,) relative brightness of interior faces with unit ``normal`` (N, 3): 1.5 facing ``up`` (3,) (the
    windows above), 0.5 facing down; mean 1 over the sphere (the interior light's scale is kept)."""
    return 1.0 + 0.5 * (normal @ np.asarray(up, np.float64))


def _jittered_samples(xs: np.ndarray, ys: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """n x n stratified jittered sub-pixel positions for pixels (xs, ys) (P,): returns uv (P n^2, 2), pixel id (P n^2,)."""
    P = len(xs)
    g = (np.arange(n) + 0.0) / n
    gx, gy = np.meshgrid(g, g)
    offs = np.stack([gx.ravel(), gy.ravel()], axis=1)  # (n^2, 2)
    jitter = rng.random((P, n * n, 2)) / n
    uv = np.stack([xs, ys], axis=1)[:, None, :] - 0.5 + offs[None] + jitter
    return uv.reshape(-1, 2), np.repeat(np.arange(P), n * n)


def denoise_radiance(radiance_premult: np.ndarray, alpha: np.ndarray, normal: np.ndarray, material: np.ndarray,
                     radius: int = 3, sigma_px: float = 2.0, sigma_normal: float = 0.15,
                     depth_m: np.ndarray | None = None) -> np.ndarray:
    """Cross-bilateral filter of the object's Monte Carlo noise, guided by its noise-free G-buffer.

    A joint bilateral filter (OpenCV ximgproc) whose guide is the first-hit normal, with each material
    shifted far apart in guide space: each pixel's radiance becomes a weighted mean over a
    (2r+1)^2 window of pixels with the same material and a similar normal (Gaussian in pixel distance
    and normal difference).  With ``depth_m`` (and camera-frame normals, whose z is then redundant) the
    third guide channel is the depth instead, so surfaces far apart in depth do not mix.  The radiance
    is filtered un-premultiplied (uncovered pixels excluded) and multiplied by the pixel's own alpha again.
    Shapes: (h, w, 3), (h, w), (h, w, 3) unit normals, (h, w) int (-1 = none), (h, w) metres (inf = none).
    """
    guide = (normal * 0.5 + 0.5).astype(np.float32)
    guide[..., 0] += 100.0 * (material.astype(np.float32) + 1.0)  # different materials (and "none") never mix
    if depth_m is not None:
        d = np.where(np.isfinite(depth_m), depth_m, 0.0)
        guide[..., 2] = (d * DENOISE_DEPTH_SCALE_PER_M).astype(np.float32)
    guide[alpha <= 0, 0] = -1000.0  # uncovered pixels form their own class
    d = 2 * radius + 1
    with np.errstate(divide="ignore", invalid="ignore"):
        rad = np.where(alpha[..., None] > 0, radiance_premult / alpha[..., None], 0.0).astype(np.float32)
    # OpenCV's colour sigma is in guide units: normal difference sigma_normal maps to sigma_normal / 2.
    out = cv2.ximgproc.jointBilateralFilter(guide, rad, d, sigma_normal / 2.0, sigma_px) * alpha[..., None]
    return np.where(alpha[..., None] > 0, out, radiance_premult)
