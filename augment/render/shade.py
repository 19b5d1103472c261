"""Shading at points of the object's surface: sun + environment (MIS) with control variates, one bounce.

For shading points (object frame) with their :class:`~streetaug.augment.render.surface.SurfaceHits`::

    sun (disc-sampled, self-shadowing ray)
    + environment: MIS of env-map CDF and BRDF sampling (power heuristic), self-occlusion rays, with
      control variates: the unoccluded diffuse term and, for rough lobes, the specular albedo x cosine
      term are integrated exactly from the irradiance map, so only occlusion and the lobes' shape
      carry Monte Carlo noise.
    + metallic flakes (:func:`~streetaug.augment.render.brdf.flake_lobe`, paints that have them): part of the
      BRDF the environment's MIS samples see (its share of the diffuse lobe is left out of the control variate).
    + retro-reflection (:func:`~streetaug.augment.render.brdf.retro_lobe`, materials that have it): for
      the sun's samples, and in closed form for the environment seen from the viewer's direction.

Rays the object blocks see its own surface (the one-bounce model of :mod:`.bounce`); free rays
leaving it downwards see the environment's lower hemisphere (the ground radiance of the estimate)
times the shadow ratio where they land (:class:`streetaug.augment.render.shadow.GroundShadow`), so a
car's underside and tyres see its own shadow.  Shading happens in the object frame; environment
directions are rotated to the camera frame only to look the map up.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..core import camera_dir_to_lonlat, sample_equirect
from ..lighting.light import DistantLight
from .bounce import BounceLight
from .brdf import (BRDFParams, brdf_pdf, eval_brdf, mirror_albedo, reflect, retro_env_factor, retro_lobe,
                   sample_brdf, schlick_weight, specular_albedo)
from .environment import EnvironmentTables
from .sampling import lookup_irradiance, sample_cone
from .settings import RenderSettings
from .shadow import GroundShadow
from .surface import PreparedAsset

RAY_EPS_M = 1e-3  # ray origin offset along the geometric normal
FIS_LEVEL_BIAS = 1  # filtered importance sampling one level sharper than the sample footprint (less blur bias)
SHADE_CHUNK_RAYS = 100_000  # light-sample rays per batch: bounds memory (~45 MB a batch; 300k: ~130), keeps Embree batches large
SPEC_CV_ROUGHNESS = (0.5, 0.75)  # the specular control variate fades in between these roughnesses (measured)
MIRROR_CV_ROUGHNESS = (0.1, 0.15)  # specular lobes below this roughness (glass, chrome) are mirrors for their variate


def lookup_envmap(envmap: np.ndarray, dirs_cam: np.ndarray) -> np.ndarray:
    """Radiance (N, C) of a camera-frame equirect map (H, W, C) at unit camera-frame directions (N, 3)."""
    return sample_equirect(envmap, *camera_dir_to_lonlat(dirs_cam))


def filtered_env_radiance(pyramid: list[np.ndarray], dirs_cam: np.ndarray, sample_sr: np.ndarray) -> np.ndarray:
    """Filtered importance sampling (Krivanek & Colbert 2008): radiance (N, 3) from the pyramid level whose
    texel solid angle matches the solid angle ``sample_sr`` (N,) each sample stands for (1 / (n pdf))."""
    H0, W0 = pyramid[0].shape[:2]
    texel_sr = 4.0 * np.pi / (H0 * W0) * 1.3  # mean texel solid angle of level 0 (x1.3: the equator's)
    level = np.clip(np.floor(0.5 * np.log2(np.maximum(sample_sr, 1e-12) / texel_sr)) - FIS_LEVEL_BIAS, 0, len(pyramid) - 1).astype(np.int64)
    out = np.empty((len(dirs_cam), 3))
    for lev in np.unique(level):
        sel = np.flatnonzero(level == lev)
        out[sel] = lookup_envmap(pyramid[lev], dirs_cam[sel])
    return out


def mirror_cv_weight(roughness: np.ndarray) -> np.ndarray:
    """Weight (N,) in [0, 1] of the mirror control variate for the base specular lobe (1 mirror-like, 0 glossy)."""
    lo, hi = MIRROR_CV_ROUGHNESS
    return np.clip((hi - np.asarray(roughness)) / (hi - lo), 0.0, 1.0)


def spec_cv_weight(roughness: np.ndarray) -> np.ndarray:
    """Weight (N,) in [0, 1] of the cosine control variate for the specular lobe (0 glossy, 1 rough)."""
    lo, hi = SPEC_CV_ROUGHNESS
    return np.clip((np.asarray(roughness) - lo) / (hi - lo), 0.0, 1.0)


@dataclass
class ShadingContext:
    """Everything the shading of one object in one image reads, plus its ray counters (mutable).

    Attributes:
        prep: the prepared object; light: the camera-frame distant light; env: the tables of its env map.
        R_cam_from_obj: (3, 3) rotation object -> camera; sun_dir_obj: (3,) unit sun direction, object frame.
        settings: the render settings (the foreground lowers the light samples for its edge passes).
        rng: the render's random generator (draw order is part of the result).
        ambient_rgb: (3,) radiance along blocked rays when ``bounce`` is None (and under the surface).
        interior_rgb: (3,) irradiance-like factor of the car's interior (x base colour = radiance).
        bounce: radiance of the object's own surface along the rays it blocks, or None.
        foot_ratio: (3,) mean shadow ratio under the object (for ``bounce``).
        ground_shadow: the shadow ratio map as seen from the object, or None.
        rays: rays cast per stage (filled in place); raycast_s: seconds spent in ray casting.
        residual: False = the environment's Monte Carlo residual is not sampled (``noisy`` stays 0): the
            foreground's extra edge samples, whose pixels take the residual from the samples that have it.
    """

    prep: PreparedAsset
    light: DistantLight
    env: EnvironmentTables
    R_cam_from_obj: np.ndarray
    sun_dir_obj: np.ndarray | None
    settings: RenderSettings
    rng: np.random.Generator
    ambient_rgb: np.ndarray
    interior_rgb: np.ndarray
    bounce: BounceLight | None = None
    foot_ratio: np.ndarray = field(default_factory=lambda: np.full(3, 0.15))
    ground_shadow: GroundShadow | None = None
    rays: dict[str, int] = field(default_factory=dict)
    raycast_s: float = 0.0
    residual: bool = True

    @classmethod
    def for_object(cls, prep: PreparedAsset, light: DistantLight, env: EnvironmentTables, T_cam_from_object: np.ndarray,
                   settings: RenderSettings, rng: np.random.Generator, ambient_rgb: np.ndarray,
                   interior_rgb: np.ndarray, bounce: BounceLight | None = None, foot_ratio: np.ndarray | None = None,
                   ground_shadow: GroundShadow | None = None) -> "ShadingContext":
        """The context of ``prep`` at ``T_cam_from_object`` (4, 4); ``foot_ratio`` None = 0.15."""
        R = np.asarray(T_cam_from_object, dtype=np.float64)[:3, :3]
        sun_obj = None if light.sun is None else R.T @ np.asarray(light.sun.direction, dtype=np.float64)
        return cls(prep, light, env, R, sun_obj, settings, rng, np.asarray(ambient_rgb, dtype=np.float64),
                   np.asarray(interior_rgb, dtype=np.float64), bounce,
                   np.full(3, 0.15) if foot_ratio is None else np.asarray(foot_ratio, dtype=np.float64), ground_shadow)

    def count(self, stage: str, n: int, seconds: float) -> None:
        """Add ``n`` rays cast by ``stage`` and the seconds they took."""
        self.rays[stage] = self.rays.get(stage, 0) + n
        self.raycast_s += seconds


@dataclass(frozen=True)
class LightSamples:
    """Shadow-ray samples of one light term (sun, env or BRDF) for a batch of shading points.

    Attributes:
        kind: "sun", "env" or "brdf".
        point: (S,) int64 index of the shading point each sample belongs to.
        origins, dirs: (S, 3) float64 ray origins (offset along the geometric normal) and unit directions, object frame.
        contrib: (S, 3) float64 contribution if the ray is free (env terms: control variate subtracted).
        weight: (S, 3) BRDF x cos x MIS weight / pdf (env terms only, else None).
        cv: (S, 3) the control variate of the sample (env terms only).
        weighted_env: (S, 3) ``weight x L_env`` (env terms only; the ground-shadow correction scales it).
    """

    kind: str
    point: np.ndarray
    origins: np.ndarray
    dirs: np.ndarray
    contrib: np.ndarray
    weight: np.ndarray | None = None
    cv: np.ndarray | None = None
    weighted_env: np.ndarray | None = None


def shade(ctx: ShadingContext, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
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


def _shade_batch(ctx: ShadingContext, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
                 params: BRDFParams, cv_scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One chunk of :func:`shade`: (smooth, noisy) radiance parts, each (N, 3)."""
    N = len(p)
    params = params.precompute(lobes=ctx.residual)  # no environment / BRDF samples: no lobe probabilities
    smooth = np.zeros((N, 3))
    noisy = np.zeros((N, 3))
    samples = []
    if ctx.sun_dir_obj is not None and ctx.settings.sun_samples:
        if np.any(np.asarray(ctx.light.sun.irradiance_rgb) > 0):
            samples.append(_sun_samples(ctx, p, n_s, n_g, v, params))
        else:  # a sun of no irradiance (hidden): no light, only its random numbers drawn (same stream after it)
            ctx.rng.random(len(p) * ctx.settings.sun_samples)
            ctx.rng.random(len(p) * ctx.settings.sun_samples)
    # Environment: MIS of env-map importance and BRDF sampling, with the unoccluded diffuse term as a
    # control variate: per sample we subtract g = c_d/pi L cos (MIS-weighted) and add its exact
    # expectation c_d/pi E(n) from the irradiance map, so unblocked diffuse light is noise-free.
    n_v = np.clip(np.einsum("ij,ij->i", n_s, v), 0, 1)
    coat_keep = 1.0 - params.clearcoat * (0.04 + 0.96 * schlick_weight(n_v))
    # Rough specular lobes are nearly cosine-shaped: their directional albedo x cos / pi is a good
    # control variate too (its exact expectation is again the irradiance); glossy lobes get none.
    spec_alb = specular_albedo(n_v, params)
    spec_cv = spec_alb * spec_cv_weight(params.roughness)[:, None]
    g_color = (params.c_lambert + spec_cv) / np.pi * coat_keep[:, None]  # (N, 3); flakes: sampled, no variate
    if cv_scale is not None:
        g_color = g_color * cv_scale[:, None]
    smooth += g_color * lookup_irradiance(ctx.env.irradiance, n_s @ ctx.R_cam_from_obj.T)
    if params.has_retro:  # the environment behind the viewer, returned by the retro lobe (closed form)
        smooth += retro_env_factor(n_s, v, params) * lookup_envmap(ctx.env.pyramid[0], v @ ctx.R_cam_from_obj.T)
    # Near-mirror lobes (clear coat, glass, chrome) reflect about one texel of the map: a control variate
    # of their unoccluded light whose expectation is the full-resolution map at the mirror direction, so
    # their reflections are as sharp as the map and noise-free (not left to the denoiser) where unblocked.
    mirror = None
    w_m = mirror_cv_weight(params.roughness)
    if np.any(params.clearcoat > 0) or np.any(w_m > 0):
        scale_m = np.ones(N) if cv_scale is None else cv_scale
        mirror = (w_m, scale_m)
        r_cam = reflect(v, n_s) @ ctx.R_cam_from_obj.T
        smooth += mirror_albedo(n_v, params, w_m, spec_alb) * scale_m[:, None] * lookup_envmap(ctx.env.pyramid[0], r_cam)
    for kind in ("env", "brdf") if ctx.residual else ():
        if (ctx.settings.env_samples if kind == "env" else ctx.settings.brdf_samples) > 0:
            samples.append(_env_samples(ctx, kind, p, n_s, n_g, v, params, g_color, noisy, mirror))
    if samples:
        _trace_light_samples(ctx, samples, smooth, noisy)
    return smooth, noisy


