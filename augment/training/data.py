"""Training and evaluation data of the learned sky (:mod:`streetaug.augment.lighting.skynet`), made by the project: synthetic skies, real panoramas, camera views.

* Sky model: domes of synthetic skies (:mod:`.synth`, cached as one ``.npz`` under the cache folder)
  and of the real training panoramas (``shared/data/hdri``), with azimuth rotation, mirror flips,
  exposure and white-balance augmentation.
* Image predictor: low-res camera views with their sky domes, from three sources: street scenes of
  :mod:`streetaug.augment.scenegen` rendered under random synthetic skies (cached), perspective crops of
  the real training panoramas, and crops of synthetic skies over a flat ground (both made on the fly).

All views are on the radiometric scale of their LDR image (``LDR = hdr_to_ldr(HDR)``), auto-exposed
like a camera; their domes (the target sky, heading frame) are on the same scale.  The real panoramas
are split: :data:`TRAIN_PANORAMAS` for training, :data:`VAL_PANORAMAS` never seen in training.
Nothing here writes into the repository; caches go to :func:`default_cache_dir`.
"""

from __future__ import annotations

import hashlib
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..core import InputError, PinholeCamera, atomic_path, hdr_to_ldr, intrinsics_from_fov, luminance, make_transform
from ..lighting.skynet.dome import (
    camera_from_angles,
    dome_directions,
    find_peak,
    heading_from_camera,
    load_hdri,
    panorama_to_dome,
    render_perspective,
)
from ..lighting.skynet.inputs import VIEW_SIZE, quantize_ldr, resize_view, view_rays
from ..lighting.skynet.model import PEAK_DISC_THRESHOLD
from ..scenegen.make import choose_exposure
from ..scenegen.render import StreetRenderer
from ..scenegen.street import StreetParams, build_street
from .synth import random_sky

TRAIN_PANORAMAS = ("city", "dawn", "forest", "night")
VAL_PANORAMAS = ("sky", "sunrise", "venice")
# Fraction of the clear-sky sun reaching the ground, by eye from the panoramas (index.json "sun").
PANORAMA_SUN_VISIBILITY = {"city": 0.0, "dawn": 0.0, "forest": 0.5, "night": 0.0, "sky": 1.0, "sunrise": 1.0,
                           "venice": 0.0}
# name -> (sun direction source in index.json or None, visibility by eye): "gt_peak" is the luminance-weighted
# peak region; industrial_sunset's gt_peak is the glow 17 deg above the sun, so its brightest pixel is used.
PANORAMA_SUN = {
    "city": (None, 0.0), "dawn": (None, 0.0), "night": (None, 0.0), "venice": (None, 0.0),
    "forest": ("gt_peak", 0.5), "sky": ("gt_peak", 1.0), "sunrise": ("gt_peak", 1.0),
    "crystal_falls_1k": ("gt_peak", 1.0), "drakensberg_solitary_mountain_1k": ("gt_peak", 1.0),
    "hilly_terrain_01_1k": ("gt_peak", 1.0), "industrial_sunset_02_1k": ("brightest_pixel", 0.6),
    "kloppenheim_05_1k": ("gt_peak", 1.0), "noon_grass_1k": ("gt_peak", 1.0), "quarry_02_1k": ("gt_peak", 1.0),
    "resting_place": ("gt_peak", 0.8), "snowy_field_1k": ("gt_peak", 1.0), "spiaggia_di_mondello_1k": ("gt_peak", 1.0),
    "wasteland_clouds_puresky_1k": ("gt_peak", 0.3),
}
DOME_MEDIAN_TARGET = 0.25  # sky-model exposure: the dome's median luminance -> this (LDR ~0.53) at EV 0
VIEW_KEY_VALUE = 0.18  # camera auto-exposure: geometric mean luminance of a view -> this
CACHE_VERSION = 2  # 2: camera pitch sign fixed in dome.camera_from_angles (street and crop views)


def panorama_visibility() -> dict[str, float]:
    """Sun visibility (0..1, by eye) of every known panorama: :data:`PANORAMA_SUN_VISIBILITY` and the 11 added
    for issue 16 (:data:`PANORAMA_SUN`)."""
    return {**{n: v for n, (_, v) in PANORAMA_SUN.items()}, **PANORAMA_SUN_VISIBILITY}


