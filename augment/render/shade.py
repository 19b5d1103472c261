"""Foreground rendering: camera rays through the object's pixels, G-buffer, Monte Carlo shading.

Pipeline (all vectorised, rays in big Embree batches)::

    object box -> pixel box -> n x n jittered camera samples (+ k x k more in silhouette pixels, 2 x 2
      at material boundaries and shading discontinuities)
      -> ray-mesh hits (object frame) -> G-buffer (point, smooth normal facing the viewer, material, uv,
         textures: base colour, metallic-roughness, normal map)
      -> shading: sun (disc-sampled, self-shadowing ray) + environment (MIS of env-map CDF and BRDF
         sampling, power heuristic, self-occlusion rays) with control variates: the unoccluded diffuse
         term and, for rough lobes, the specular albedo x cosine term are integrated exactly from the
         irradiance map, so only occlusion and the lobes' shape carry Monte Carlo noise
      -> glass: reflection on the glass + the continued ray (dark interior or what lies behind)
      -> per-pixel premultiplied radiance, coverage alpha, camera-z depth
      -> G-buffer-guided cross-bilateral denoising of the Monte Carlo residual only.

Rays the object blocks see its own surface (the one-bounce model of :mod:`.bounce`); free rays
leaving it downwards see the environment's lower hemisphere (the ground radiance of the estimate)
times the shadow ratio where they land (:class:`streetaug.augment.render.shadow.GroundShadow`), so a
car's underside and tyres see its own shadow.  Shading happens in the object frame; environment
directions are rotated to the camera frame only to look the map up.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..core import invert_transform, project_points
from ..lighting.light import DistantLight
from .bounce import BounceLight
from .brdf import BRDFParams, brdf_pdf, eval_brdf, row_norm, sample_brdf, schlick_weight, specular_albedo
from .geometry import PreparedAsset, sample_texture
from .sampling import EnvSampler, env_pyramid, env_sampler_for, irradiance_map, lookup_irradiance, sample_cone, sampler_map
from .settings import RenderSettings

if TYPE_CHECKING:  # shadow imports this module
    from .shadow import GroundShadow

RAY_EPS_M = 1e-3  # ray origin offset along the geometric normal
FIS_LEVEL_BIAS = 1  # filtered importance sampling one level sharper than the sample footprint (less blur bias)


@dataclass(frozen=True)
class Foreground:
    """The rendered object over its pixel box.

    Attributes:
        x0, y0: top-left pixel of the box in the image (the box is ``alpha.shape`` big).
        radiance_premult: (h, w, 3) float32 linear radiance x coverage (premultiplied).
        alpha: (h, w) float32 coverage in [0, 1] (glass that shows the scene behind lowers it).
        depth_m: (h, w) float32 camera-frame z of the nearest hit, inf where the object is absent.
        stats: rays cast per stage and sample counts.
    """

    x0: int
    y0: int
    radiance_premult: np.ndarray
    alpha: np.ndarray
    depth_m: np.ndarray
    stats: dict = field(default_factory=dict)


def object_pixel_box(K: np.ndarray, width: int, height: int, T_cam_from_object: np.ndarray,
                     corners_object: np.ndarray, pad_px: int = 2) -> tuple[int, int, int, int] | None:
    """Integer pixel box (x0, y0, x1, y1), end-exclusive, covering the projected object box, or None if off-screen."""
    pts = corners_object @ T_cam_from_object[:3, :3].T + T_cam_from_object[:3, 3]
    z = pts[:, 2]
    if np.all(z <= 1e-3):
        return None
    if np.any(z <= 1e-3):
        # The box straddles the camera plane: anything on screen may be covered.
        return 0, 0, width, height
    uv, _ = project_points(K, pts)
    x0 = int(np.floor(uv[:, 0].min())) - pad_px
    y0 = int(np.floor(uv[:, 1].min())) - pad_px
    x1 = int(np.ceil(uv[:, 0].max())) + pad_px + 1
    y1 = int(np.ceil(uv[:, 1].max())) + pad_px + 1
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


def camera_rays(K: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Unit camera-frame ray directions (N, 3) through pixel positions uv (N, 2) (as ``pixel_rays``, BLAS-free)."""
    d = np.concatenate([uv, np.ones((len(uv), 1))], axis=1) @ np.linalg.inv(K).T
    return d / np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]