def _sun_samples(ctx: ShadingContext, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
                 params: BRDFParams) -> LightSamples:
    """Sun-disc directions (explicit light sampling), ``settings.sun_samples`` per point."""
    ns_sun = ctx.settings.sun_samples
    sun = ctx.light.sun
    idx_sun = np.repeat(np.arange(len(p)), ns_sun)
    rows = _rows(idx_sun, len(p))
    l_sun = sample_cone(ctx.sun_dir_obj, sun.half_angle_rad, ctx.rng.random(len(idx_sun)), ctx.rng.random(len(idx_sun)))
    p_sun = params if ns_sun == 1 else params.take(idx_sun)
    nn = rows(n_s)
    f = eval_brdf(nn, rows(v), l_sun, p_sun)
    if p_sun.has_retro:
        f = f + retro_lobe(nn, rows(v), l_sun, p_sun)
    cos = np.clip(np.einsum("ij,ij->i", nn, l_sun), 0.0, 1.0)
    up = np.einsum("ij,ij->i", rows(n_g), l_sun) > 0
    contrib_sun = f * (cos * up / ns_sun)[:, None] * np.asarray(sun.irradiance_rgb)[None]
    live = np.flatnonzero(up & (contrib_sun.max(axis=1) > 0))
    return LightSamples("sun", idx_sun[live], p[idx_sun[live]] + RAY_EPS_M * n_g[idx_sun[live]], l_sun[live],
                        contrib_sun[live])


