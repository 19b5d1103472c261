"""Renderer of the generated street scenes: Embree ray casting, Lambertian shading under sun + sky.

Per pixel: ``spp`` jittered primary rays (anti-aliasing); at each hit the procedural albedo, the sun
(``sun_rays`` shadow rays per sample over the sun's disc, a per-pixel rotated golden-angle spiral:
smooth penumbrae), the sky (cosine-weighted hemisphere rays occluded by the scene; a ray that hits the
scene brings back one diffuse bounce lit by the sun with its own shadow ray plus 0.7 x the unoccluded
sky) and, for glass, a traced mirror reflection (Schlick Fresnel, boosted so dark panes read as glass).
The noisy sky irradiance is demodulated from the albedo and smoothed with an edge-aware a-trous
filter (normal and depth stopping), so textures stay sharp.  Rays that miss show the sky model.

Frames: the scene, the sky and the sun live in the global frame (z up); the camera is given by
``K`` and ``T_global_from_cam`` (OpenCV camera frame).  Radiance is in the sky model's physical
units (see :mod:`streetaug.augment.lighting.sky`); exposure is applied by the caller.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from streetaug.augment.core import (
    PinholeCamera,
    check_shape,
    equirect_pixel_lonlat,
    equirect_solid_angles,
    invert_transform,
    lonlat_to_world_dir,
    sample_equirect,
    transform_points,
    world_dir_to_lonlat,
)
from streetaug.augment.lighting.sky import sky_radiance, sun_irradiance, sun_visibility
from streetaug.augment.core.raycast import RayScene

from .patterns import surface_albedo
from .street import StreetScene

RAY_EPS_M = 2e-3
CHUNK_SAMPLES = 600_000


@dataclass(frozen=True)
class SkyParams:
    """Daylight of a scene (global frame).

    Attributes:
        sun_dir_global: (3,) unit vector towards the sun (x east, y north, z up).
        turbidity: Preetham turbidity.
        cloud_cover: 0 (clear) .. 1 (overcast).
        ground_albedo: albedo of the sky model's ground below the horizon.
        sun_half_angle_rad: angular radius of the sun disc used for shadows (softness).
    """

    sun_dir_global: np.ndarray
    turbidity: float = 3.0
    cloud_cover: float = 0.0
    ground_albedo: float = 0.15
    sun_half_angle_rad: float = float(np.radians(0.2665))

    def radiance(self, dirs_global: np.ndarray) -> np.ndarray:
        """Sky radiance (N, 3) from unit global directions (N, 3), sun disc excluded."""
        return sky_radiance(dirs_global, self.sun_dir_global, self.turbidity, self.cloud_cover, self.ground_albedo)

    @property
    def sun_irradiance_rgb(self) -> np.ndarray:
        """(3,) irradiance of the sun (visibility applied) on a surface facing it."""
        return sun_irradiance(self.sun_dir_global, self.turbidity, self.cloud_cover)

    @property
    def sun_visibility(self) -> float:
        return sun_visibility(self.cloud_cover)

    def envmap_world(self, height: int, width: int) -> np.ndarray:
        """Sky radiance (height, width, 3) float32 in the world (z-up) equirect convention, no sun disc."""
        lon, lat = equirect_pixel_lonlat(height, width)
        d = lonlat_to_world_dir(lon, lat).reshape(-1, 3)
        return self.radiance(d).reshape(height, width, 3).astype(np.float32)


@dataclass(frozen=True)
class RenderResult:
    """A rendered camera image.

    Attributes:
        radiance: (H, W, 3) float32 linear radiance (sky model units, before exposure).
        depth_m: (H, W) float32 camera-frame z of the centre ray's hit, inf for sky.
        label: (H, W) uint8 lidarseg label of the centre ray's hit, 0 for sky.
        shadow: (H, W) float32 fraction of the sun reaching the surface (1 = lit), nan for sky.
    """

    radiance: np.ndarray
    depth_m: np.ndarray
    label: np.ndarray
    shadow: np.ndarray


def _orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (N, 3) completing unit normals n (N, 3) to right-handed frames."""
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def _cosine_directions(n: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions (N, 3) around unit normals n (N, 3); pdf = cos / pi."""
    t, b = _orthonormal_basis(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    z = np.sqrt(np.clip(1 - u1, 0, 1))
    return t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None] + n * z[:, None]


def _cone_directions(axis: np.ndarray, half_angle: float, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions (N, 3) uniform inside the cone of ``half_angle`` around the unit axis (3,)."""
    a = np.tile(axis, (len(u1), 1))
    t, b = _orthonormal_basis(a)
    z = 1 - u1 * (1 - np.cos(half_angle))
    r = np.sqrt(np.clip(1 - z * z, 0, 1))
    phi = 2 * np.pi * u2
    return t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None] + a * z[:, None]