def filtered_env_radiance(pyramid: list[np.ndarray], dirs_cam: np.ndarray, sample_sr: np.ndarray) -> np.ndarray:
    """Filtered importance sampling (Krivanek & Colbert 2008): radiance (N, 3) from the pyramid level whose
    texel solid angle matches the solid angle ``sample_sr`` (N,) each sample stands for (1 / (n pdf))."""
    H0, W0 = pyramid[0].shape[:2]
    texel_sr = 4.0 * np.pi / (H0 * W0) * 1.3  # mean texel solid angle of level 0 (x1.3: the equator's)
    level = np.clip(np.floor(0.5 * np.log2(np.maximum(sample_sr, 1e-12) / texel_sr)) - FIS_LEVEL_BIAS, 0, len(pyramid) - 1).astype(np.int64)
    out = np.empty((len(dirs_cam), 3))
    for lev in np.unique(level):
        sel = np.flatnonzero(level == lev)
        out[sel] = lookup_equirect(pyramid[lev], dirs_cam[sel])
    return out


def env_radiance(light: DistantLight, dirs_cam: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) of the environment map (sun excluded) from unit camera-frame directions (N, 3)."""
    return lookup_equirect(light.envmap, dirs_cam)


def lookup_equirect(env: np.ndarray, dirs_cam: np.ndarray) -> np.ndarray:
    """Bilinear lookup (N, C) of a camera-frame equirect map (H, W, C) at unit directions (N, 3).

    Same as :func:`streetaug.augment.core.sample_equirect` (wrapping in longitude, clamped
    in latitude), written with flat gathers for speed.
    """
    H, W = env.shape[:2]
    flat = env.reshape(H * W, -1)
    d = np.asarray(dirs_cam)
    lon = np.arctan2(d[:, 0], d[:, 2])
    lat = np.arcsin(np.clip(-d[:, 1], -1.0, 1.0))
    x = (lon * (0.5 / np.pi) + 0.5) * W - 0.5
    y = np.clip((0.5 - lat / np.pi) * H - 0.5, 0.0, H - 1.0)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa = np.mod(x0, W)
    xb = np.mod(x0 + 1, W)
    ra = y0 * W
    rb = np.minimum(y0 + 1, H - 1) * W
    top = flat[ra + xa] * (1 - fx) + flat[ra + xb] * fx
    bot = flat[rb + xa] * (1 - fx) + flat[rb + xb] * fx
    return top * (1 - fy) + bot * fy


@dataclass
class _Ctx:
    prep: PreparedAsset
    light: DistantLight
    sampler: EnvSampler
    R_cam_from_obj: np.ndarray
    sun_dir_obj: np.ndarray | None
    settings: RenderSettings
    rng: np.random.Generator
    ambient_rgb: np.ndarray
    interior_rgb: np.ndarray
    rays: dict
    irradiance: np.ndarray
    pyramid: list
    bounce: BounceLight | None = None
    foot_ratio: np.ndarray = field(default_factory=lambda: np.full(3, 0.15))
    ground_shadow: "GroundShadow | None" = None
    sampler_env: np.ndarray | None = None
    raycast_s: float = 0.0


def surface_at_hits(prep: PreparedAsset, face: np.ndarray, bary: np.ndarray, dirs: np.ndarray):
    """G-buffer for ray hits (object frame): (smooth normal, geometric normal, front-facing, params, opacity, emission).

    Args:
        face: (N,) index into ``prep.faces``; bary: (N, 2) barycentrics; dirs: (N, 3) unit ray directions.

    Both normals face the ray's origin; textures (base colour, metallic-roughness, normal map) are applied.
    """
    asset = prep.asset
    f = prep.faces[face]
    u, v = bary[:, :1], bary[:, 1:]
    w0 = 1.0 - u - v
    vn = asset.vertex_normals
    n_s = w0 * vn[f[:, 0]] + u * vn[f[:, 1]] + v * vn[f[:, 2]]
    n_g = prep.face_normal[face]
    front = np.einsum("ij,ij->i", dirs, n_g) < 0.0
    n_g = np.where(front[:, None], n_g, -n_g)
    # Smooth normal on the viewer's side of the geometry.
    n_s = np.where((np.einsum("ij,ij->i", n_s, n_g) < 0.0)[:, None], -n_s, n_s)
    n_s /= np.maximum(row_norm(n_s)[:, None], 1e-12)
    bad = ~np.isfinite(n_s).all(axis=1) | (row_norm(n_s) < 0.5)
    n_s[bad] = n_g[bad]
    mid = prep.face_material[face]
    base = prep.base_color[mid].copy()
    metallic = prep.metallic[mid].copy()
    rough = prep.roughness[mid].copy()
    if asset.uv is not None:
        uvs = asset.uv[f]
        uv = w0 * uvs[:, 0] + u * uvs[:, 1] + v * uvs[:, 2]
        for m_index, mat in enumerate(asset.materials):
            sel = np.flatnonzero(mid == m_index)
            if len(sel) == 0:
                continue
            if mat.base_color_texture is not None:
                base[sel] *= sample_texture(mat.base_color_texture, uv[sel])[:, :3]
            if mat.metallic_roughness_texture is not None:
                mr = sample_texture(mat.metallic_roughness_texture, uv[sel])
                rough[sel] *= mr[:, 1]
                metallic[sel] *= mr[:, 2]
            if mat.normal_texture is not None and prep.face_tangent is not None:
                t_n = sample_texture(mat.normal_texture, uv[sel]) * 2.0 - 1.0
                T = prep.face_tangent[face[sel]]
                B = prep.face_bitangent[face[sel]]
                ns = n_s[sel]
                T = T - np.einsum("ij,ij->i", T, ns)[:, None] * ns
                T /= np.maximum(row_norm(T)[:, None], 1e-12)
                B = B - np.einsum("ij,ij->i", B, ns)[:, None] * ns - np.einsum("ij,ij->i", B, T)[:, None] * T
                B /= np.maximum(row_norm(B)[:, None], 1e-12)
                nm = t_n[:, :1] * T + t_n[:, 1:2] * B + t_n[:, 2:3] * ns
                nm /= np.maximum(row_norm(nm)[:, None], 1e-12)
                n_s[sel] = np.where(np.isfinite(nm).all(axis=1, keepdims=True), nm, ns)
    # Keep the shading normal within the viewer's hemisphere (avoids black rims on smoothed meshes).
    view = -dirs
    nv = np.einsum("ij,ij->i", n_s, view)
    fix = nv < 0.02
    if np.any(fix):
        n_s[fix] += view[fix] * (0.02 - nv[fix])[:, None]
        n_s[fix] /= row_norm(n_s[fix])[:, None]
    params = BRDFParams(base, np.clip(metallic, 0, 1), np.clip(rough, 0, 1), prep.specular[mid], prep.clearcoat[mid])
    return n_s, n_g, front, params, prep.opacity[mid], prep.emission[mid]


EDGE_LIGHT_SAMPLES = {"sun_samples": 1, "env_samples": 0, "brdf_samples": 1}  # per extra edge sample
SHADING_EDGE_REL = 0.15  # relative jump of the noise-free radiance that marks a pixel for more samples
SHADE_CHUNK_RAYS = 300_000  # light-sample rays per batch: bounds memory, keeps Embree batches large


def _shade(ctx: _Ctx, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
           params: BRDFParams, cv_scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Outgoing radiance towards ``v`` at object-frame points ``p`` (N, 3): sun + environment (MIS).

    Returned in two parts, each (N, 3): ``smooth`` (the control variates' exact expectations and the
    sun, whose only noise is at self-shadow edges) and ``noisy`` (the Monte Carlo environment residual),
    so that the denoiser can filter the second much more strongly.  Processed in chunks of
    :data:`SHADE_CHUNK_RAYS` light samples.  ``cv_scale`` (N,) scales the control variates per point
    (any constant keeps the estimate unbiased; the sky's visible fraction there minimises the residual).
    """
    s = ctx.settings
    per_point = max(1, s.sun_samples + s.env_samples + s.brdf_samples)
    chunk = max(1, SHADE_CHUNK_RAYS // per_point)
    if len(p) <= chunk:
        return _shade_batch(ctx, p, n_s, n_g, v, params, cv_scale)
    smooth, noisy = np.empty((len(p), 3)), np.empty((len(p), 3))
    for a in range(0, len(p), chunk):
        sl = slice(a, a + chunk)
        smooth[sl], noisy[sl] = _shade_batch(ctx, p[sl], n_s[sl], n_g[sl], v[sl], params.take(sl),
                                             None if cv_scale is None else cv_scale[sl])
    return smooth, noisy


SPEC_CV_ROUGHNESS = (0.5, 0.75)  # the specular control variate fades in between these roughnesses (measured)


def spec_cv_weight(roughness: np.ndarray) -> np.ndarray:
    """Weight (N,) in [0, 1] of the cosine control variate for the specular lobe (0 glossy, 1 rough)."""
    lo, hi = SPEC_CV_ROUGHNESS
    return np.clip((np.asarray(roughness) - lo) / (hi - lo), 0.0, 1.0)


def _shade_batch(ctx: _Ctx, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
                 params: BRDFParams, cv_scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One chunk of :func:`_shade`: (smooth, noisy) radiance parts, each (N, 3)."""
    N = len(p)
    params = params.precompute()
    s = ctx.settings
    rng = ctx.rng
    R = ctx.R_cam_from_obj
    smooth = np.zeros((N, 3))
    noisy = np.zeros((N, 3))
    origins_all, dirs_all, kinds = [], [], []

    # -- sun: directions in the disc, explicit.
    ns_sun = s.sun_samples if ctx.sun_dir_obj is not None else 0
    if ns_sun:
        sun = ctx.light.sun
        idx_sun = np.repeat(np.arange(N), ns_sun)
        l_sun = sample_cone(ctx.sun_dir_obj, sun.half_angle_rad, rng.random(len(idx_sun)), rng.random(len(idx_sun)))
        f = eval_brdf(n_s[idx_sun], v[idx_sun], l_sun, params.take(idx_sun))
        cos = np.clip(np.einsum("ij,ij->i", n_s[idx_sun], l_sun), 0.0, 1.0)
        up = np.einsum("ij,ij->i", n_g[idx_sun], l_sun) > 0
        contrib_sun = f * (cos * up / ns_sun)[:, None] * np.asarray(sun.irradiance_rgb)[None]
        live = np.flatnonzero(up & (contrib_sun.max(axis=1) > 0))
        origins_all.append(p[idx_sun[live]] + RAY_EPS_M * n_g[idx_sun[live]])
        dirs_all.append(l_sun[live])
        kinds.append(("sun", idx_sun[live], contrib_sun[live], None))

    # -- environment: MIS of env-map importance and BRDF sampling, with the unoccluded diffuse
    #    term as a control variate: per sample we subtract g = c_d/pi L cos (MIS-weighted) and add its
    #    exact expectation c_d/pi E(n) from the irradiance map, so unblocked diffuse light is noise-free.
    n_e, n_b = s.env_samples, s.brdf_samples
    n_v = np.clip(np.einsum("ij,ij->i", n_s, v), 0, 1)
    coat_keep = 1.0 - params.clearcoat * (0.04 + 0.96 * schlick_weight(n_v))
    # Rough specular lobes are nearly cosine-shaped: their directional albedo x cos / pi is a good
    # control variate too (its exact expectation is again the irradiance); glossy lobes get none.
    spec_cv = specular_albedo(n_v, params) * spec_cv_weight(params.roughness)[:, None]
    g_color = (params.c_diff + spec_cv) / np.pi * coat_keep[:, None]  # (N, 3)
    if cv_scale is not None:
        g_color = g_color * cv_scale[:, None]
    E_n = lookup_irradiance(ctx.irradiance, n_s @ R.T)
    smooth += g_color * E_n
    for kind, count in (("env", n_e), ("brdf", n_b)):
        if count == 0:
            continue
        idx = np.repeat(np.arange(N), count)
        pr = params.take(idx)
        nn, vv, ng = n_s[idx], v[idx], n_g[idx]
        if kind == "env":
            l_cam, p_env = ctx.sampler.sample(rng.random((len(idx), 3)))
            l = l_cam @ R  # camera -> object frame (R^T l)
            p_brdf = brdf_pdf(nn, vv, l, pr)
            w = (n_e * p_env) ** 2 / np.maximum((n_e * p_env) ** 2 + (n_b * p_brdf) ** 2, 1e-300) / (n_e * p_env)
        else:
            l = sample_brdf(nn, vv, pr, rng.random((len(idx), 3)))
            l_cam = l @ R.T
            p_brdf = brdf_pdf(nn, vv, l, pr)
            p_env = ctx.sampler.pdf(l_cam) if n_e else np.zeros(len(idx))
            w = (n_b * p_brdf) ** 2 / np.maximum((n_e * p_env) ** 2 + (n_b * p_brdf) ** 2, 1e-300) / np.maximum(n_b * p_brdf, 1e-300)
        cos = np.clip(np.einsum("ij,ij->i", nn, l), 0.0, 1.0)
        up = np.einsum("ij,ij->i", ng, l) > 0
        cw = cos * w  # cos / (n p) x MIS weight
        live = np.flatnonzero(cw > 0)
        il = idx[live]
        weight = eval_brdf(nn[live], vv[live], l[live], pr.take(live)) * cw[live, None]
        if kind == "brdf":  # filtered importance sampling: a sample of a wide lobe sees a blurred sky
            L = filtered_env_radiance(ctx.pyramid, l_cam[live], 1.0 / np.maximum(n_b * p_brdf[live], 1e-12))
        else:
            L = lookup_equirect(ctx.sampler_env, l_cam[live])  # the map the samples were drawn from
        cv = g_color[il] * cw[live, None] * L  # the control variate, MIS-weighted
        contrib = weight * L - cv
        # Rays under the geometric surface count as blocked (by the surface itself) without tracing them.
        below = ~up[live]
        down = np.flatnonzero(below)
        if len(down):
            blocked_c = weight[down] * ctx.ambient_rgb[None] - cv[down]
            for k in range(3):
                noisy[:, k] += np.bincount(il[down], weights=blocked_c[:, k], minlength=N)
        keep = np.flatnonzero(~below)
        origins_all.append(p[il[keep]] + RAY_EPS_M * ng[live[keep]])
        dirs_all.append(l[live[keep]])
        kinds.append((kind, il[keep], contrib[keep], (weight[keep], cv[keep], weight[keep] * L[keep])))

    if not origins_all:
        return smooth, noisy
    origins = np.concatenate(origins_all)
    dirs = np.concatenate(dirs_all)
    t0 = time.perf_counter()
    blocked = ctx.prep.scene.occluded(origins, dirs) if len(origins) else np.zeros(0, bool)
    ctx.raycast_s += time.perf_counter() - t0
    ctx.rays["shade_visibility"] = ctx.rays.get("shade_visibility", 0) + len(origins)
    start = 0
    for kind, idx, contrib, extra in kinds:
        b = blocked[start:start + len(idx)]
        o, d = origins[start:start + len(idx)], dirs[start:start + len(idx)]
        start += len(idx)
        if extra is None:  # sun: blocked means no light
            c = np.where(b[:, None], 0.0, contrib)
            target = smooth
        else:  # environment: blocked rays see the object's own surface (one approximate bounce)
            weight, cv, wL = extra
            c = contrib.copy()
            bi = np.flatnonzero(b)
            if len(bi):
                c[bi] = weight[bi] * _blocked_radiance(ctx, o[bi], d[bi]) - cv[bi]
            if ctx.ground_shadow is not None:  # free rays going down land on the (possibly shadowed) ground
                fi = np.flatnonzero(~b & (d @ ctx.ground_shadow.up_obj < 0))
                if len(fi):
                    c[fi] += wL[fi] * (ctx.ground_shadow.ratio_along(o[fi], d[fi]) - 1.0)
            target = noisy
        for k in range(3):
            target[:, k] += np.bincount(idx, weights=c[:, k], minlength=N)
    return smooth, noisy


def _blocked_radiance(ctx: _Ctx, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) arriving along rays the object blocks: its surface there (see :mod:`.bounce`)."""
    if ctx.bounce is None:
        return np.broadcast_to(ctx.ambient_rgb, (len(origins), 3))
    t0 = time.perf_counter()
    hits = ctx.prep.scene.intersect(origins, dirs)
    ctx.raycast_s += time.perf_counter() - t0
    ctx.rays["shade_bounce"] = ctx.rays.get("shade_bounce", 0) + len(origins)
    out = np.broadcast_to(ctx.ambient_rgb, (len(origins), 3)).copy()
    h = np.flatnonzero(hits.hit)
    if len(h):
        A, B = ctx.bounce.radiance(hits.face[h], dirs[h])
        out[h] = A + B * ctx.foot_ratio[None]
    return out


def _trace(ctx: _Ctx, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Follow camera rays (object frame) through glass.

    Returns:
        radiance: (N, 6) premultiplied radiance of each ray: smooth part (3) then noisy part (3) (see :func:`_shade`).
        alpha: (N,) 1 - fraction of the background seen along the ray (0 where the ray misses).
        t_first: (N,) distance to the first hit, inf where none.
        normal_first: (N, 3) shading normal at the first hit (object frame), 0 where none.
        material_first: (N,) material index at the first hit, -1 where none.
    """
    N = len(origins)
    radiance = np.zeros((N, 6))
    normal_first = np.zeros((N, 3))
    material_first = np.full(N, -1, dtype=np.int64)
    escaped = np.zeros(N)
    t_first = np.full(N, np.inf)
    throughput = np.ones((N, 3))
    active = np.arange(N)
    o, d = origins, dirs
    for depth in range(ctx.settings.max_glass_depth):
        t0 = time.perf_counter()
        hits = ctx.prep.scene.intersect(o, d)
        ctx.raycast_s += time.perf_counter() - t0
        ctx.rays["camera" if depth == 0 else "glass"] = ctx.rays.get("camera" if depth == 0 else "glass", 0) + len(o)
        if depth == 0:
            t_first[active] = hits.t
        miss = ~hits.hit
        if depth > 0:
            escaped[active[miss]] += throughput[active[miss]].mean(axis=1)
        hit = np.flatnonzero(hits.hit)
        if len(hit) == 0:
            break
        idx = active[hit]
        dh = d[hit]
        p = o[hit] + hits.t[hit, None] * dh
        n_s, n_g, front, params, opacity, emission = surface_at_hits(ctx.prep, hits.face[hit], hits.bary[hit], dh)
        if depth == 0:
            normal_first[idx] = n_s
            material_first[idx] = ctx.prep.face_material[hits.face[hit]]
        v = -dh
        glass = opacity < 1.0
        tp = throughput[idx]
        # Front faces: full shading (glass: diffuse scaled by opacity, specular reflection kept).
        fr = np.flatnonzero(front)
        if len(fr):
            pr = params.take(fr)
            op = opacity[fr]
            pr = BRDFParams(pr.base_color * op[:, None], pr.metallic, pr.roughness, pr.specular, pr.clearcoat)
            scale = None if ctx.bounce is None else ctx.bounce.face_sky_visibility(hits.face[hit][fr])
            smooth, noisy = _shade(ctx, p[fr], n_s[fr], n_g[fr], v[fr], pr, scale)
            radiance[idx[fr], :3] += tp[fr] * (smooth + emission[fr])
            radiance[idx[fr], 3:] += tp[fr] * noisy
        # Back faces (inside the car): opaque ones seen through glass show the dark interior; seen
        # directly (through a hole of an open mesh, e.g. a hollow tyre) they get no light at all.
        inner = np.flatnonzero(~front & ~glass) if depth > 0 else np.zeros(0, np.int64)
        if len(inner):
            radiance[idx[inner], :3] += tp[inner] * params.base_color[inner] * ctx.interior_rgb[None]
        # Glass continues with its transmission (1 - opacity)(1 - F) tinted by the base colour.
        cont = np.flatnonzero(glass)
        if len(cont) == 0:
            break
        nv = np.clip(np.einsum("ij,ij->i", n_s[cont], v[cont]), 0.0, 1.0)
        c_spec = params.take(cont).c_spec
        F = c_spec + (1 - c_spec) * schlick_weight(nv)[:, None]
        tint = np.sqrt(np.clip(params.base_color[cont], 0.0, 1.0))
        throughput[idx[cont]] = tp[cont] * (1.0 - opacity[cont])[:, None] * (1.0 - F) * tint
        active = idx[cont]
        o = p[cont] - RAY_EPS_M * n_g[cont]
        d = dh[cont]
    # Whatever still travels after the last surface is absorbed by the (dark) interior.
    alpha = np.where(np.isfinite(t_first), 1.0 - escaped, 0.0)
    return radiance, alpha, t_first, normal_first, material_first


def _jittered_samples(xs: np.ndarray, ys: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """n x n stratified jittered sub-pixel positions for pixels (xs, ys) (P,): returns uv (P n^2, 2), pixel id (P n^2,)."""
    P = len(xs)
    g = (np.arange(n) + 0.0) / n
    gx, gy = np.meshgrid(g, g)
    offs = np.stack([gx.ravel(), gy.ravel()], axis=1)  # (n^2, 2)
    jitter = rng.random((P, n * n, 2)) / n
    uv = np.stack([xs, ys], axis=1)[:, None, :] - 0.5 + offs[None] + jitter
    return uv.reshape(-1, 2), np.repeat(np.arange(P), n * n)


def render_foreground(K: np.ndarray, width: int, height: int, light: DistantLight, prep: PreparedAsset,
                      T_cam_from_object: np.ndarray, settings: RenderSettings, rng: np.random.Generator,
                      ambient_rgb: np.ndarray, interior_rgb: np.ndarray, bounce: BounceLight | None = None,
                      foot_ratio: np.ndarray | None = None, ground_shadow: "GroundShadow | None" = None) -> Foreground | None:
    """Render the object over its pixel box (see module docstring); None if it is off-screen.

    Args:
        K: (3, 3) intrinsics; width, height: image size in pixels.
        light: camera-frame distant light.
        prep: the prepared asset; T_cam_from_object: (4, 4) pose.
        ambient_rgb: (3,) radiance seen by rays the car blocks when ``bounce`` is None (and by rays
            going under the geometric surface).
        interior_rgb: (3,) irradiance-like factor for the car's interior (x base colour = radiance).
        bounce: radiance model of the object's own surfaces for the rays it blocks (one bounce).
        foot_ratio: (3,) mean shadow ratio under the object (from the shadow pass), for ``bounce``.
        ground_shadow: the shadow ratio map seen from the object: rays that leave it downwards see the
            ground radiance of the map times the ratio where they land (the object's own shadow).
    """
    box = object_pixel_box(K, width, height, T_cam_from_object, prep.box_corners_object)
    if box is None:
        return None
    x0, y0, x1, y1 = box
    w, h = x1 - x0, y1 - y0
    T_obj_from_cam = invert_transform(T_cam_from_object)
    R = T_cam_from_object[:3, :3]
    sun_obj = None if light.sun is None else R.T @ np.asarray(light.sun.direction, dtype=np.float64)
    ctx = _Ctx(prep, light, env_sampler_for(light.envmap), R, sun_obj, settings, rng,
               np.asarray(ambient_rgb, dtype=np.float64), np.asarray(interior_rgb, dtype=np.float64), {},
               irradiance_map(light.envmap), env_pyramid(light.envmap), bounce,
               np.full(3, 0.15) if foot_ratio is None else np.asarray(foot_ratio, dtype=np.float64), ground_shadow,
               sampler_map(light.envmap))
    cam_obj = T_obj_from_cam[:3, 3]

    def cast(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d_obj = camera_rays(K, uv) @ R  # camera -> object frame
        o_obj = np.broadcast_to(cam_obj, d_obj.shape)
        return _trace(ctx, np.ascontiguousarray(o_obj), d_obj) + (d_obj,)

    def merge(a, b):
        return tuple(np.concatenate([x, y]) for x, y in zip(a, b))

    ys, xs = np.divmod(np.arange(w * h), w)
    n = settings.aa_grid
    uv, pix = _jittered_samples(xs + x0, ys + y0, n, rng)
    traced = cast(uv)
    t = traced[2]
    hit = np.isfinite(t)
    counts = np.full(w * h, n * n, dtype=np.float64)
    # Silhouette pixels (mixed coverage or next to one) get k x k more samples.
    nhit = np.bincount(pix, weights=hit, minlength=w * h).reshape(h, w)
    any_hit = (nhit > 0).astype(np.uint8)
    all_hit = (nhit == n * n).astype(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    silhouette = (cv2.dilate(any_hit, kernel) > 0) & ~(cv2.erode(all_hit, kernel, borderType=cv2.BORDER_REPLICATE) > 0)
    # Material boundaries inside the object (window frames, tyres, lights) get a few samples more too.
    mat = np.full(w * h, -1.0, np.float32)
    first_hit = traced[4] >= 0
    mat[pix[first_hit]] = traced[4][first_hit]
    mat = mat.reshape(h, w)
    inner = (cv2.dilate(mat, kernel) != cv2.erode(mat, kernel, borderType=cv2.BORDER_REPLICATE)) & ~silhouette
    # Shading discontinuities (creases between flat faces, self-shadow edges): the noise-free part of
    # the first pass jumps by more than SHADING_EDGE_REL between neighbours.
    smooth_lum = np.bincount(pix, weights=traced[0][:, :3] @ np.array([0.2126, 0.7152, 0.0722]), minlength=w * h)
    smooth_lum = np.log(np.maximum(smooth_lum.reshape(h, w) / (n * n), 1e-4)).astype(np.float32)
    jump = cv2.dilate(smooth_lum, kernel) - cv2.erode(smooth_lum, kernel, borderType=cv2.BORDER_REPLICATE)
    inner |= (jump > np.log1p(SHADING_EDGE_REL)) & (mat >= 0) & ~silhouette
    n_edge = 0
    # The extra samples are there for coverage and sharp shading edges; each pixel averages k x k of
    # them, so each needs fewer light samples (EDGE_LIGHT_SAMPLES instead of the preset's).
    ctx.settings = dataclasses.replace(settings, **{k: min(getattr(settings, k), v) for k, v in EDGE_LIGHT_SAMPLES.items()})
    for edge, k in ((silhouette, settings.edge_grid), (inner, min(settings.edge_grid, 2))):
        edge_ids = np.flatnonzero(edge.ravel())
        if len(edge_ids) == 0 or k <= 1:
            continue
        uv2, pix2 = _jittered_samples(xs[edge_ids] + x0, ys[edge_ids] + y0, k, rng)
        traced = merge(traced, cast(uv2))
        counts[edge_ids] += k * k
        n_edge += len(uv2)
        pix = np.concatenate([pix, edge_ids[pix2]])
    rad, alpha, t, n_first, m_first, d_obj = traced
    P = w * h
    rad_px = np.stack([np.bincount(pix, weights=rad[:, c], minlength=P) for c in range(6)], axis=1) / counts[:, None]
    alpha_px = np.bincount(pix, weights=alpha, minlength=P) / counts
    # Camera z of the nearest hit per pixel.
    z = np.where(np.isfinite(t), t * np.einsum("ij,j->i", d_obj, R[2]), np.inf)
    depth_px = np.full(P, np.inf)
    np.minimum.at(depth_px, pix, z)
    # G-buffer per pixel (mean first-hit normal, a first-hit material) for the denoiser.
    hit_all = m_first >= 0
    n_px = np.stack([np.bincount(pix, weights=n_first[:, c], minlength=P) for c in range(3)], axis=1)
    n_px /= np.maximum(row_norm(n_px)[:, None], 1e-9)
    m_px = np.full(P, -1, dtype=np.int64)
    m_px[pix[hit_all]] = m_first[hit_all]
    smooth_px, noisy_px = rad_px[:, :3], rad_px[:, 3:]
    if settings.denoise:
        # Only the Monte Carlo residual is filtered (widely); the control variates' expectations and
        # the sun keep their full sharpness.  Guide: camera-frame normal, material, depth.
        n_cam = n_px @ R.T
        noisy_px = denoise_radiance(noisy_px.reshape(h, w, 3), alpha_px.reshape(h, w), n_cam.reshape(h, w, 3),
                                    m_px.reshape(h, w), depth_m=depth_px.reshape(h, w),
                                    radius=DENOISE_RADIUS_PX, sigma_px=DENOISE_SIGMA_PX).reshape(P, 3)
    rad_px = smooth_px + noisy_px
    stats = {"rays": dict(ctx.rays), "raycast_s": ctx.raycast_s, "pixels": int(P), "camera_samples": int(len(pix)), "edge_samples": int(n_edge),
             "box": [int(x0), int(y0), int(x1), int(y1)]}
    return Foreground(
        x0=x0, y0=y0,
        radiance_premult=rad_px.reshape(h, w, 3).astype(np.float32),
        alpha=np.clip(alpha_px, 0.0, 1.0).reshape(h, w).astype(np.float32),
        depth_m=depth_px.reshape(h, w).astype(np.float32),
        stats=stats,
    )


DENOISE_RADIUS_PX = 6
DENOISE_SIGMA_PX = 3.5
DENOISE_DEPTH_SCALE_PER_M = 0.15  # guide units per metre of depth (0.5 m ~ one normal sigma)


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