def default_cache_dir() -> Path:
    """``$STREETAUG_CACHE/skynet`` or ``~/.cache/streetaug/skynet`` (never inside the repository)."""
    root = os.environ.get("STREETAUG_CACHE")
    return (Path(root) if root else Path.home() / ".cache" / "streetaug") / "skynet"


def default_hdri_dir() -> Path:
    """``$STREETAUG_HDRI`` or the shared development data beside the repository (``../shared/data/hdri``)."""
    env = os.environ.get("STREETAUG_HDRI")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2].parent / "shared" / "data" / "hdri"


def load_panoramas(hdri_dir: str | Path, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """World-convention panoramas (see :func:`.dome.load_hdri`) by name; InputError if one is missing."""
    hdri_dir = Path(hdri_dir)
    if not hdri_dir.is_dir():
        raise InputError(f"{hdri_dir}: HDR panorama folder not found (pass --hdri DIR or set STREETAUG_HDRI)")
    return {n: load_hdri(hdri_dir / f"{n}.hdr") for n in names}


# ----------------------------------------------------------------------------- per-sample helpers


def white_balance_gains(rng: np.random.Generator, sigma: float = 0.08) -> np.ndarray:
    """Random per-channel gains (3,) of unit luminance."""
    g = np.exp(rng.normal(0.0, sigma, 3))
    return g / luminance(g)


def peak_intensity(dome: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """RGB (3,) of the brightest dome pixel inside the peak disc around ``direction`` (the decoder's
    intensity encoding region), or of the nearest pixel if the disc holds none."""
    H, W = dome.shape[:2]
    kappa = 100.0 * (H / 64.0) ** 2
    cos = dome_directions(H, W) @ direction
    disc = np.exp(kappa * (cos - 1.0)) >= PEAK_DISC_THRESHOLD
    if not disc.any():
        disc = cos >= cos.max()
    lum = np.where(disc, luminance(dome), -1.0)
    j, i = np.unravel_index(np.argmax(lum), lum.shape)
    return np.maximum(dome[j, i].astype(np.float64), 0.0)


def sky_targets(dome: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(peak direction (3,), peak intensity RGB (3,)) of an HDR dome."""
    d = find_peak(dome)
    return d, peak_intensity(dome, d)


def augment_dome(dome: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random azimuth roll (whole pixels) and mirror flip of a dome (H, W, 3)."""
    out = np.roll(dome, int(rng.integers(dome.shape[1])), axis=1)
    return out[:, ::-1] if rng.uniform() < 0.5 else out


def expose_dome(dome: np.ndarray, rng: np.random.Generator | None, ev_range=(-2.0, 1.5)) -> np.ndarray:
    """Scale a dome so its median luminance is ``DOME_MEDIAN_TARGET`` x 2^EV, EV random in ``ev_range``
    (0 when ``rng`` is None); random white balance too."""
    med = max(float(np.median(luminance(dome))), 1e-9)
    if rng is None:
        return (dome * (DOME_MEDIAN_TARGET / med)).astype(np.float32)
    s = DOME_MEDIAN_TARGET / med * 2.0 ** rng.uniform(*ev_range)
    return (dome * s * white_balance_gains(rng)).astype(np.float32)


# ----------------------------------------------------------------------------- synthetic sky pool


def _synth_chunk(args: tuple[int, int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    seed, start, stop, H, W = args
    domes, vis = [], []
    for i in range(start, stop):
        rng = np.random.default_rng([seed, 7, i])
        sky = random_sky(rng)
        domes.append(sky.dome(H, W))
        vis.append(sky.sun_visibility)
    return np.stack(domes), np.array(vis, dtype=np.float32)


def synthetic_sky_pool(n: int, seed: int, height: int, width: int, cache_dir: str | Path | None = None,
                       workers: int = 2, log=print) -> tuple[np.ndarray, np.ndarray]:
    """(n, H, W, 3) float32 synthetic HDR domes (physical units) and their sun visibility (n,); cached."""
    cache = Path(cache_dir or default_cache_dir()) / f"synth_skies_v{CACHE_VERSION}_s{seed}_{height}x{width}_n{n}.npz"
    if cache.is_file():
        with np.load(cache) as z:
            return z["domes"], z["visibility"]
    log(f"generating {n} synthetic skies ({height}x{width}) -> {cache}")
    chunks = [(seed, a, min(a + 100, n), height, width) for a in range(0, n, 100)]
    if workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            parts = list(ex.map(_synth_chunk, chunks))
    else:
        parts = [_synth_chunk(c) for c in chunks]
    domes = np.concatenate([p[0] for p in parts])
    vis = np.concatenate([p[1] for p in parts])
    cache.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(cache) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, domes=domes, visibility=vis)
    return domes, vis


class SkyBatches:
    """Random training batches for the sky model: synthetic domes + real training panoramas."""

    def __init__(self, synth_domes: np.ndarray, panoramas: dict[str, np.ndarray], height: int, width: int,
                 real_fraction: float = 0.3) -> None:
        self.synth = synth_domes
        self.panos = list(panoramas.values())
        self.H, self.W = height, width
        self.real_fraction = real_fraction if self.panos else 0.0

    def one(self, rng: np.random.Generator) -> np.ndarray:
        """One augmented, exposed HDR dome (H, W, 3)."""
        if rng.uniform() < self.real_fraction:
            pano = self.panos[int(rng.integers(len(self.panos)))]
            dome = panorama_to_dome(pano, self.H, self.W, yaw_rad=rng.uniform(0, 2 * np.pi))
            dome = dome[:, ::-1] if rng.uniform() < 0.5 else dome
        else:
            dome = augment_dome(self.synth[int(rng.integers(len(self.synth)))], rng)
        return expose_dome(np.ascontiguousarray(dome), rng)

    def batch(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """``ldr`` (n, 3, H, W), ``log_hdr`` (n, 3, H, W), ``dir`` (n, 3), ``log_int`` (n, 3); float32."""
        domes = [self.one(rng) for _ in range(n)]
        return dome_batch(domes)


def dome_batch(domes: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Network tensors (as numpy) of exposed HDR domes (each (H, W, 3))."""
    targets = [sky_targets(d) for d in domes]
    hdr = np.stack(domes).astype(np.float32)
    return {
        "ldr": quantize_ldr(hdr).transpose(0, 3, 1, 2).copy(),
        "log_hdr": np.log1p(np.maximum(hdr, 0.0)).transpose(0, 3, 1, 2).copy(),
        "dir": np.stack([t[0] for t in targets]).astype(np.float32),
        "log_int": np.log1p(np.stack([t[1] for t in targets])).astype(np.float32),
    }


# ----------------------------------------------------------------------------- camera views


@dataclass(frozen=True)
class View:
    """One training/evaluation view.

    Attributes:
        ldr: (h, w, 3) uint8 image (contract camera response of the radiance x exposure).
        K: (3, 3) intrinsics of ``ldr``.
        R_heading_from_cam: (3, 3) camera -> heading frame.
        dome: (H, W, 3) float32 sky dome (heading frame), on the image's radiometric scale; None for a real
            photo (only its sun is known: ``sun_dir_heading`` is then required).
        visibility: 0..1 fraction of the clear-sky sun that reaches the ground.
        sun_dir_heading: (3,) true sun direction (heading frame), or None if unknown.
    """

    ldr: np.ndarray
    K: np.ndarray
    R_heading_from_cam: np.ndarray
    dome: np.ndarray | None
    visibility: float
    sun_dir_heading: np.ndarray | None = None


def auto_exposure(radiance: np.ndarray) -> float:
    """Camera-like exposure k: geometric mean luminance -> VIEW_KEY_VALUE (linear)."""
    lum = luminance(np.asarray(radiance, dtype=np.float64))
    return float(VIEW_KEY_VALUE / np.exp(np.mean(np.log(np.maximum(lum, 1e-9)))))


def random_camera(rng: np.random.Generator, sky_bias: float = 0.2) -> tuple[np.ndarray, float, float, float]:
    """(K at VIEW_SIZE, yaw, pitch, roll) of a random camera: 45-100 deg horizontal FOV, mostly level;
    with probability ``sky_bias`` tilted up 8-35 deg."""
    h, w = VIEW_SIZE
    K = intrinsics_from_fov(w, h, float(rng.uniform(45.0, 100.0)))
    pitch = rng.uniform(8.0, 35.0) if rng.uniform() < sky_bias else float(np.clip(rng.normal(0.0, 4.0), -10, 10))
    roll = float(np.clip(rng.normal(0.0, 2.0), -6, 6))
    return K, float(rng.uniform(-np.pi, np.pi)), float(np.radians(pitch)), float(np.radians(roll))


def _rz(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def panorama_view(pano_world: np.ndarray, visibility: float, rng: np.random.Generator, dome_hw: tuple[int, int],
                  camera: tuple | None = None, exposure_ev: float | None = None) -> View:
    """A perspective crop of a world panorama (optionally mirrored) with its dome, auto-exposed.

    ``camera`` = (K, yaw, pitch, roll) fixes the camera (no flip); ``exposure_ev`` adds EV to the auto exposure.
    """
    if camera is None:
        if rng.uniform() < 0.5:
            pano_world = pano_world[:, ::-1]
        camera = random_camera(rng)
    K, yaw, pitch, roll = camera
    R_world_from_cam = camera_from_angles(yaw, pitch, roll)
    h, w = VIEW_SIZE
    rad = render_perspective(pano_world, K, R_world_from_cam, w, h)
    ev = exposure_ev if exposure_ev is not None else (rng.normal(0.0, 0.5) if rng is not None else 0.0)
    k = auto_exposure(rad) * 2.0**ev
    up_cam = R_world_from_cam.T @ np.array([0.0, 0.0, 1.0])
    dome = panorama_to_dome(pano_world, *dome_hw, yaw_rad=yaw) * k
    ldr = np.clip(np.round(hdr_to_ldr(rad * k) * 255), 0, 255).astype(np.uint8)
    return View(ldr, K, heading_from_camera(up_cam), dome.astype(np.float32), float(visibility))


def synthetic_sky_view(rng: np.random.Generator, dome_hw: tuple[int, int]) -> View:
    """A crop of a random synthetic sky above a flat ground (uniform albedo with a mild texture)."""
    sky = random_sky(rng)
    K, yaw, pitch, roll = random_camera(rng, sky_bias=0.35)
    R_world_from_cam = camera_from_angles(yaw, pitch, roll)
    h, w = VIEW_SIZE
    d = PinholeCamera(K, w, h).rays().reshape(-1, 3) @ R_world_from_cam.T
    rad = sky.radiance(d)
    below = d[:, 2] < 0
    if below.any():  # textured ground: the sky model's ground x a low-frequency albedo variation
        p = d[below, :2] / np.maximum(-d[below, 2:3], 0.02)
        tex = 1.0 + 0.25 * np.sin(p[:, 0] * rng.uniform(0.5, 3)) * np.sin(p[:, 1] * rng.uniform(0.5, 3))
        rad[below] *= tex[:, None]
    # the sun disc if in view
    cos_sun = d @ np.asarray(sky.sun_dir)
    e = sky.sun_irradiance_rgb
    if np.any(e > 0):
        rad += (cos_sun >= np.cos(sky.sun_half_angle_rad * 4))[:, None] * (e / (2 * np.pi * (1 - np.cos(sky.sun_half_angle_rad * 4))))
    rad = rad.reshape(h, w, 3)
    k = auto_exposure(rad) * 2.0 ** rng.normal(0.0, 0.5)
    up_cam = R_world_from_cam.T @ np.array([0.0, 0.0, 1.0])
    dome = sky.dome(*dome_hw, R_sky_from_heading=_rz(yaw)) * k
    ldr = np.clip(np.round(hdr_to_ldr(rad * k) * 255), 0, 255).astype(np.uint8)
    sun_h = _rz(yaw).T @ np.asarray(sky.sun_dir)
    return View(ldr, K, heading_from_camera(up_cam), dome.astype(np.float32), sky.sun_visibility, sun_h)


def _street_chunk(args: tuple[int, int, int, int, int]) -> list[View]:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    seed, start, stop, H, W = args
    out = []
    h, w = VIEW_SIZE
    for i in range(start, stop):
        rng = np.random.default_rng([seed, 11, i])
        heading = rng.uniform(-np.pi, np.pi)
        scene = build_street(StreetParams(seed=100_000 + seed * 10_000 + i, drive_on_left=bool(rng.uniform() < 0.5)),
                             make_transform(_rz(heading), [0.0, 0.0, 0.0]))
        sky = random_sky(rng)
        renderer = StreetRenderer(scene, sky)
        for _ in range(2):  # two cameras per street and sky
            K, yaw, pitch, roll = random_camera(rng, sky_bias=0.1)
            R_ego_from_cam = camera_from_angles(yaw, pitch, roll)
            T = scene.T_global_from_ego @ make_transform(R_ego_from_cam, [1.5, 0.0, 1.5])
            res = renderer.render(K, T, w, h, spp=4, sky_rays=1, sun_rays=1, seed=int(rng.integers(1 << 30)))
            k = choose_exposure(res.radiance, res.label) * 2.0 ** rng.normal(0.0, 0.3)
            R_global_from_cam = T[:3, :3]
            up_cam = R_global_from_cam.T @ np.array([0.0, 0.0, 1.0])
            fwd = R_global_from_cam[:, 2]
            yaw_global = float(np.arctan2(fwd[1], fwd[0]))
            dome = sky.dome(H, W, R_sky_from_heading=_rz(yaw_global)) * k
            ldr = np.clip(np.round(hdr_to_ldr(res.radiance * k) * 255), 0, 255).astype(np.uint8)
            sun_h = _rz(yaw_global).T @ np.asarray(sky.sun_dir)
            out.append(View(ldr, K, heading_from_camera(up_cam), dome.astype(np.float32), sky.sun_visibility, sun_h))
    return out


def _cached_views(cache: Path, make, chunks: list, workers: int, log, what: str) -> list[View]:
    """Views from ``cache`` (.npz) or made by ``make(chunk) -> list[View]`` over ``chunks`` and cached."""
    if cache.is_file():
        with np.load(cache) as z:  # each z[key] reads the whole array: read each once
            ldr, K, R, dome, vis, sun = (z[k] for k in ("ldr", "K", "R", "dome", "vis", "sun"))
        return [View(ldr[i], K[i], R[i], dome[i], float(vis[i]), None if np.isnan(sun[i, 0]) else sun[i])
                for i in range(len(vis))]
    log(f"making {what} -> {cache}")
    if workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            parts = list(ex.map(make, chunks))
    else:
        parts = [make(c) for c in chunks]
    views = [v for p in parts for v in p]
    cache.parent.mkdir(parents=True, exist_ok=True)
    nan3 = np.full(3, np.nan)
    with atomic_path(cache) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, ldr=np.stack([v.ldr for v in views]), K=np.stack([v.K for v in views]),
                     R=np.stack([v.R_heading_from_cam for v in views]), dome=np.stack([v.dome for v in views]),
                     vis=np.array([v.visibility for v in views], np.float32),
                     sun=np.stack([nan3 if v.sun_dir_heading is None else v.sun_dir_heading for v in views]))
    return views


def street_view_pool(n_streets: int, seed: int, dome_hw: tuple[int, int], cache_dir: str | Path | None = None,
                     workers: int = 2, log=print) -> list[View]:
    """2 x ``n_streets`` rendered street views under random synthetic skies (cached as one ``.npz``)."""
    H, W = dome_hw
    cache = Path(cache_dir or default_cache_dir()) / f"street_views_v{CACHE_VERSION}_s{seed}_{H}x{W}_n{n_streets}.npz"
    chunks = [(seed, a, min(a + 25, n_streets), H, W) for a in range(0, n_streets, 25)]
    return _cached_views(cache, _street_chunk, chunks, workers, log, f"{2 * n_streets} street views under random skies")


def _crop_chunk(args: tuple) -> list[View]:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    seed, start, stop, H, W, hdri_dir, names = args
    panos = load_panoramas(hdri_dir, names)
    visibility = panorama_visibility()
    out = []
    for i in range(start, stop):
        rng = np.random.default_rng([seed, 13, i])
        if i % 2 == 0:
            name = names[(i // 2) % len(names)]
            out.append(panorama_view(panos[name], visibility[name], rng, (H, W)))
        else:
            out.append(synthetic_sky_view(rng, (H, W)))
    return out


def crop_view_pool(n: int, seed: int, dome_hw: tuple[int, int], hdri_dir: str | Path,
                   cache_dir: str | Path | None = None, workers: int = 2, log=print,
                   panoramas: tuple[str, ...] = TRAIN_PANORAMAS) -> tuple[list[View], list[View]]:
    """(n/2 crops of the real training ``panoramas`` (in turn), n/2 crops of synthetic skies over a flat ground);
    cached (the cache name holds the panorama list)."""
    H, W = dome_hw
    tag = "" if tuple(panoramas) == TRAIN_PANORAMAS else "_p" + hashlib.sha256(",".join(panoramas).encode()).hexdigest()[:8]
    cache = Path(cache_dir or default_cache_dir()) / f"crop_views_v{CACHE_VERSION}_s{seed}_{H}x{W}_n{n}{tag}.npz"
    chunks = [(seed, a, min(a + 100, n), H, W, str(hdri_dir), tuple(panoramas)) for a in range(0, n, 100)]
    views = _cached_views(cache, _crop_chunk, chunks, workers, log, f"{n} panorama and synthetic-sky crops")
    return views[0::2], views[1::2]


def flip_view(v: View) -> View:
    """The mirror image of a view (image columns flipped; heading-frame y, dome longitudes and K's cx follow)."""
    h, w = v.ldr.shape[:2]
    K = np.array(v.K, dtype=np.float64).copy()
    K[0, 2] = (w - 1) - K[0, 2]
    K[0, 1] = -K[0, 1]
    Fc, Fh = np.diag([-1.0, 1.0, 1.0]), np.diag([1.0, -1.0, 1.0])
    sun = None if v.sun_dir_heading is None else Fh @ v.sun_dir_heading
    dome = None if v.dome is None else np.ascontiguousarray(v.dome[:, ::-1])
    return View(np.ascontiguousarray(v.ldr[:, ::-1]), K, Fh @ v.R_heading_from_cam @ Fc, dome, v.visibility, sun)


def views_batch(views: list[View], dome_hw: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """Network tensors (numpy) of views: ``ldr`` (B, 3, h, w), ``rays`` (B, 3, h, w), ``dome_ldr``, ``log_hdr``
    (B, 3, H, W), ``dir``, ``log_int`` (B, 3) peak targets, ``vis`` (B,), ``has_dome`` (B,) 1 where the view
    has a sky dome.  Real photos (``dome`` None) get zero dome tensors and ``dir`` = their ``sun_dir_heading``;
    ``dome_hw`` gives the dome size when no view of the batch has one."""
    h, w = VIEW_SIZE
    ldr, rays = [], []
    for v in views:
        img, K = (v.ldr, v.K) if v.ldr.shape[:2] == (h, w) else resize_view(v.ldr, v.K, h, w)
        ldr.append(img.astype(np.float32).transpose(2, 0, 1) / 255.0)
        rays.append(view_rays(K, v.R_heading_from_cam, h, w))
    has = np.array([v.dome is not None for v in views])
    shape = next((v.dome.shape for v in views if v.dome is not None), None)
    if shape is None:
        if dome_hw is None:
            raise ValueError("views_batch: no view has a sky dome; pass dome_hw")
        shape = (*dome_hw, 3)
    blank = np.full(shape, 1e-3, np.float32)
    out = dome_batch([v.dome if v.dome is not None else blank for v in views])
    for i in np.nonzero(~has)[0]:
        if views[i].sun_dir_heading is None:
            raise ValueError(f"views_batch: view {i} has neither a dome nor a sun direction")
        out["dir"][i] = views[i].sun_dir_heading
        out["log_int"][i] = 0.0
    out.update(ldr=np.ascontiguousarray(np.stack(ldr)), rays=np.ascontiguousarray(np.stack(rays)),
               vis=np.array([v.visibility for v in views], np.float32), dome_ldr=out.pop("ldr"),
               has_dome=has.astype(np.float32))
    return out