def _rows(index: np.ndarray, n: int):
    """``a -> a[index]`` for a sorted ``index`` (m,) into n rows; the identity when it takes every row once (no copy)."""
    if len(index) == n:
        return lambda a: a
    return lambda a: a[index]


def _env_samples(ctx: ShadingContext, kind: str, p: np.ndarray, n_s: np.ndarray, n_g: np.ndarray, v: np.ndarray,
                 params: BRDFParams, g_color: np.ndarray, noisy: np.ndarray,
                 mirror: tuple[np.ndarray, np.ndarray] | None = None) -> LightSamples:
    """Environment samples drawn from the map (``kind`` "env") or the BRDF ("brdf"), MIS-weighted.

    Samples under the geometric surface count as blocked by the surface itself (added to ``noisy``
    in place, no ray traced); the others are returned for the visibility test.  ``mirror`` = (spec weight,
    scale), each (N,): the near-mirror lobes' control variate (:func:`~.brdf.mirror_lobes`), or None.
    """
    s, R, rng = ctx.settings, ctx.R_cam_from_obj, ctx.rng
    n_e, n_b = s.env_samples, s.brdf_samples
    N = len(p)
    idx = np.repeat(np.arange(N), n_e if kind == "env" else n_b)
    rows = _rows(idx, N)
    pr = params if len(idx) == N else params.take(idx)
    nn, vv, ng = rows(n_s), rows(v), rows(n_g)
    if kind == "env":
        l_cam, p_env = ctx.env.sampler.sample(rng.random((len(idx), 3)))
        l = l_cam @ R  # camera -> object frame (R^T l)
        p_brdf = brdf_pdf(nn, vv, l, pr)
        w = (n_e * p_env) ** 2 / np.maximum((n_e * p_env) ** 2 + (n_b * p_brdf) ** 2, 1e-300) / (n_e * p_env)
    else:
        l = sample_brdf(nn, vv, pr, rng.random((len(idx), 3)))
        l_cam = l @ R.T
        p_brdf = brdf_pdf(nn, vv, l, pr)
        p_env = ctx.env.sampler.pdf(l_cam) if n_e else np.zeros(len(idx))
        w = (n_b * p_brdf) ** 2 / np.maximum((n_e * p_env) ** 2 + (n_b * p_brdf) ** 2, 1e-300) / np.maximum(n_b * p_brdf, 1e-300)
    cos = np.clip(np.einsum("ij,ij->i", nn, l), 0.0, 1.0)
    up = np.einsum("ij,ij->i", ng, l) > 0
    cw = cos * w  # cos / (n p) x MIS weight
    live = np.flatnonzero(cw > 0)
    il = idx[live]
    at_live = _rows(live, len(idx))
    pr_live = pr if len(live) == len(idx) else pr.take(live)
    if mirror is None:
        weight = eval_brdf(at_live(nn), at_live(vv), at_live(l), pr_live) * cw[live, None]
    else:
        w_m, scale_m = mirror
        f, f_m = eval_brdf(at_live(nn), at_live(vv), at_live(l), pr_live, w_m[il])
        weight = f * cw[live, None]
    if kind == "brdf":  # filtered importance sampling: a sample of a wide lobe sees a blurred sky
        L = filtered_env_radiance(ctx.env.pyramid, l_cam[live], 1.0 / np.maximum(n_b * p_brdf[live], 1e-12))
    else:
        L = lookup_envmap(ctx.env.sampler_map, l_cam[live])  # the map the samples were drawn from
    cv = g_color[il] * cw[live, None] * L  # the control variate, MIS-weighted
    if mirror is not None:
        cv = cv + f_m * (scale_m[il] * cw[live])[:, None] * L
    contrib = weight * L - cv
    down = np.flatnonzero(~up[live])
    if len(down):
        blocked_c = weight[down] * ctx.ambient_rgb[None] - cv[down]
        for k in range(3):
            noisy[:, k] += np.bincount(il[down], weights=blocked_c[:, k], minlength=N)
    keep = np.flatnonzero(up[live])
    return LightSamples(kind, il[keep], p[il[keep]] + RAY_EPS_M * ng[live[keep]], l[live[keep]], contrib[keep],
                        weight[keep], cv[keep], weight[keep] * L[keep])