def _spiral(sample: int, n_rays: int, n_total: int, rotation: np.ndarray, jitter: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(u1, u2) pairs of rays ``sample * n_rays ... + n_rays - 1`` of an ``n_total``-point golden-angle spiral,
    rotated per pixel by ``rotation`` (N,) and shifted within its radial stratum by ``jitter`` (N,)."""
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    out = []
    for j in range(n_rays):
        m = sample * n_rays + j
        out.append(((m + jitter) / n_total, np.mod(m * golden + rotation, 1.0)))
    return out


class StreetRenderer:
    """Renders camera images and answers shading queries for one :class:`StreetScene` under one sky."""

    def __init__(self, scene: StreetScene, sky: SkyParams) -> None:
        self.scene = scene
        self.sky = sky
        self.rays = RayScene(scene.vertices_global, scene.faces)
        self.normals = scene.face_normals_global
        self.T_street_from_global = invert_transform(scene.T_global_from_street)
        self.base_albedo = np.array([m.albedo for m in scene.materials])[scene.face_material]
        self.sun_dir = np.asarray(sky.sun_dir_global, dtype=np.float64)
        self.sun_dir = self.sun_dir / np.linalg.norm(self.sun_dir)
        self.sun_e = sky.sun_irradiance_rgb if self.sun_dir[2] > 0 else np.zeros(3)
        self._sky_irradiance_map = self._sky_irradiance_by_normal(16, 32)

    def with_scene(self, scene: StreetScene) -> "StreetRenderer":
        """A renderer of ``scene`` under the same sky (sky tables shared, not recomputed).

        For the same street at another time (objects moved, same faces and materials): a new ray scene,
        new face normals; everything else is the sky's.
        """
        other = copy.copy(self)
        other.scene = scene
        other.rays = RayScene(scene.vertices_global, scene.faces)
        other.normals = scene.face_normals_global
        other.T_street_from_global = invert_transform(scene.T_global_from_street)
        other.base_albedo = np.array([m.albedo for m in scene.materials])[scene.face_material]
        return other

    # ------------------------------------------------------------------ sky helpers

    def _sky_irradiance_by_normal(self, height: int, width: int) -> np.ndarray:
        """Unoccluded irradiance (height, width, 3) from the sky's upper hemisphere, indexed by the normal
        in the world equirect convention."""
        env = self.sky.envmap_world(64, 128).reshape(-1, 3).astype(np.float64)
        lon, lat = equirect_pixel_lonlat(64, 128)
        d = lonlat_to_world_dir(lon, lat).reshape(-1, 3)
        omega = equirect_solid_angles(64, 128).reshape(-1) * (d[:, 2] > 0)
        nl, nt = equirect_pixel_lonlat(height, width)
        normals = lonlat_to_world_dir(nl, nt).reshape(-1, 3)
        cos = np.clip(normals @ d.T, 0, None) * omega[None]
        return (cos @ env).reshape(height, width, 3)

    def sky_irradiance_unoccluded(self, normals: np.ndarray) -> np.ndarray:
        """(N, 3) irradiance from the unoccluded sky on surfaces with unit global normals (N, 3)."""
        lon, lat = world_dir_to_lonlat(normals)
        return sample_equirect(self._sky_irradiance_map, lon, lat)

    def sun_disc_radiance(self) -> np.ndarray:
        """(3,) radiance of the sun disc (shown where camera rays see it)."""
        omega = 2 * np.pi * (1 - np.cos(max(self.sky.sun_half_angle_rad, np.radians(0.2665))))
        return self.sun_e / omega

    # ------------------------------------------------------------------ shading

    def oriented_normals(self, face: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Unit normals (N, 3) of faces (N,) turned to face the rays (N, 3) that hit them."""
        n = self.normals[face]
        flip = np.einsum("ij,ij->i", n, dirs) > 0
        return np.where(flip[:, None], -n, n)

    def sun_visibility_at(self, points: np.ndarray, normals: np.ndarray, rng: np.random.Generator,
                        disc_samples: list[tuple[np.ndarray, np.ndarray]] | None = None) -> np.ndarray:
        """(N,) fraction of visible points of the sun disc, times the cosine term (0 when facing away).

        ``disc_samples``: one (u1, u2) pair of (N,) arrays in [0, 1) per shadow ray (default: one random ray).
        """
        cos = normals @ self.sun_dir
        out = np.zeros(len(points))
        if not np.any(self.sun_e > 0):
            return out
        if disc_samples is None:
            disc_samples = [(rng.uniform(size=len(points)), rng.uniform(size=len(points)))]
        sel = np.nonzero(cos > 0)[0]
        for u1, u2 in disc_samples if len(sel) else []:
            d = _cone_directions(self.sun_dir, self.sky.sun_half_angle_rad, u1[sel], u2[sel])
            occ = self.rays.occluded(points[sel] + normals[sel] * RAY_EPS_M, d)
            out[sel] += (~occ) * cos[sel] / len(disc_samples)
        return out

    def bounce_radiance(self, points: np.ndarray, normals: np.ndarray, face: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Outgoing diffuse radiance (N, 3) of secondary hits: base albedo x (sun with shadow + 0.7 x open sky)."""
        e = self.sun_e[None] * self.sun_visibility_at(points, normals, rng)[:, None]
        e = e + 0.7 * self.sky_irradiance_unoccluded(normals)
        return self.base_albedo[face] / np.pi * e

    def sky_gather(self, points: np.ndarray, normals: np.ndarray, samples: list[tuple[np.ndarray, np.ndarray]],
                    rng: np.random.Generator) -> np.ndarray:
        """Monte Carlo irradiance (N, 3) from the sky and one bounce; one cosine-weighted ray per (u1, u2) pair
        of (N,) arrays in ``samples``."""
        total = np.zeros((len(points), 3))
        n_rays = len(samples)
        for u1, u2 in samples:
            d = _cosine_directions(normals, u1, u2)
            hits = self.rays.intersect(points + normals * RAY_EPS_M, d)
            L = np.zeros((len(points), 3))
            miss = ~hits.hit
            if miss.any():
                L[miss] = self.sky.radiance(d[miss])
            if hits.hit.any():
                h = np.nonzero(hits.hit)[0]
                q = self.rays.hit_points(hits)[h]
                nq = self.oriented_normals(hits.face[h], d[h])
                L[h] = self.bounce_radiance(q, nq, hits.face[h], rng)
            total += L * np.pi  # cosine pdf: E = pi * mean(L)
        return total / n_rays

    def _glass_reflection(self, points, normals, dirs, rng) -> np.ndarray:
        """Radiance (N, 3) seen in the mirror direction, with a Schlick Fresnel factor (F0 = 0.04)."""
        r = dirs - 2 * np.einsum("ij,ij->i", dirs, normals)[:, None] * normals
        cos_i = np.clip(-np.einsum("ij,ij->i", dirs, normals), 0, 1)
        fresnel = 0.04 + 0.96 * (1 - cos_i) ** 5
        hits = self.rays.intersect(points + normals * RAY_EPS_M, r)
        L = np.zeros((len(points), 3))
        miss = ~hits.hit
        if miss.any():
            L[miss] = self.sky.radiance(r[miss])
        if hits.hit.any():
            h = np.nonzero(hits.hit)[0]
            q = self.rays.hit_points(hits)[h]
            L[h] = self.bounce_radiance(q, self.oriented_normals(hits.face[h], r[h]), hits.face[h], rng)
        return L * np.clip(fresnel * 4.0, 0, 1)[:, None]

    # ------------------------------------------------------------------ camera

    def render(
        self,
        K: np.ndarray,
        T_global_from_cam: np.ndarray,
        width: int,
        height: int,
        spp: int = 4,
        sky_rays: int = 2,
        sun_rays: int = 4,
        seed: int = 0,
        denoise: bool = True,
    ) -> RenderResult:
        """Render one pinhole camera (K (3, 3), OpenCV frame posed by ``T_global_from_cam`` (4, 4)).

        ``spp`` jittered primary samples per pixel (stratified when a square), ``sky_rays`` sky samples
        per primary sample, ``sun_rays`` shadow rays towards the sun disc per primary sample.
        """
        check_shape(K, (3, 3), "K")
        check_shape(T_global_from_cam, (4, 4), "T_global_from_cam")
        if spp < 1 or sky_rays < 1:
            raise ValueError(f"spp and sky_rays must be >= 1, got {spp}, {sky_rays}")
        camera = PinholeCamera(K, width, height)
        n_pix = width * height
        jitter = _primary_jitter(np.random.default_rng(seed), spp, n_pix)
        pixels_uv = camera.pixel_grid().reshape(-1, 2)
        acc = _PixelSums.zeros(n_pix)
        chunk = max(1, CHUNK_SAMPLES // spp)
        for start in range(0, n_pix, chunk):
            px = np.arange(start, min(start + chunk, n_pix))
            crng = np.random.default_rng([seed, start])
            # per-pixel rotations of low-discrepancy (golden-angle spiral) patterns for the sun disc and the sky
            rot_sun, rot_sky = crng.uniform(size=len(px)), crng.uniform(size=len(px))
            jit_sun, jit_sky = crng.uniform(size=len(px)), crng.uniform(size=len(px))
            for s in range(spp):
                uv = pixels_uv[px] + jitter[s, px]
                sun_samples = _spiral(s, sun_rays, spp * sun_rays, rot_sun, jit_sun)
                sky_samples = _spiral(s, sky_rays, spp * sky_rays, rot_sky, jit_sky)
                self._render_sample(camera, T_global_from_cam, px, uv, s == 0, sun_samples, sky_samples, crng, acc)
        return self._resolve(acc, spp, width, height, denoise)

    def _render_sample(self, camera: PinholeCamera, T_global_from_cam: np.ndarray, px: np.ndarray, uv: np.ndarray,
                       first: bool, sun_samples: list[tuple[np.ndarray, np.ndarray]],
                       sky_samples: list[tuple[np.ndarray, np.ndarray]], rng: np.random.Generator,
                       acc: "_PixelSums") -> None:
        """Trace one primary sample through pixels ``px`` (at ``uv`` (P, 2)) and add its light to ``acc``.

        ``sun_samples`` / ``sky_samples``: the (u1, u2) pairs of (P,) arrays of this sample for all the
        pixels; the first sample (``first``) also sets depth, label and shadow.
        """
        d_cam = camera.rays(uv)
        d = d_cam @ T_global_from_cam[:3, :3].T
        hits = self.rays.intersect(np.tile(T_global_from_cam[:3, 3], (len(px), 1)), d)
        miss = ~hits.hit
        if miss.any():
            sky = self.sky.radiance(d[miss])
            if np.any(self.sun_e > 0):
                cos_disc = np.cos(max(self.sky.sun_half_angle_rad, np.radians(0.2665)))
                sky = sky + (d[miss] @ self.sun_dir >= cos_disc)[:, None] * self.sun_disc_radiance()[None]
            acc.emitted[px[miss]] += sky
        h = np.nonzero(hits.hit)[0]
        if len(h) == 0:
            return
        ph = px[h]
        face = hits.face[h]
        p = self.rays.hit_points(hits)[h]
        n = self.oriented_normals(face, d[h])
        p_street = transform_points(self.T_street_from_global, p)
        n_street = n @ self.T_street_from_global[:3, :3].T
        albedo, gloss = surface_albedo(self.scene.materials, self.scene.face_material[face], p_street, n_street)
        vis = self.sun_visibility_at(p, n, rng, [(u1[h], u2[h]) for u1, u2 in sun_samples])
        acc.direct[ph] += albedo / np.pi * self.sun_e[None] * vis[:, None]
        acc.albedo_sum[ph] += albedo
        acc.e_sky_sum[ph] += self.sky_gather(p, n, [(u1[h], u2[h]) for u1, u2 in sky_samples], rng)
        acc.hit_count[ph] += 1
        acc.normal_sum[ph] += n
        g_sel = gloss > 0
        if g_sel.any():
            gi = np.nonzero(g_sel)[0]
            acc.emitted[ph[gi]] += gloss[gi, None] * self._glass_reflection(p[gi], n[gi], d[h][gi], rng)
        if first:
            acc.depth[ph] = (hits.t[h] * d_cam[h, 2])
            acc.label[ph] = self.scene.face_label[face]
            cos = n @ self.sun_dir
            acc.shadow[ph] = np.where(cos > 0, vis / np.maximum(cos, 1e-9), 0.0)

    @staticmethod
    def _resolve(acc: "_PixelSums", spp: int, width: int, height: int, denoise: bool) -> RenderResult:
        """The image from the per-pixel sums: sky irradiance (denoised) x albedo + sun + emitted, over ``spp``."""
        hit_any = acc.hit_count > 0
        e_sky = np.where(hit_any[:, None], acc.e_sky_sum / np.maximum(acc.hit_count, 1)[:, None], 0.0)
        if denoise:
            normals_px = acc.normal_sum / np.maximum(np.linalg.norm(acc.normal_sum, axis=1, keepdims=True), 1e-9)
            depth_px = np.where(hit_any, acc.depth, np.nan)
            # pixels whose centre sample missed: use a far depth so they do not blend with neighbours
            depth_px = np.where(np.isfinite(depth_px), depth_px, 1e6)
            e_sky = atrous_denoise(
                e_sky.reshape(height, width, 3), normals_px.reshape(height, width, 3),
                depth_px.reshape(height, width), hit_any.reshape(height, width),
            ).reshape(-1, 3)
        radiance = (acc.direct + acc.albedo_sum / np.pi * e_sky + acc.emitted) / spp
        return RenderResult(
            radiance=radiance.reshape(height, width, 3).astype(np.float32),
            depth_m=acc.depth.reshape(height, width).astype(np.float32),
            label=acc.label.reshape(height, width),
            shadow=acc.shadow.reshape(height, width).astype(np.float32),
        )


def _primary_jitter(rng: np.random.Generator, spp: int, n_pix: int) -> np.ndarray:
    """(spp, n_pix, 2) float32 sub-pixel offsets in [-0.5, 0.5) (stratified when ``spp`` is a square)."""
    g = int(round(np.sqrt(spp)))
    jitter = rng.uniform(size=(spp, n_pix, 2)).astype(np.float32)
    if g * g == spp:
        cells = np.array([[(k % g), (k // g)] for k in range(spp)], dtype=np.float32)
        jitter = (cells[:, None, :] + jitter) / g
    jitter -= 0.5
    return jitter


@dataclass(frozen=True)
class _PixelSums:
    """Per-pixel sums over a render's primary samples (arrays of n_pix rows, filled in place).

    Attributes:
        direct: (P, 3) albedo / pi x sun irradiance; ``albedo_sum`` (P, 3); ``e_sky_sum`` (P, 3) sky irradiance;
        hit_count: (P,) samples that hit the scene; ``emitted`` (P, 3) sky, sun disc, glass reflections;
        normal_sum: (P, 3); ``depth`` (P,) camera z of the first sample; ``label`` (P,) uint8; ``shadow`` (P,).
    """

    direct: np.ndarray
    albedo_sum: np.ndarray
    e_sky_sum: np.ndarray
    hit_count: np.ndarray
    emitted: np.ndarray
    normal_sum: np.ndarray
    depth: np.ndarray
    label: np.ndarray
    shadow: np.ndarray

    @classmethod
    def zeros(cls, n_pix: int) -> "_PixelSums":
        return cls(np.zeros((n_pix, 3)), np.zeros((n_pix, 3)), np.zeros((n_pix, 3)), np.zeros(n_pix),
                   np.zeros((n_pix, 3)), np.zeros((n_pix, 3)), np.full(n_pix, np.inf), np.zeros(n_pix, dtype=np.uint8),
                   np.full(n_pix, np.nan))


def atrous_denoise(
    value: np.ndarray, normals: np.ndarray, depth_m: np.ndarray, valid: np.ndarray,
    iterations: int = 4, sigma_normal_pow: float = 64.0, sigma_depth_rel: float = 0.04,
) -> np.ndarray:
    """Edge-aware a-trous (B3-spline, 5x5) smoothing of an (H, W, 3) image.

    Weights stop at normal changes (``(n_p . n_q) ** sigma_normal_pow``), at depth changes larger than
    ``sigma_depth_rel`` x depth x step, and at invalid pixels.  Returns (H, W, 3) float64.
    """
    H, W = depth_m.shape
    kernel = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
    out = np.where(valid[..., None], value, 0.0).astype(np.float64)
    for it in range(iterations):
        step = 2**it
        pad = 2 * step
        v_pad = np.pad(out, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
        n_pad = np.pad(normals, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
        d_pad = np.pad(depth_m, pad, mode="edge")
        m_pad = np.pad(valid, pad, mode="constant")
        acc = np.zeros_like(out)
        wsum = np.zeros((H, W))
        for a in range(5):
            for b in range(5):
                dy, dx = (a - 2) * step, (b - 2) * step
                sl = (slice(pad + dy, pad + dy + H), slice(pad + dx, pad + dx + W))
                wn = np.clip(np.einsum("ijk,ijk->ij", normals, n_pad[sl]), 0, 1) ** sigma_normal_pow
                wd = np.exp(-np.abs(d_pad[sl] - depth_m) / (sigma_depth_rel * depth_m * step + 0.05))
                w = kernel[a] * kernel[b] * wn * wd * m_pad[sl]
                acc += w[..., None] * v_pad[sl]
                wsum += w
        out = np.where(valid[..., None], acc / np.maximum(wsum, 1e-12)[..., None], 0.0)
    return out
