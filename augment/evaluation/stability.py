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
  measured, not the perturbation itself), over the pixels the insertion changed in either run;
* ``lighting_psnr_db`` (families that scale the image's radiance, ``Family.radiance_gain``: exposure): PSNR
  of the perturbed run's composite against the same objects rendered into the same perturbed image under the
  unperturbed lighting times that gain (what a perfectly stable estimate gives: the map follows the image's
  exposure by design), over the pixels either changed. The renderer's own reaction to the image (its camera
  matching: noise and blur measured around the object) is the same in both, so this measures the lighting
  estimate alone; ``composite_psnr_db`` measures both (with a perfectly scaled lighting it reaches only about
  27 / 33 dB at -1 / +1 EV on the bundled sunny sample's default placement at L1, 27 / 29 at L2).

Conventions: perturbations are deterministic given their strength and ``seed``; a perturbation of the
calibration changes what the pipeline *believes* (K or T_ego_from_cam), not the pixels.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from streetaug.datasets.sample import CameraView, Sample
from streetaug.placement.place import Placement

from ..assets.asset import Asset
from ..core import atomic_path, hdr_to_ldr_uint8, ldr_uint8_to_hdr, make_transform, write_json_atomic
from ..lighting.api import estimate_lighting_from_image
from ..lighting.light import DistantLight
from ..lighting.types import LightingEstimate
from ..lighting.types import SampleLighting
from ..pipeline import InsertOptions, InsertResult
from ..pipeline.results import SampleInsertResult
from ..pipeline.sample import insert_into_sample, insert_placed_into_sample
from .metrics import psnr_db

ImageFn = Callable[[np.ndarray], np.ndarray]  # (H, W, 3) uint8 -> the same image perturbed
Perturbed = tuple[Sample, CameraView, ImageFn]
PerturbFn = Callable[[Sample, CameraView, float, np.random.Generator], Perturbed]


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
    radiance_gain: Callable[[float], float] | None = None  # strength -> the factor on the image's radiance


def _with_image(sample: Sample, view: CameraView, image_fn: ImageFn) -> Perturbed:
    image = image_fn(view.image)
    new_view = view.with_image(image)
    return (*with_camera(sample, new_view), image_fn)


def with_camera(sample: Sample, view: CameraView) -> tuple[Sample, CameraView]:
    """``(sample with view replacing its camera of that channel, view)``."""
    return dataclasses.replace(sample, cameras=dict(sample.cameras, **{view.channel: view})), view


def _with_lidar(sample: Sample, view: CameraView,
                points_fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]) -> Perturbed:
    lidar = sample.lidar
    if lidar is None:
        return sample, view, _identity
    points, keep = points_fn(lidar.points_sensor)
    new = dataclasses.replace(
        lidar, points_sensor=points, intensity=lidar.intensity[keep],
        labels=None if lidar.labels is None else lidar.labels[keep],
    )
    return sample.with_lidar(new), view, _identity


def _identity(image: np.ndarray) -> np.ndarray:
    return image


def exposure(sample: Sample, view: CameraView, ev: float, rng: np.random.Generator | None) -> Perturbed:
    """The image as if exposed ``ev`` stops brighter (through the contract's camera response)."""
    return _with_image(sample, view, lambda im: hdr_to_ldr_uint8(ldr_uint8_to_hdr(im) * 2.0**ev))


def sensor_noise(sample: Sample, view: CameraView, sigma_8bit: float, rng: np.random.Generator | None) -> Perturbed:
    """Additive Gaussian noise of ``sigma_8bit`` grey levels (fixed pattern for a given rng)."""
    noise = rng.normal(0.0, sigma_8bit, size=(view.height, view.width, 3))
    return _with_image(sample, view, lambda im: np.clip(np.round(im + noise), 0, 255).astype(np.uint8))