def _trace_light_samples(ctx: ShadingContext, samples: list[LightSamples], smooth: np.ndarray, noisy: np.ndarray) -> None:
    """Trace every sample's shadow ray (one batch) and add the free and blocked contributions in place."""
    N = len(smooth)
    origins = np.concatenate([s.origins for s in samples])
    dirs = np.concatenate([s.dirs for s in samples])
    t0 = time.perf_counter()
    blocked = ctx.prep.scene.occluded(origins, dirs) if len(origins) else np.zeros(0, bool)
    ctx.count("shade_visibility", len(origins), time.perf_counter() - t0)
    start = 0
    for s in samples:
        b = blocked[start:start + len(s.point)]
        start += len(s.point)
        if s.weight is None:  # sun: blocked means no light
            c = np.where(b[:, None], 0.0, s.contrib)
            target = smooth
        else:  # environment: blocked rays see the object's own surface (one approximate bounce)
            c = s.contrib.copy()
            bi = np.flatnonzero(b)
            if len(bi):
                c[bi] = s.weight[bi] * blocked_radiance(ctx, s.origins[bi], s.dirs[bi]) - s.cv[bi]
            if ctx.ground_shadow is not None:  # free rays going down land on the (possibly shadowed) ground
                fi = np.flatnonzero(~b & (s.dirs @ ctx.ground_shadow.up_obj < 0))
                if len(fi):
                    c[fi] += s.weighted_env[fi] * (ctx.ground_shadow.ratio_along(s.origins[fi], s.dirs[fi]) - 1.0)
            target = noisy
        for k in range(3):
            target[:, k] += np.bincount(s.point, weights=c[:, k], minlength=N)


def blocked_radiance(ctx: ShadingContext, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) arriving along rays (object frame) the object blocks: its surface there (see :mod:`.bounce`)."""
    if ctx.bounce is None:
        return np.broadcast_to(ctx.ambient_rgb, (len(origins), 3))
    t0 = time.perf_counter()
    hits = ctx.prep.scene.intersect(origins, dirs)
    ctx.count("shade_bounce", len(origins), time.perf_counter() - t0)
    out = np.broadcast_to(ctx.ambient_rgb, (len(origins), 3)).copy()
    h = np.flatnonzero(hits.hit)
    if len(h):
        A, B = ctx.bounce.radiance(hits.face[h], dirs[h])
        out[h] = A + B * ctx.foot_ratio[None]
    return out
