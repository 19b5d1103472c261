"""Real training and evaluation views of the image predictor: street photos with ephemeris sun labels, panoramas.

* **Street photos** (the real dev scene ``scene-0916`` of ``../shared/data/nuscenes-seq``, 41 keyframes x 6
  cameras; the one-north keyframe of ``../shared/data/nuscenes-real``): the true sun direction of each view is
  the ephemeris (:func:`..lighting.sun.sun_direction_global` at the view's timestamp and location) rotated
  into the camera with the view's ``T_cam_from_global``.  The product path sees a bare image and assumes a
  level camera (up = -y); the labels are compared **in the camera frame**, and training uses the same
  level-camera heading frame as inference, so the camera's real tilt (< 2 deg on nuScenes) is part of the
  error, as it is for a user.
* **Keyframe split** (contiguous blocks, a gap between them so neighbouring keyframes 0.5 s apart do not leak):
  :data:`TRAIN_KEYFRAMES` 0-23, gap 24-26 (unused), :data:`TEST_KEYFRAMES` 27-40.
* **Sun visibility label** of a street photo, from the object shadows of its *sample* (all 6 cameras):
  :func:`..lighting.evidence.box_shadow_evidence` measures the lit/shadow road contrast around each
  annotated object where the ephemeris sun casts its shadow, and again for a control sun at the same
  elevation from the opposite azimuth.  Under an overcast sky the road next to a car is darker on every side
  (ambient occlusion, wet tyre tracks): the raw contrast is 2-6 on scene-0916 although it casts no shadow.
  Only a cast shadow is darker on the sun's side than on the other, so the label is
  :func:`visibility_from_contrast` of ``median(contrast at the sun) / median(contrast at the control)``.
* **Panoramas** (``../shared/data/hdri``): :data:`PANORAMA_SUN` gives each one's sun (direction from
  ``index.json``, visibility by eye); :data:`TRAIN_PANORAMAS_V3` / :data:`HELDOUT_PANORAMAS` are the split of
  the image predictor v3 (the held-out ones are never trained on).

The nuScenes images are CC BY-NC-SA 4.0: weights trained on them are derived from them.  Nothing here
writes into the repository.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..core import InputError, hdr_to_ldr, ldr_uint8_to_hdr, scale_intrinsics
from ..lighting.evidence import box_shadow_evidence, prepare_image
from ..lighting.skynet.dome import camera_from_angles, heading_from_camera, hdri_direction, render_perspective
from .data import PANORAMA_SUN, View, auto_exposure

DEV_SCENE = "scene-0916"
DEV_VERSION = "v1.0-mini"
ONE_NORTH_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
TRAIN_KEYFRAMES = tuple(range(0, 24))
GAP_KEYFRAMES = tuple(range(24, 27))
TEST_KEYFRAMES = tuple(range(27, 41))
LEVEL_UP_CAM = np.array([0.0, -1.0, 0.0])  # what a bare image is assumed to be (the product path)
PHOTO_SIZE = (180, 320)  # (h, w) the street photos are kept at for training (crops are resized from it)
CLEAR_CONTRAST = 4.0  # lit/shadow road ratio of a clear sky at mid elevation (sun / sky horizontal irradiance + 1)

OLD_PANORAMAS = ("city", "dawn", "forest", "night", "sky", "sunrise", "venice")  # before the 11 new ones
TRAIN_PANORAMAS_V3 = ("city", "dawn", "forest", "night", "crystal_falls_1k", "industrial_sunset_02_1k",
                      "noon_grass_1k", "quarry_02_1k", "resting_place", "spiaggia_di_mondello_1k",
                      "wasteland_clouds_puresky_1k")
HELDOUT_PANORAMAS = ("sky", "sunrise", "venice", "drakensberg_solitary_mountain_1k", "hilly_terrain_01_1k",
                     "kloppenheim_05_1k", "snowy_field_1k")


def panorama_sun(hdri_dir: str | Path) -> dict[str, tuple[np.ndarray | None, float]]:
    """name -> (world sun direction (3,) or None, visibility) of the panoramas listed in :data:`PANORAMA_SUN`."""
    index = Path(hdri_dir) / "index.json"
    if not index.is_file():
        raise InputError(f"{index}: panorama index not found (pass the hdri folder)")
    files = json.loads(index.read_text())["files"]
    out = {}
    for name, (key, vis) in PANORAMA_SUN.items():
        if name not in files:
            raise InputError(f"{index}: panorama {name!r} missing")
        d = None if key is None else hdri_direction(files[name][key]["azimuth_deg"], files[name][key]["elevation_deg"])
        out[name] = (d, vis)
    return out


def visibility_from_contrast(contrast: float | None) -> float:
    """Sun visibility 0..1 of a lit/shadow road contrast: ``(contrast - 1) / (CLEAR_CONTRAST - 1)`` clipped
    (a clear sky's direct sun adds ~3x the sky's irradiance on the lit road); None (no usable shadow) -> 0."""
    if contrast is None:
        return 0.0
    return float(np.clip((contrast - 1.0) / (CLEAR_CONTRAST - 1.0), 0.0, 1.0))


@dataclass(frozen=True)
class StreetPhoto:
    """One real camera view with its ephemeris sun.

    Attributes:
        keyframe: index of the sample in its scene (time order).
        channel: camera channel.
        image_path: the JPEG.
        K: (3, 3) intrinsics of the full image (pixel centres at integers).
        sun_dir_cam: (3,) unit direction to the sun, camera frame (ephemeris).
        up_cam: (3,) unit global up in the camera frame (the real tilt; the product path assumes (0, -1, 0)).
        sun_elevation_deg: sun elevation above the horizon.
        visibility: the sample's sun visibility label (see the module doc).
        shadow_contrast: the sample's median object-shadow contrast at the sun over that at the control
            sun, or None (no usable object).
    """

    keyframe: int
    channel: str
    image_path: str
    K: np.ndarray
    sun_dir_cam: np.ndarray
    up_cam: np.ndarray
    sun_elevation_deg: float
    visibility: float
    shadow_contrast: float | None


def street_photos(dataroot: str | Path, version: str = DEV_VERSION, scene: str | None = DEV_SCENE,
                  sample_tokens: tuple[str, ...] | None = None, keyframes: tuple[int, ...] | None = None,
                  shadows: bool = True) -> list[StreetPhoto]:
    """The camera views of a scene's keyframes (or of the given samples) with ephemeris sun labels.

    Args:
        dataroot, version: the nuScenes folder and version.
        scene: scene name whose keyframes are listed (ignored when ``sample_tokens`` is given).
        keyframes: indices into the scene's keyframes (default all).
        shadows: compute the visibility label from the object shadows (reads every image once); False: 0.
    """
    from ...datasets.nuscenes import NuScenesReader  # noqa: PLC0415 (the reader pulls in the devkit tables)
    from ..lighting.sun import sun_direction_global, up_direction_camera

    reader = NuScenesReader(str(dataroot), version)
    tokens = list(sample_tokens) if sample_tokens is not None else list(reader.sample_tokens(scene))
    chosen = range(len(tokens)) if keyframes is None else keyframes
    out = []
    for k in chosen:
        sample = reader.sample(tokens[k])
        rows, contrasts = [], []
        for ch in sorted(sample.cameras):
            view = sample.cameras[ch]
            sun = sun_direction_global(sample.location, view.timestamp_us)
            T = np.asarray(view.T_cam_from_global, dtype=np.float64)
            d = T[:3, :3] @ sun.direction_global
            up = up_direction_camera(view)
            if shadows:
                work = prepare_image(np.asarray(view.image), np.asarray(view.K, dtype=np.float64), up)
                control = sun.direction_global * np.array([-1.0, -1.0, 1.0])  # same elevation, opposite azimuth
                ev = box_shadow_evidence(work, T, list(sample.boxes), sun.direction_global)
                ev_c = box_shadow_evidence(work, T, list(sample.boxes), control)
                if ev is not None and ev_c is not None:
                    contrasts.append((ev["per_object_contrast"], ev_c["per_object_contrast"]))
            rows.append((ch, view.image_path, np.asarray(view.K, dtype=np.float64), d / np.linalg.norm(d), up,
                         float(sun.elevation_deg)))
        contrast = None
        if contrasts:
            at_sun = np.median(np.concatenate([c[0] for c in contrasts]))
            at_control = np.median(np.concatenate([c[1] for c in contrasts]))
            contrast = float(at_sun / max(at_control, 1e-6))
        vis = visibility_from_contrast(contrast) if shadows else 0.0
        out += [StreetPhoto(k, ch, p, K, d, up, el, vis, contrast) for ch, p, K, d, up, el in rows]
    return out


def photo_view(photo: StreetPhoto, image_rgb: np.ndarray, size: tuple[int, int] = PHOTO_SIZE) -> View:
    """A training :class:`.data.View` of a street photo: the image area-resized to ``size`` (h, w), the
    level-camera heading frame (as inference without metadata), the sun label; no sky dome (``dome`` None)."""
    h, w = size
    H0, W0 = image_rgb.shape[:2]
    small = cv2.resize(np.ascontiguousarray(image_rgb), (w, h), interpolation=cv2.INTER_AREA)
    K = scale_intrinsics(photo.K, w / W0, h / H0)
    R = heading_from_camera(LEVEL_UP_CAM)
    return View(small, K, R, None, photo.visibility, R @ photo.sun_dir_cam)


def jitter_photo(v: View, rng: np.random.Generator, out_hw: tuple[int, int]) -> View:
    """A random crop (70-100 % of each side, the principal point moving with it), resized to ``out_hw``,
    with a random exposure (+-0.7 EV in linear radiance) and white balance; heading frame and label kept."""
    H, W = v.ldr.shape[:2]
    s = rng.uniform(0.7, 1.0)
    ch, cw = int(round(H * s)), int(round(W * s))
    y0, x0 = int(rng.integers(0, H - ch + 1)), int(rng.integers(0, W - cw + 1))
    crop = v.ldr[y0:y0 + ch, x0:x0 + cw]
    K = np.array(v.K, dtype=np.float64).copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    oh, ow = out_hw
    small = cv2.resize(np.ascontiguousarray(crop), (ow, oh), interpolation=cv2.INTER_AREA)
    K = scale_intrinsics(K, ow / cw, oh / ch)
    gain = 2.0 ** rng.normal(0.0, 0.35) * np.exp(rng.normal(0.0, 0.05, 3))
    hdr = ldr_uint8_to_hdr(small) * gain
    ldr = np.clip(np.round(hdr_to_ldr(hdr) * 255.0), 0, 255).astype(np.uint8)
    return View(ldr, K, v.R_heading_from_cam, None, v.visibility, v.sun_dir_heading)


def panorama_level_views(pano_world: np.ndarray, sun_world: np.ndarray | None, width: int = 1600,
                         height: int = 900, fov_deg: float = 70.0, n_azimuths: int = 12):
    """Level perspective views of a panorama at ``n_azimuths`` offsets from the sun's azimuth (from world
    azimuth 0 if no sun), auto-exposed like ``benchmarks/bench_sky.py``: yields (offset_deg, image (H, W, 3)
    uint8, K (3, 3), sun_dir_cam (3,) or None)."""
    from ..core import intrinsics_from_fov

    K = intrinsics_from_fov(width, height, fov_deg)
    az0 = 0.0 if sun_world is None else float(np.arctan2(sun_world[1], sun_world[0]))
    for o in np.arange(n_azimuths) * (360.0 / n_azimuths):
        R_wc = camera_from_angles(az0 + np.radians(o), 0.0, 0.0)
        rad = render_perspective(pano_world, K, R_wc, width, height, supersample=1)
        image = np.clip(np.round(hdr_to_ldr(rad * auto_exposure(rad)) * 255), 0, 255).astype(np.uint8)
        yield float(o), image, K, None if sun_world is None else R_wc.T @ sun_world


def bare_image_prediction(image_rgb: np.ndarray, K: np.ndarray, models=None, use_cues: bool = True):
    """The image predictor's :class:`..lighting.skynet.predict.SkyPrediction` of a bare image exactly as the
    lighting front door runs it without metadata (:func:`..lighting.learned.learned_sky_estimate`): a level
    camera, the image first downscaled by :func:`..lighting.evidence.prepare_image`.  Its ``direction_cam``
    is the model's sun direction whether or not it is confident enough to report a sun; ``use_cues`` False:
    the network alone."""
    from ..lighting.skynet.predict import predict_sky

    work = prepare_image(np.asarray(image_rgb), np.asarray(K, dtype=np.float64), LEVEL_UP_CAM)
    small = np.clip(np.round(work.ldr * 255.0), 0, 255).astype(np.uint8)
    return predict_sky(small, work.K, LEVEL_UP_CAM, models=models, use_cues=use_cues)
