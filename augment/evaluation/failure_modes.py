"""The failure cases behind ``streetaug stability --failure-modes``: hard inputs built from one sample
(night, the sun at the horizon, at the zenith or behind the camera, a wall filling the view, a wet road,
no LiDAR, no map...), each inserted into, with its outcome and a contact sheet.

An error is an outcome here too, and must be a clear one.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from streetaug.datasets.sample import CameraView, Sample

from ..assets.asset import Asset
from ..core import write_image_rgb, write_json_atomic
from ..lighting.sun import sun_direction_global
from ..pipeline import InsertOptions, insert_into_view
from .stability import exposure, with_camera

FAILURE_MODES_SCHEMA = "streetaug.failure_modes/1"

def at_time(sample: Sample, view: CameraView, when_utc: dt.datetime,
            location: str | None = None) -> tuple[Sample, CameraView]:
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


def facing_a_wall(sample: Sample, view: CameraView, distance_m: float = 4.0) -> tuple[Sample, CameraView]:
    """A textured wall ``distance_m`` ahead fills the image, and a LiDAR wall (32-beam-like spacing) matches it."""
    rng = np.random.default_rng(0)
    wall_image = np.clip(rng.normal(120, 20, (view.height, view.width, 3)), 0, 255).astype(np.uint8)
    v = view.with_image(wall_image)
    lidar = sample.lidar
    if lidar is None:
        return with_camera(sample, v)
    xs, ys = np.meshgrid(np.arange(-30, 30, 0.014), np.arange(-3, 1.7, 0.093))
    wall_cam = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, distance_m)], axis=1)
    T_sensor_from_cam = np.linalg.inv(lidar.T_global_from_lidar) @ v.T_global_from_cam
    pts = np.concatenate([lidar.points_sensor, wall_cam @ T_sensor_from_cam[:3, :3].T + T_sensor_from_cam[:3, 3]])
    labels = None if lidar.labels is None else np.concatenate(
        [lidar.labels, np.full(len(wall_cam), 28, lidar.labels.dtype)])  # 28 = static.manmade
    walled = dataclasses.replace(lidar, points_sensor=pts, intensity=np.zeros(len(pts), np.float32), labels=labels)
    s, v = with_camera(sample, v)
    return s.with_lidar(walled), v


def wet_road(sample: Sample, view: CameraView) -> tuple[Sample, CameraView]:
    """The upper image mirrored into the road below the horizon (a wet road reflecting sky and buildings)."""
    img = view.image.copy()
    horizon = int(np.clip(view.K[1, 2], 1, view.height - 1))
    n = min(horizon, view.height - horizon)
    img[horizon:horizon + n] = (0.4 * img[horizon:horizon + n] + 0.6 * img[horizon - n:horizon][::-1]).astype(np.uint8)
    return with_camera(sample, view.with_image(img))


def sun_behind_camera(sample: Sample, view: CameraView, elevation_deg: float = 30.0) -> tuple[Sample, CameraView]:
    """Afternoon sun at ``elevation_deg``; the ego turned round if needed so that the sun is behind the camera."""
    day = dt.datetime.fromtimestamp(sample.timestamp_us / 1e6, dt.timezone.utc).date()
    s, v = at_time(sample, view, time_with_sun_elevation(sample.location, day, elevation_deg))
    d = v.T_cam_from_global[:3, :3] @ sun_direction_global(s.location, v.timestamp_us).direction_global
    if d[2] > 0:
        v = dataclasses.replace(v, T_global_from_ego=v.T_global_from_ego @ np.diag([-1.0, -1.0, 1.0, 1.0]))
    return with_camera(s, v)


def failure_cases(sample: Sample, view: CameraView) -> dict[str, tuple[Sample, CameraView, str]]:
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
        "no_lidar": (sample.with_lidar(None), view, "no LiDAR sweep"),
        "no_map_no_lidarseg": (
            sample.with_lidar(None if lidar is None else dataclasses.replace(lidar, labels=None),
                              drivable_area_global=None),
            view, "no map expansion and no lidarseg: LiDAR ground only"),
        "nothing_to_place_on": (sample.with_lidar(None, drivable_area_global=None), view,
                                "no map, no LiDAR: no road known"),
    }


def run_failure_cases(sample: Sample, view: CameraView, assets: Sequence[Asset],
                      options: InsertOptions) -> tuple[list[dict], dict[str, np.ndarray]]:
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


def write_failure_modes(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions,
                        out_dir: str | Path) -> list[dict]:
    """Run every failure case; write ``failure_modes.json`` and the contact sheet ``failure_modes.jpg``.

    Returns the outcome rows (case, what, outcome, detail, lighting).
    """
    rows, images = run_failure_cases(sample, view, assets, options)
    out_dir = Path(out_dir)
    write_json_atomic(out_dir / "failure_modes.json", {"schema": FAILURE_MODES_SCHEMA, "cases": rows})
    write_image_rgb(out_dir / "failure_modes.jpg", contact_sheet(rows, images))
    return rows
