"""How much the outputs move when the inputs are slightly wrong: the stability report.

Each perturbation family (exposure, sensor noise, JPEG, focal-length error, depth bias/noise, LiDAR
dropout, camera calibration error) is applied at a few strengths to one camera of a sample, and the
insertion is re-run with the same seed.  Measured against the unperturbed run:

* ``sun_change_deg``: angle between the estimated sun directions (camera frame), for the dataset path
  (ephemeris) and for the single-image path (no metadata);
* ``envmap_change``: RMS difference of log(1 + radiance) of the estimated environments (64 x 128);
* ``placement_change_m`` / ``placement_yaw_change_deg``: movement of the first placed box (global);
* ``composite_psnr_db``: PSNR (dB, 8-bit) of the perturbed run's composite against the unperturbed
  composite with the same perturbation applied afterwards (so only the insertion's reaction is
  measured, not the perturbation itself), over the pixels the insertion changed in either run.

Conventions: perturbations are deterministic given their strength and ``seed``; a perturbation of the
calibration changes what the pipeline *believes* (K or T_ego_from_cam), not the pixels.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import time
import zlib
from dataclasses import dataclass
from typing import Callable, Sequence

import cv2
import numpy as np

from ..core import atomic_path, hdr_to_ldr_uint8, ldr_uint8_to_hdr, make_transform
from ..lighting.estimate import estimate_lighting_from_image
from ..lighting.sun import sun_direction_global
from ..pipeline import insert_into_view
from .metrics import psnr_db

PerturbFn = Callable[..., tuple[object, object, Callable[[np.ndarray], np.ndarray]]]


@dataclass(frozen=True)
class Family:
    """A perturbation family: ``apply(sample, view, strength, rng) -> (sample', view', image_fn)``.

    ``image_fn`` applies the same perturbation to any image (identity for calibration/geometry errors);
    ``unit`` names the strength's unit; ``strengths`` are the report's sweep.
    """

    name: str
    unit: str
    strengths: tuple[float, ...]
    apply: PerturbFn


def _with_image(sample, view, image_fn):
    image = image_fn(view.image)
    new_view = dataclasses.replace(view, _load_image=lambda: image)
    return (*_with_camera(sample, new_view), image_fn)


def _with_camera(sample, view):
    """``(sample with view replacing its camera of that channel, view)``."""
    return dataclasses.replace(sample, cameras=dict(sample.cameras, **{view.channel: view})), view


def _with_lidar(sample, view, points_fn):
    lidar = sample.lidar
    if lidar is None:
        return sample, view, _identity
    points, keep = points_fn(lidar.points_sensor)
    new = dataclasses.replace(
        lidar, points_sensor=points, intensity=lidar.intensity[keep],
        labels=None if lidar.labels is None else lidar.labels[keep],
    )
    return dataclasses.replace(sample, _load_lidar=lambda: new), view, _identity


def _identity(image: np.ndarray) -> np.ndarray:
    return image


def exposure(sample, view, ev: float, rng):
    """The image as if exposed ``ev`` stops brighter (through the contract's camera response)."""
    return _with_image(sample, view, lambda im: hdr_to_ldr_uint8(ldr_uint8_to_hdr(im) * 2.0**ev))


def sensor_noise(sample, view, sigma_8bit: float, rng):
    """Additive Gaussian noise of ``sigma_8bit`` grey levels (fixed pattern for a given rng)."""
    noise = rng.normal(0.0, sigma_8bit, size=(view.height, view.width, 3))
    return _with_image(sample, view, lambda im: np.clip(np.round(im + noise), 0, 255).astype(np.uint8))


def jpeg(sample, view, quality: float, rng):
    """JPEG re-compression at ``quality`` (0-100)."""

    def fn(im: np.ndarray) -> np.ndarray:
        ok, buf = cv2.imencode(".jpg", im[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()

    return _with_image(sample, view, fn)


def focal_error(sample, view, percent: float, rng):
    """The calibration claims a focal length ``percent`` % too long (pixels unchanged)."""
    K = view.K.copy()
    K[0, 0] *= 1 + percent / 100.0
    K[1, 1] *= 1 + percent / 100.0
    new_view = dataclasses.replace(view, K=K)
    return (*_with_camera(sample, new_view), _identity)


def calibration_error(sample, view, degrees: float, rng):
    """The calibration's camera rotation is off by ``degrees`` about a fixed random axis."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R, _ = cv2.Rodrigues(axis * np.radians(degrees))
    T = view.T_ego_from_cam @ make_transform(R, [0.0, 0.0, 0.0])
    new_view = dataclasses.replace(view, T_ego_from_cam=T)
    return (*_with_camera(sample, new_view), _identity)


def depth_bias(sample, view, percent: float, rng):
    """Every LiDAR range scaled by 1 + ``percent`` / 100 (a range bias)."""
    return _with_lidar(sample, view, lambda p: (p * (1 + percent / 100.0), slice(None)))


def depth_noise(sample, view, sigma_m: float, rng):
    """Gaussian range noise of ``sigma_m`` metres on every LiDAR point."""

    def fn(p):
        r = np.linalg.norm(p, axis=1, keepdims=True)
        scale = 1.0 + rng.normal(0.0, sigma_m, size=(len(p), 1)) / np.maximum(r, 1e-6)
        return p * scale, slice(None)

    return _with_lidar(sample, view, fn)


def lidar_dropout(sample, view, percent: float, rng):
    """A random ``percent`` % of the LiDAR points removed."""

    def fn(p):
        keep = rng.random(len(p)) >= percent / 100.0
        return p[keep], keep

    return _with_lidar(sample, view, fn)


def _families() -> dict[str, Family]:
    fams = (
        Family("exposure", "EV", (-1.0, -0.5, 0.5, 1.0), exposure),
        Family("noise", "sigma (8-bit levels)", (2.0, 5.0, 10.0), sensor_noise),
        Family("jpeg", "quality", (90.0, 70.0, 50.0), jpeg),
        Family("focal", "% error", (-2.0, -1.0, 1.0, 2.0), focal_error),
        Family("depth_bias", "% range", (-5.0, 5.0), depth_bias),
        Family("depth_noise", "sigma (m)", (0.05, 0.2), depth_noise),
        Family("lidar_dropout", "% points", (25.0, 50.0, 75.0), lidar_dropout),
        Family("calibration", "deg rotation", (0.5, 1.0), calibration_error),
    )
    return {f.name: f for f in fams}


FAMILIES = _families()


# ----------------------------------------------------------------------------- metrics


def angle_deg(a: np.ndarray | None, b: np.ndarray | None) -> float | None:
    """Angle between two directions in degrees; None when either is missing (no sun)."""
    if a is None or b is None:
        return None
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = float(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))
    return float(np.degrees(np.arccos(c)))


def envmap_change(light_a, light_b, height: int = 64, width: int = 128) -> float:
    """RMS difference of log(1 + radiance) between two lights' full environments."""
    ea = np.log1p(np.maximum(light_a.to_envmap(height, width), 0.0))
    eb = np.log1p(np.maximum(light_b.to_envmap(height, width), 0.0))
    return float(np.sqrt(np.mean((ea - eb) ** 2)))


def _affected(result, source: np.ndarray) -> np.ndarray:
    return (result.mask > 0.01) | (result.shadow_ratio < 0.995) | (np.abs(result.image.astype(int) - source).max(-1) > 2)


def _first_box(result):
    placement = result.placement
    if placement is None or not placement.placements:
        return None
    return placement.placements[0]


# ----------------------------------------------------------------------------- the report


def measure(sample, view, assets, options, family: Family, strength: float, baseline=None, seed: int = 0) -> dict:
    """One perturbation at one strength vs the unperturbed run (``baseline`` = (result, image_lighting))."""
    if baseline is None:
        baseline = run_once(sample, view, assets, options)
    base, base_image_light = baseline
    rng = np.random.default_rng([seed, zlib.crc32(family.name.encode()), int(round(abs(strength) * 1000))])
    p_sample, p_view, image_fn = family.apply(sample, view, strength, rng)
    t = time.perf_counter()
    result = insert_into_view(p_sample, p_view, assets, options)
    seconds = time.perf_counter() - t
    image_light = estimate_lighting_from_image(p_view.image, p_view.K)

    row: dict = {"family": family.name, "strength": float(strength), "unit": family.unit, "seconds": seconds}
    row["sun_change_deg"] = angle_deg(base.lighting.sun_dir_cam, result.lighting.sun_dir_cam)
    row["sun_visibility_change"] = abs(base.lighting.sun_visibility - result.lighting.sun_visibility)
    row["envmap_change"] = envmap_change(base.lighting.light_cam, result.lighting.light_cam)
    row["image_path_sun_change_deg"] = angle_deg(base_image_light.sun_dir_cam, image_light.sun_dir_cam)
    row["image_path_envmap_change"] = envmap_change(base_image_light.light_cam, image_light.light_cam)
    a, b = _first_box(base), _first_box(result)
    row["placed"] = b is not None
    if a is not None and b is not None:
        row["placement_change_m"] = float(np.linalg.norm(a.box.center - b.box.center))
        ya, yb = np.arctan2(a.T_global_from_object[1, 0], a.T_global_from_object[0, 0]), np.arctan2(
            b.T_global_from_object[1, 0], b.T_global_from_object[0, 0])
        row["placement_yaw_change_deg"] = float(abs(np.degrees((yb - ya + np.pi) % (2 * np.pi) - np.pi)))
    else:
        row["placement_change_m"] = row["placement_yaw_change_deg"] = None
    expected = image_fn(base.image)
    where = _affected(base, view.image) | _affected(result, p_view.image)
    row["composite_psnr_db"] = psnr_db(expected, result.image, where)
    row["finite"] = bool(np.isfinite(result.lighting.light_cam.envmap).all() and np.isfinite(result.shadow_ratio).all())
    return row


def run_once(sample, view, assets, options):
    """The unperturbed insertion and single-image lighting (the report's baseline)."""
    return insert_into_view(sample, view, assets, options), estimate_lighting_from_image(view.image, view.K)


def stability_report(sample, view, assets, options, families: Sequence[str] | None = None,
                     strengths: dict[str, Sequence[float]] | None = None, seed: int = 0) -> dict:
    """Every family at every strength; returns ``{"rows": [...], "baseline": {...}}`` (JSON-serialisable)."""
    names = list(families) if families is not None else list(FAMILIES)
    unknown = [n for n in names if n not in FAMILIES]
    if unknown:
        raise ValueError(f"unknown perturbation families {unknown}; known: {', '.join(FAMILIES)}")
    baseline = run_once(sample, view, assets, options)
    rows = []
    for name in names:
        fam = FAMILIES[name]
        for s in (strengths or {}).get(name, fam.strengths):
            rows.append(measure(sample, view, assets, options, fam, s, baseline, seed))
    base = baseline[0]
    return {
        "schema": "streetaug.stability/1",
        "sample_token": sample.token, "camera": view.channel,
        "baseline": {"placed": _first_box(base) is not None, "sun_source": base.lighting.sun_source,
                     "level": base.lighting.level, "timing_s": base.timing_s},
        "rows": rows,
    }


def plot_report(report: dict, path) -> None:
    """Curves: one column per perturbation family (x = its strength), one row per metric."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = [("sun_change_deg", "sun change (deg)"), ("image_path_sun_change_deg", "sun change, image only (deg)"),
               ("envmap_change", "env map change (log RMS)"), ("placement_change_m", "placement change (m)"),
               ("composite_psnr_db", "composite PSNR (dB)")]
    by_family: dict[str, list[dict]] = {}
    for row in report["rows"]:
        by_family.setdefault(row["family"], []).append(row)
    fig, axes = plt.subplots(len(metrics), len(by_family), figsize=(2.2 * len(by_family), 1.5 * len(metrics)),
                             squeeze=False, sharey="row")
    for j, (fam, rows) in enumerate(by_family.items()):
        rows = sorted(rows, key=lambda r: r["strength"])
        xs = [r["strength"] for r in rows]
        for i, (metric, label) in enumerate(metrics):
            ax = axes[i, j]
            ys = [np.nan if r[metric] is None else min(float(r[metric]), 99.0) for r in rows]
            ax.plot(xs, ys, marker="o", ms=3)
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(fam, fontsize=8)
            if i == len(metrics) - 1:
                ax.set_xlabel(rows[0]["unit"], fontsize=7)
            if j == 0:
                ax.set_ylabel(label, fontsize=6)
    fig.suptitle(f"stability: sample {report['sample_token'][:8]} {report['camera']} (missing points: no sun / "
                 f"no placement)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)


# ----------------------------------------------------------------------------- failure modes


def at_time(sample, view, when_utc: dt.datetime, location: str | None = None):
    """``(sample, view)`` as if captured at ``when_utc`` (naive = UTC), optionally at another location."""
    us = int(when_utc.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6)
    new_view = dataclasses.replace(view, timestamp_us=us)
    cams = dict(sample.cameras, **{view.channel: new_view})
    return dataclasses.replace(sample, timestamp_us=us, cameras=cams, location=location or sample.location), new_view


def _elevation(location: str, when: dt.datetime) -> float:
    return sun_direction_global(location, int(when.replace(tzinfo=dt.timezone.utc).timestamp() * 1e6)).elevation_deg


def time_with_sun_elevation(location: str, day: dt.date, elevation_deg: float) -> dt.datetime:
    """The UTC time after the highest sun of ``day`` (at ``location``) when the sun sinks through ``elevation_deg``."""
    start = dt.datetime(day.year, day.month, day.day) - dt.timedelta(hours=12)
    times = [start + dt.timedelta(minutes=10 * i) for i in range(6 * 48)]  # 48 h: any time zone
    elev = np.array([_elevation(location, t) for t in times])
    peak = 6 * 12 + int(np.argmax(elev[6 * 12:6 * 36]))
    for i in range(peak, len(times) - 1):
        if elev[i] >= elevation_deg > elev[i + 1]:
            lo, hi = times[i], times[i + 1]
            for _ in range(20):  # bisection to about a second
                mid = lo + (hi - lo) / 2
                lo, hi = (mid, hi) if _elevation(location, mid) >= elevation_deg else (lo, mid)
            return lo
    raise ValueError(f"the sun never sinks through {elevation_deg} deg at {location} on {day}")


def facing_a_wall(sample, view, distance_m: float = 4.0):
    """A textured wall ``distance_m`` ahead fills the image, and a LiDAR wall (32-beam-like spacing) matches it."""
    rng = np.random.default_rng(0)
    wall_image = np.clip(rng.normal(120, 20, (view.height, view.width, 3)), 0, 255).astype(np.uint8)
    v = dataclasses.replace(view, _load_image=lambda: wall_image)
    lidar = sample.lidar
    if lidar is None:
        return _with_camera(sample, v)
    xs, ys = np.meshgrid(np.arange(-30, 30, 0.014), np.arange(-3, 1.7, 0.093))
    wall_cam = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, distance_m)], axis=1)
    T_sensor_from_cam = np.linalg.inv(lidar.T_global_from_lidar) @ v.T_global_from_cam
    pts = np.concatenate([lidar.points_sensor, wall_cam @ T_sensor_from_cam[:3, :3].T + T_sensor_from_cam[:3, 3]])
    labels = None if lidar.labels is None else np.concatenate(
        [lidar.labels, np.full(len(wall_cam), 28, lidar.labels.dtype)])  # 28 = static.manmade
    walled = dataclasses.replace(lidar, points_sensor=pts, intensity=np.zeros(len(pts), np.float32), labels=labels)
    s, v = _with_camera(sample, v)
    return dataclasses.replace(s, _load_lidar=lambda: walled), v


def wet_road(sample, view):
    """The upper image mirrored into the road below the horizon (a wet road reflecting sky and buildings)."""
    img = view.image.copy()
    horizon = int(np.clip(view.K[1, 2], 1, view.height - 1))
    n = min(horizon, view.height - horizon)
    img[horizon:horizon + n] = (0.4 * img[horizon:horizon + n] + 0.6 * img[horizon - n:horizon][::-1]).astype(np.uint8)
    return _with_camera(sample, dataclasses.replace(view, _load_image=lambda: img))


def sun_behind_camera(sample, view, elevation_deg: float = 30.0):
    """Afternoon sun at ``elevation_deg``; the ego turned round if needed so that the sun is behind the camera."""
    day = dt.datetime.fromtimestamp(sample.timestamp_us / 1e6, dt.timezone.utc).date()
    s, v = at_time(sample, view, time_with_sun_elevation(sample.location, day, elevation_deg))
    d = v.T_cam_from_global[:3, :3] @ sun_direction_global(s.location, v.timestamp_us).direction_global
    if d[2] > 0:
        v = dataclasses.replace(v, T_global_from_ego=v.T_global_from_ego @ np.diag([-1.0, -1.0, 1.0, 1.0]))
    return _with_camera(s, v)


def failure_cases(sample, view) -> dict[str, tuple[object, object, str]]:
    """Named hard cases built from one sample: name -> (sample, view, what is special)."""
    day = dt.datetime.fromtimestamp(sample.timestamp_us / 1e6, dt.timezone.utc).date()
    loc = sample.location
    lidar = sample.lidar
    equinox_noon = [dt.datetime(day.year, 3, 20) + dt.timedelta(minutes=m) for m in range(0, 24 * 60, 6)]
    zenith_time = max(equinox_noon, key=lambda t: _elevation("singapore-onenorth", t))
    return {
        "night": (*exposure(*at_time(sample, view, time_with_sun_elevation(loc, day, -20.0)), -6.0, None)[:2],
                  "sun 20 deg below the horizon, image 6 EV darker"),
        "night_timestamp_day_image": (*at_time(sample, view, time_with_sun_elevation(loc, day, -20.0)),
                                      "a daylight image whose timestamp says night (wrong clock)"),
        "sun_below_horizon": (*at_time(sample, view, time_with_sun_elevation(loc, day, -0.5)),
                              "sun 0.5 deg below the horizon"),
        "sun_at_horizon": (*at_time(sample, view, time_with_sun_elevation(loc, day, 0.5)),
                           "sun 0.5 deg above the horizon"),
        "sun_at_zenith": (*at_time(sample, view, zenith_time, "singapore-onenorth"),
                          "Singapore, equinox noon: sun near the zenith"),
        "sun_behind_camera": (*sun_behind_camera(sample, view), "sun 30 deg high behind the camera"),
        "facing_a_wall": (*facing_a_wall(sample, view), "a wall 4 m ahead fills the view (image and LiDAR)"),
        "wet_road": (*wet_road(sample, view), "the road mirrors the sky and buildings"),
        "no_lidar": (dataclasses.replace(sample, _load_lidar=lambda: None), view, "no LiDAR sweep"),
        "no_map_no_lidarseg": (
            dataclasses.replace(sample, drivable_area_global=None,
                                _load_lidar=lambda: None if lidar is None else dataclasses.replace(lidar, labels=None)),
            view, "no map expansion and no lidarseg: LiDAR ground only"),
        "nothing_to_place_on": (dataclasses.replace(sample, drivable_area_global=None, _load_lidar=lambda: None), view,
                                "no map, no LiDAR: no road known"),
    }


def run_failure_cases(sample, view, assets, options) -> tuple[list[dict], dict[str, np.ndarray]]:
    """Insert into every failure case; returns (one outcome row per case, case name -> composited image)."""
    rows, images = [], {}
    for name, (s, v, what) in failure_cases(sample, view).items():
        try:
            result = insert_into_view(s, v, assets, options)
        except Exception as e:  # noqa: BLE001 - an error is an outcome here, and must be a clear one
            rows.append({"case": name, "what": what, "outcome": "error", "detail": f"{type(e).__name__}: {e}"})
            continue
        est = result.lighting
        finite = bool(np.isfinite(est.light_cam.envmap).all() and np.isfinite(result.shadow_ratio).all())
        rows.append({
            "case": name, "what": what, "finite": finite,
            "outcome": "inserted" if result.objects else "skipped",
            "detail": result.skipped_reason or f"{len(result.objects)} object(s), visible "
                      + ", ".join(f"{o['visible_fraction']:.2f}" for o in result.objects),
            "sun_source": est.sun_source, "sun_visibility": float(est.sun_visibility), "level": est.level,
            "lighting_reason": est.reason,
        })
        images[name] = _crop_around(result.image, [o["bbox_2d"] for o in result.objects if o["bbox_2d"]])
    return rows, images


def _crop_around(image: np.ndarray, boxes: list, zoom: float = 4.0) -> np.ndarray:
    """A 16:9 crop ``zoom`` times the size of the boxes' union (the whole image without boxes)."""
    if not boxes:
        return image
    H, W = image.shape[:2]
    b = np.asarray(boxes, dtype=float)
    cx, cy = (b[:, 0].min() + b[:, 2].max()) / 2, (b[:, 1].min() + b[:, 3].max()) / 2
    w = min(max((b[:, 2].max() - b[:, 0].min()) * zoom, (b[:, 3].max() - b[:, 1].min()) * zoom * 16 / 9, 320), W)
    h = min(w * 9 / 16, H)
    x0 = int(np.clip(cx - w / 2, 0, W - w))
    y0 = int(np.clip(cy - h / 2, 0, H - h))
    return image[y0:y0 + int(h), x0:x0 + int(w)]


def contact_sheet(rows: list[dict], images: dict[str, np.ndarray], tile_width: int = 360) -> np.ndarray:
    """One tile per case (image + a caption with the case and its outcome), 3 per row, uint8 RGB."""
    tiles = []
    for row in rows:
        img = images.get(row["case"])
        h = int(round(tile_width * 9 / 16))
        tile = np.full((h + 44, tile_width, 3), 255, np.uint8)
        if img is not None:
            tile[:h] = cv2.resize(img, (tile_width, h), interpolation=cv2.INTER_AREA)
        caption = f"{row['case']}: {row['outcome']}"
        sub = row.get("sun_source", "")
        sub = f"sun {sub} vis {row.get('sun_visibility', 0):.2f}; {row['detail']}" if sub else row["detail"]
        cv2.putText(tile, caption, (4, h + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(tile, sub[:62], (4, h + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.36, (60, 60, 60), 1, cv2.LINE_AA)
        tiles.append(tile)
    while len(tiles) % 3:
        tiles.append(np.full_like(tiles[0], 255))
    return np.vstack([np.hstack(tiles[i:i + 3]) for i in range(0, len(tiles), 3)])