def jpeg(sample: Sample, view: CameraView, quality: float, rng: np.random.Generator | None) -> Perturbed:
    """JPEG re-compression at ``quality`` (0-100)."""

    def fn(im: np.ndarray) -> np.ndarray:
        ok, buf = cv2.imencode(".jpg", im[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()

    return _with_image(sample, view, fn)


def focal_error(sample: Sample, view: CameraView, percent: float, rng: np.random.Generator | None) -> Perturbed:
    """The calibration claims a focal length ``percent`` % too long (pixels unchanged)."""
    K = view.K.copy()
    K[0, 0] *= 1 + percent / 100.0
    K[1, 1] *= 1 + percent / 100.0
    new_view = dataclasses.replace(view, K=K)
    return (*with_camera(sample, new_view), _identity)


def calibration_error(sample: Sample, view: CameraView, degrees: float, rng: np.random.Generator | None) -> Perturbed:
    """The calibration's camera rotation is off by ``degrees`` about a fixed random axis."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R, _ = cv2.Rodrigues(axis * np.radians(degrees))
    T = view.T_ego_from_cam @ make_transform(R, [0.0, 0.0, 0.0])
    new_view = dataclasses.replace(view, T_ego_from_cam=T)
    return (*with_camera(sample, new_view), _identity)


def depth_bias(sample: Sample, view: CameraView, percent: float, rng: np.random.Generator | None) -> Perturbed:
    """Every LiDAR range scaled by 1 + ``percent`` / 100 (a range bias)."""
    return _with_lidar(sample, view, lambda p: (p * (1 + percent / 100.0), slice(None)))


def depth_noise(sample: Sample, view: CameraView, sigma_m: float, rng: np.random.Generator | None) -> Perturbed:
    """Gaussian range noise of ``sigma_m`` metres on every LiDAR point."""

    def fn(p):
        r = np.linalg.norm(p, axis=1, keepdims=True)
        scale = 1.0 + rng.normal(0.0, sigma_m, size=(len(p), 1)) / np.maximum(r, 1e-6)
        return p * scale, slice(None)

    return _with_lidar(sample, view, fn)


def lidar_dropout(sample: Sample, view: CameraView, percent: float, rng: np.random.Generator | None) -> Perturbed:
    """A random ``percent`` % of the LiDAR points removed."""

    def fn(p):
        keep = rng.random(len(p)) >= percent / 100.0
        return p[keep], keep

    return _with_lidar(sample, view, fn)


def _families() -> dict[str, Family]:
    fams = (
        Family("exposure", "EV", (-1.0, -0.5, 0.5, 1.0), exposure, lambda ev: 2.0**ev),
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


def envmap_change(light_a: DistantLight, light_b: DistantLight, height: int = 64, width: int = 128) -> float:
    """RMS difference of log(1 + radiance) between two lights' full environments."""
    ea = np.log1p(np.maximum(light_a.to_envmap(height, width), 0.0))
    eb = np.log1p(np.maximum(light_b.to_envmap(height, width), 0.0))
    return float(np.sqrt(np.mean((ea - eb) ** 2)))


def _affected(result: InsertResult, source: np.ndarray) -> np.ndarray:
    return (result.mask > 0.01) | (result.shadow_ratio < 0.995) | (np.abs(result.image.astype(int) - source).max(-1) > 2)


def _first_box(result: InsertResult) -> Placement | None:
    placement = result.placement
    if placement is None or not placement.placements:
        return None
    return placement.placements[0]


# ----------------------------------------------------------------------------- the report


def measure(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions, family: Family,
            strength: float, baseline: Baseline | None = None, seed: int = 0) -> dict:
    """One perturbation at one strength vs the unperturbed run (``baseline`` = (result, image_lighting))."""
    if baseline is None:
        baseline = run_once(sample, view, assets, options)
    base, base_image_light = baseline[0], baseline[1]
    base_sample = baseline[2] if len(baseline) > 2 else None
    rng = np.random.default_rng([seed, zlib.crc32(family.name.encode()), int(round(abs(strength) * 1000))])
    p_sample, p_view, image_fn = family.apply(sample, view, strength, rng)
    t = time.perf_counter()
    result = _insert_one(p_sample, p_view, assets, options)
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
    row["lighting_psnr_db"] = None
    if family.radiance_gain is not None and base_sample is not None and base_sample.placements and result.objects:
        ideal = insert_placed_into_sample(
            p_sample, [p_view], base_sample.placements, base_sample.assets, options,
            lighting=scaled_lighting(base_sample.shared_lighting, family.radiance_gain(strength))).views[p_view.channel]
        changed = _affected(ideal, p_view.image) | _affected(result, p_view.image)
        row["lighting_psnr_db"] = psnr_db(ideal.image, result.image, changed)
    row["finite"] = bool(np.isfinite(result.lighting.light_cam.envmap).all() and np.isfinite(result.shadow_ratio).all())
    return row


def scaled_lighting(lighting: SampleLighting, gain: float) -> SampleLighting:
    """A sample's lighting with every radiance (maps, sun, volume) times ``gain``: what a perfectly stable
    estimate gives for the sample's images ``gain`` times brighter."""
    k = float(gain)
    if lighting.level in ("L0", "L1"):
        per_view = {}
        for channel, est in lighting.per_view.items():
            light = est.light_cam
            sun = None if light.sun is None else dataclasses.replace(light.sun, irradiance_rgb=np.asarray(
                light.sun.irradiance_rgb) * k)
            per_view[channel] = dataclasses.replace(est, light_cam=dataclasses.replace(
                light, envmap=(light.envmap * np.float32(k)).astype(np.float32), sun=sun))
        return dataclasses.replace(lighting, per_view=per_view)
    # L2 / L3: a camera's image units per volume unit (its exposure ratio) scale its map, sun and local light
    return dataclasses.replace(lighting, exposure_ratio={c: r * k for c, r in lighting.exposure_ratio.items()})


def _insert_sample(sample: Sample, view: CameraView, assets: Sequence[Asset],
                   options: InsertOptions) -> SampleInsertResult:
    return insert_into_sample(sample, [view], {view.channel: assets}, options)


def _insert_one(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions) -> InsertResult:
    """:func:`streetaug.augment.pipeline.insert_into_view` (the same result)."""
    return _view_result(_insert_sample(sample, view, assets, options), view)


def _view_result(result: SampleInsertResult, view: CameraView) -> InsertResult:
    out = result.views[view.channel]
    return dataclasses.replace(out, skipped_reason=result.skipped_reason) if result.skipped_reason else out


# the insertion, the single-image lighting of the same view and (optional) the sample-level insertion (its
# placements and shared lighting: ``lighting_psnr_db``)
Baseline = tuple[InsertResult, LightingEstimate] | tuple[InsertResult, LightingEstimate, SampleInsertResult]


def run_once(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions) -> Baseline:
    """The unperturbed insertion, single-image lighting and sample-level insertion (the report's baseline)."""
    whole = _insert_sample(sample, view, assets, options)
    return _view_result(whole, view), estimate_lighting_from_image(view.image, view.K), whole


def stability_report(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions, families: Sequence[str] | None = None,
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


def plot_report(report: dict, path: str | Path) -> None:
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


def write_stability_report(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions,
                           out_dir: str | Path, families: Sequence[str] | None = None, seed: int = 0) -> dict:
    """:func:`stability_report` written as ``stability.json`` and its curves ``stability.png``; returns the report."""
    report = stability_report(sample, view, assets, options, families, seed=seed)
    out_dir = Path(out_dir)
    write_json_atomic(out_dir / "stability.json", report)
    plot_report(report, out_dir / "stability.png")
    return report
