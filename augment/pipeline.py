"""The insertion pipeline, stage by stage: sample -> placement -> lighting -> render -> labels.

Each stage is a plain function call on plain data objects (see ``docs``/architecture); this module
only wires them together, times them, and writes the contract's output files.

* :func:`insert_into_sample` - several cameras of one sample: objects placed once in the global frame
  and rendered into every camera that sees them or their shadows (what multi-camera detectors need).
* :func:`insert_into_view` - one camera (``streetaug insert``); :func:`insert_into_image` - any image
  with depth, an env map and a pose; :func:`write_insert_outputs` writes the contract's files.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample

from .assets.asset import Asset
from .core import (
    pose_camera_to_transform,
    rotate_vectors,
    transform_points,
)
from .core import InputError, write_exr, write_image_rgb, write_json_atomic
from .lighting.light import DistantLight

LABELS_SCHEMA = "streetaug.labels/1"


@dataclass(frozen=True)
class InsertOptions:
    """Options of one insertion (the CLI maps its flags onto these).

    Attributes:
        quality: render preset, ``draft`` | ``default`` | ``high``.
        level: lighting level, ``L0`` (constant dome) | ``L1`` (sun + parametric sky) | ``L2`` (+ the scene
            volume near the placement) | ``L3`` (full scene volume) | ``auto`` (the cheapest level whose
            predicted error is near the best's, per placement).
        seed: base seed; per-image seeds derive from (seed, sample token, camera).
        n_objects: how many objects to insert into one image.
        yaw_sigma_deg: Gaussian yaw noise around the ego heading (3 realistic, 15 augmentation).
        ev: exposure of the camera response (contract: LDR = response(HDR * 2^EV)).
        match_camera: blur the objects and add noise like the image around them (estimated locally;
            ``RenderSettings.match_camera``), so they are not sharper or cleaner than the photo.
    """

    quality: str = "default"
    level: str = "auto"
    seed: int = 0
    n_objects: int = 1
    yaw_sigma_deg: float = 3.0
    ev: float = 0.0
    match_camera: bool = False


@dataclass(frozen=True)
class InsertResult:
    """What one insertion produced.

    Attributes:
        image: (H, W, 3) uint8 augmented image.
        objects: label dicts (contract ``labels.json`` objects), one per inserted object.
        mask: (H, W) float32 union of the objects' alpha.
        shadow_ratio: (H, W) float32 product of the objects' shadow ratio maps.
        timing_s: seconds per stage and ``total`` (inputs decoded -> outputs ready).
        lighting: the lighting estimate (None for the image form).
        placement_report: rule name -> candidates rejected (None for the image form).
        skipped_reason: set when nothing could be inserted (the image is then unchanged).
    """

    image: np.ndarray
    objects: list[dict]
    mask: np.ndarray
    shadow_ratio: np.ndarray
    timing_s: dict[str, float]
    lighting: object | None = None
    placement_report: dict | None = None
    skipped_reason: str | None = None
    extras: dict = field(default_factory=dict)


def item_seed(seed: int, *keys: str) -> np.random.Generator:
    """A generator seeded from (seed, keys...) independently of worker count, order and Python's hash salt."""
    digest = hashlib.sha256("|".join([str(seed), *keys]).encode()).digest()
    return np.random.default_rng([seed, int.from_bytes(digest[:8], "little")])


def ego_ground_plane_cam(view: CameraView) -> tuple[np.ndarray, float]:
    """The ego's ground plane (ego z = 0) in the camera frame as (normal (3,), offset d): n . p + d = 0."""
    T_cam_from_ego = view.T_cam_from_ego
    normal = rotate_vectors(T_cam_from_ego, np.array([[0.0, 0.0, 1.0]]))[0]
    point = transform_points(T_cam_from_ego, np.zeros((1, 3)))[0]
    return normal, float(-normal @ point)


def scene_depth_for_view(sample: Sample, view: CameraView) -> np.ndarray:
    """Dense metric depth (H, W) for a camera: LiDAR densified, the ground plane where LiDAR is missing."""
    from .core.depth import densify_lidar_depth, ground_plane_depth

    normal, offset = ego_ground_plane_cam(view)
    lidar = sample.lidar
    if lidar is None:
        return ground_plane_depth(view.K, view.width, view.height, normal, offset)
    points_cam = lidar.points_in(view.T_cam_from_global)
    return densify_lidar_depth(points_cam, view.K, view.width, view.height, ground_fill=(normal, offset))


@dataclass(frozen=True)
class SampleInsertResult:
    """What one multi-camera insertion produced: one placement in the global frame, rendered into every camera.

    Attributes:
        views: channel -> :class:`InsertResult` of that camera. A camera that sees neither an inserted
            object nor its shadow keeps its image unchanged, with ``skipped_reason`` set.
        placements: every placed object (``streetaug.placement.place.Placement``, global frame); an
            object's index here is its ``object_index`` in the labels.
        placed_for: (n_objects,) channel in whose view each object was placed.
        assets: (n_objects,) the asset of each placement.
        placement_results: channel -> ``PlacementResult`` of the objects placed in that view.
        visible_px, coverage_px: (n_objects,) float visible / total (unoccluded) object pixels, summed over
            the rendered cameras (their ratio is the object's visibility across cameras, as in nuScenes).
        lighting: channel -> lighting estimate of that camera.
        skipped_reason: set when no object could be placed in any view.
        timing_s: seconds of the sample-level stages (``lighting``, ``placement``) and ``total``.
    """

    views: dict[str, InsertResult]
    placements: list
    placed_for: list[str]
    assets: list[Asset]
    placement_results: dict
    visible_px: np.ndarray
    coverage_px: np.ndarray
    lighting: dict
    skipped_reason: str | None
    timing_s: dict[str, float]


def sample_lighting(sample: Sample, views: Sequence[CameraView], level: str,
                    points_cam: dict[str, np.ndarray] | None = None) -> dict[str, object]:
    """The lighting of a sample, built once from all ``views`` and expressed in each camera's frame
    (channel -> ``LightingEstimate``): one sun, sky and scene volume shared by the cameras, so that
    the same car is lit the same in every camera.  The one place the pipeline estimates lighting.

    ``points_cam``: channel -> (3,) placement in that camera's frame; the first view's point is where
    L2 centres its volume and where ``auto`` judges the level.
    """
    from .lighting.multiview import estimate_views_lighting

    points_cam = points_cam or {}
    shared = estimate_views_lighting(list(views), sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                     query_point_cam=points_cam.get(views[0].channel))
    return {view.channel: shared.for_view(view) for view in views}


def object_light(estimate, center_cam: np.ndarray) -> DistantLight:
    """The distant light an object centred at ``center_cam`` (3,) (camera frame, metres) is shaded with:
    the estimate's local light there (L2/L3 volume; L0/L1: the same light everywhere)."""
    return estimate.light_at(np.asarray(center_cam, dtype=np.float64))


def place_in_view(sample: Sample, view: CameraView, assets: Sequence[Asset], placed: Sequence, options: InsertOptions):
    """Place ``assets`` in ``view``, clear (as dynamic boxes) of the objects ``placed`` for other cameras.

    Seeded by (seed, sample token, channel). Returns the ``PlacementResult``.
    """
    from streetaug.placement.config import PlacementConfig
    from streetaug.placement.place import place_objects

    if placed:  # earlier objects count as annotated vehicles (3 m clearance); LiDAR is shared, not re-read
        sample = replace(sample, boxes=sample.boxes + tuple(p.box for p in placed),
                         _load_lidar=lambda s=sample: s.lidar)
    config = PlacementConfig(yaw_sigma_deg=options.yaw_sigma_deg, n_objects=len(assets))
    return place_objects(sample, view, [a.wlh for a in assets], item_seed(options.seed, sample.token, view.channel),
                         config, categories=[a.category for a in assets])


@dataclass(frozen=True)
class SamplePlacement:
    """Objects placed for several cameras of one sample (global frame).

    Attributes:
        placements: every placed object, in placement order (= object index).
        placed_for: channel in whose view each object was placed.
        assets: the asset of each object.
        results: channel -> ``PlacementResult`` (candidates, rule report, reason).
        seconds: channel -> seconds spent placing in that view.
    """

    placements: list
    placed_for: list[str]
    assets: list[Asset]
    results: dict
    seconds: dict[str, float]

    @property
    def reason(self) -> str | None:
        """Why nothing was placed (None when something was)."""
        if self.placements:
            return None
        return "; ".join(f"{ch}: {r.reason}" for ch, r in self.results.items() if r.reason) or "no valid placement"


def place_in_sample(sample: Sample, views: Sequence[CameraView], assets_by_channel: dict[str, Sequence[Asset]],
                    options: InsertOptions) -> SamplePlacement:
    """Place each view's assets in that view in turn, each object clear of those placed before."""
    placements, placed_for, placed_assets, results, seconds = [], [], [], {}, {}
    for view in views:
        t = time.perf_counter()
        assets = list(assets_by_channel.get(view.channel, ()))
        if assets:
            res = place_in_view(sample, view, assets, placements, options)
            results[view.channel] = res
            for p, asset in zip(res.placements, _assets_of_placements(assets, res.placements)):
                placements.append(p)
                placed_for.append(view.channel)
                placed_assets.append(asset)
        seconds[view.channel] = time.perf_counter() - t
    return SamplePlacement(placements, placed_for, placed_assets, results, seconds)


def insert_into_sample(
    sample: Sample, views: Sequence[CameraView], assets_by_channel: dict[str, Sequence[Asset]], options: InsertOptions,
) -> SampleInsertResult:
    """Insert objects into several cameras of one sample consistently (the same cars, seen by every camera).

    Stages: placement in each view in turn (each object clear of those placed before) -> lighting per
    sample -> for each camera: scene depth, render every object or shadow in its view (occluded by the
    camera's scene depth and by the other objects) -> labels.

    Args:
        views: the cameras to augment; objects are placed in each view's field of view.
        assets_by_channel: channel -> the assets to place in that view (may be empty).
    """
    render_settings(options)  # a bad preset fails before any work
    from .lighting import multiview  # noqa: F401 - heavy first import (torch): start-up, not per-image work

    t_start = time.perf_counter()
    for view in views:  # file decoding is excluded from the contract's "total": decode first
        _ = view.image
    _ = sample.lidar
    t0 = time.perf_counter()
    placed = place_in_sample(sample, views, assets_by_channel, options)
    t = time.perf_counter()
    first = {ch: p for p, ch in reversed(list(zip(placed.placements, placed.placed_for)))}  # first per view
    points_cam = {v.channel: (v.T_cam_from_global @ first[v.channel].T_global_from_object)[:3, 3]
                  for v in views if v.channel in first}
    lighting = sample_lighting(sample, views, options.level, points_cam)
    lighting_s = (time.perf_counter() - t) / max(len(views), 1)

    n = len(placed.placements)
    visible_px, coverage_px = np.zeros(n), np.zeros(n)
    out: dict[str, InsertResult] = {}
    for view in views:
        timing = {"lighting": lighting_s, "placement": placed.seconds[view.channel]}
        out[view.channel] = _render_view(sample, view, placed, lighting[view.channel], options, timing,
                                         visible_px, coverage_px)
    timing_s = {"lighting": lighting_s * len(views), "placement": sum(placed.seconds.values()),
                "total": time.perf_counter() - t0, "with_decode": time.perf_counter() - t_start}
    return SampleInsertResult(out, placed.placements, placed.placed_for, placed.assets, placed.results, visible_px,
                              coverage_px, lighting, placed.reason, timing_s)


def _render_view(sample: Sample, view: CameraView, placed: SamplePlacement, estimate, options: InsertOptions,
                 timing: dict, visible_px: np.ndarray, coverage_px: np.ndarray) -> InsertResult:
    """Render every placed object (or its shadow) that reaches ``view``; accumulate visible/coverage pixels."""
    from streetaug.placement.labels import object_label

    from .render.insert import render_insertion

    placements, placed_for, assets = placed.placements, placed.placed_for, placed.assets
    placement_result = placed.results.get(view.channel)
    t0 = time.perf_counter()
    image = view.image
    T_cam_from_global = view.T_cam_from_global
    poses = [T_cam_from_global @ p.T_global_from_object for p in placements]
    t = time.perf_counter()
    lights = [object_light(estimate, T[:3, 3] + 0.5 * p.wlh[2] * T[:3, 2]) for T, p in zip(poses, placements)]
    timing["local_light"] = time.perf_counter() - t  # each object's environment at its centre (L2/L3: Eq. 1)
    shown = [i for i in range(len(placements)) if _reaches_view(view, assets[i], poses[i], lights[i], options.quality)]
    report = None if placement_result is None else placement_result.report
    extras = {"placement": placement_result}
    if not shown:
        own = placement_result.reason if placement_result is not None else None
        if own and placements:
            reason = f"{own}; no other camera's object or shadow in view"
        elif own or placement_result is not None:
            reason = own or "no valid placement"
        else:
            reason = "no inserted object or shadow in view" if placements else "no object placed in this sample"
        timing["total"] = timing["lighting"] + timing["placement"] + time.perf_counter() - t0
        return InsertResult(image=image, objects=[], mask=np.zeros(image.shape[:2], np.float32),
                            shadow_ratio=np.ones(image.shape[:2], np.float32), timing_s=timing, lighting=estimate,
                            placement_report=report, skipped_reason=reason, extras=extras)
    t = time.perf_counter()
    depth_m = scene_depth_for_view(sample, view)
    timing["depth"] = time.perf_counter() - t
    rng = item_seed(options.seed, "render", sample.token, view.channel)
    normals = [rotate_vectors(T_cam_from_global, placements[i].ground_normal_global[None])[0] for i in shown]
    result = _render_objects(image, view.K, depth_m, [lights[i] for i in shown], [assets[i] for i in shown],
                             [poses[i] for i in shown], normals, options, rng, timing, render_insertion)
    objects = []
    for i, (T_cam_from_object, asset, ins) in zip(shown, result["objects"]):
        coverage = float(ins.coverage.sum())
        visible_px[i] += float(ins.mask.sum())
        coverage_px[i] += coverage
        if coverage <= 0:  # only its shadow reaches this camera
            continue
        label = object_label(T_cam_from_object, asset.wlh, asset.category, view.K, view.width, view.height,
                             ins.mask, ins.coverage, T_global_from_cam=view.T_global_from_cam,
                             attribute=placements[i].attribute)
        label.update(object_index=i, placed_for=placed_for[i])
        objects.append(label)
    timing["total"] = timing["lighting"] + timing["placement"] + time.perf_counter() - t0
    return InsertResult(image=result["image"], objects=objects, mask=result["mask"], shadow_ratio=result["shadow"],
                        timing_s=timing, lighting=estimate, placement_report=report, extras=extras)


def _reaches_view(view: CameraView, asset: Asset, T_cam_from_object: np.ndarray, light: DistantLight,
                  quality: str) -> bool:
    """Whether the object or its shadow can touch any pixel of ``view`` (the renderer's own pixel boxes)."""
    from .render.geometry import prepare_asset
    from .render.settings import QUALITY_PRESETS
    from .render.shade import object_pixel_box
    from .render.shadow import shadow_pixel_box

    prep = prepare_asset(asset)
    W, H = view.width, view.height
    return (object_pixel_box(view.K, W, H, T_cam_from_object, prep.box_corners_object) is not None
            or shadow_pixel_box(view.K, W, H, T_cam_from_object, prep, light, QUALITY_PRESETS[quality]) is not None)


def insert_into_view(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions) -> InsertResult:
    """Insert ``assets`` (one per object) into one camera image of a sample (see :func:`insert_into_sample`)."""
    result = insert_into_sample(sample, [view], {view.channel: assets}, options)
    out = result.views[view.channel]
    if result.skipped_reason:
        return replace(out, skipped_reason=result.skipped_reason)
    return out


def _assets_of_placements(assets: Sequence[Asset], placements: Sequence) -> list[Asset]:
    """The asset of each placement (placement may drop objects it could not place; sizes identify them)."""
    unused = list(assets)
    out = []
    for p in placements:
        i = next(i for i, a in enumerate(unused) if np.allclose(a.wlh, p.wlh))
        out.append(unused.pop(i))
    return out


def insert_into_image(
    image: np.ndarray, K: np.ndarray, depth_m: np.ndarray, envmap_cam: np.ndarray, asset: Asset,
    pose_camera: Sequence[float], options: InsertOptions,
) -> InsertResult:
    """The contract's second ``insert`` form: any image + metric depth + camera-frame env map + pose.

    Args:
        image: (H, W, 3) uint8 RGB.
        K: (3, 3) intrinsics.
        depth_m: (H, W) camera-z depth in metres (inf / 0 / nan = unknown, treated as far).
        envmap_cam: (h, w, 3) linear HDR equirect map in the camera-frame convention (distant light).
        pose_camera: (X, Y, Z, YAW_DEG): bottom centre of the box on the ground, camera frame.
    """
    from streetaug.placement.labels import object_label

    from .render.insert import render_insertion

    H, W = image.shape[:2]
    if depth_m.shape != (H, W):
        raise InputError(f"depth map: expected shape ({H}, {W}) like the image, got {depth_m.shape}")
    depth_m = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, np.inf).astype(np.float32)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    light = DistantLight.from_envmap(envmap_cam)
    timing["lighting"] = time.perf_counter() - t0
    T_cam_from_object = pose_camera_to_transform(*pose_camera)
    ground_normal = _ground_normal_from_depth(K, depth_m, T_cam_from_object, asset)
    result = _render_objects(
        image, K, depth_m, [light], [asset], [T_cam_from_object], [ground_normal], options,
        item_seed(options.seed, "image"), timing, render_insertion,
    )
    (_, _, ins), = result["objects"]
    objects = [object_label(T_cam_from_object, asset.wlh, asset.category, K, W, H, ins.mask, ins.coverage)]
    timing["total"] = time.perf_counter() - t0
    return InsertResult(result["image"], objects, result["mask"], result["shadow"], timing)


def render_settings(options: InsertOptions):
    """The render preset of ``options.quality`` with ``options.match_camera`` applied."""
    from .render.settings import resolve_settings

    return replace(resolve_settings(options.quality), match_camera=options.match_camera)


def _render_objects(image, K, depth_m, lights, assets, T_cam_from_objects, ground_normals_cam, options, rng, timing,
                    render_insertion) -> dict:
    """Render objects one after the other (each with its light); each later one is occluded by the earlier ones."""
    mask_union = np.zeros(image.shape[:2], np.float32)
    shadow = np.ones(image.shape[:2], np.float32)
    rendered = []
    settings = render_settings(options)
    t = time.perf_counter()
    for light, asset, T_cam_from_object, normal in zip(lights, assets, T_cam_from_objects, ground_normals_cam):
        ins = render_insertion(
            image, K, depth_m, light, asset, T_cam_from_object, ground_normal_cam=normal,
            quality=settings, ev=options.ev, seed=int(rng.integers(2**31)),
        )
        for stage, seconds in ins.timing_s.items():
            if stage != "total":
                timing[f"render.{stage}"] = timing.get(f"render.{stage}", 0.0) + seconds
        image = ins.image
        depth_m = np.where(ins.mask > 0.5, np.minimum(depth_m, ins.object_depth_m), depth_m)
        mask_union = np.maximum(mask_union, ins.mask)
        shadow = shadow * ins.shadow_ratio
        rendered.append((T_cam_from_object, asset, ins))
    timing["render"] = time.perf_counter() - t
    return {"image": image, "mask": mask_union, "shadow": shadow, "objects": rendered}


def _ground_normal_from_depth(K: np.ndarray, depth_m: np.ndarray, T_cam_from_object: np.ndarray, asset: Asset) -> np.ndarray:
    """Ground normal under the object from the depth map (least-squares plane), default camera up (-y)."""
    from .core import project_points, unproject_depth

    up = np.array([0.0, -1.0, 0.0])
    H, W = depth_m.shape
    l, w = asset.wlh[1], asset.wlh[0]
    gx, gy = np.meshgrid(np.linspace(-l, l, 9), np.linspace(-w, w, 9))
    pts_obj = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    uv, z = project_points(K, transform_points(T_cam_from_object, pts_obj))
    ok = np.isfinite(uv).all(axis=1) & (z > 0)
    ij = np.round(uv[ok]).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    ij = ij[inside]
    if len(ij) < 6:
        return up
    d = depth_m[ij[:, 1], ij[:, 0]]
    good = np.isfinite(d)
    if good.sum() < 6:
        return up
    p = unproject_depth(K, ij[good].astype(float), d[good])
    centred = p - p.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    normal = normal if normal @ up > 0 else -normal
    # Only trust a plane that is close to horizontal; depth noise must not tilt the car.
    return normal if normal @ up > np.cos(np.radians(15)) else up


def labels_document(result: InsertResult, image_name: str) -> dict:
    """The contract's labels.json content."""
    doc = {"schema": LABELS_SCHEMA, "image": image_name, "objects": result.objects, "timing_s": result.timing_s}
    if result.skipped_reason:
        doc["skipped_reason"] = result.skipped_reason
    if result.placement_report is not None:
        doc["placement_report"] = result.placement_report
    if result.lighting is not None:
        doc["lighting"] = {"level": result.lighting.level, "sun_source": result.lighting.sun_source,
                           "sun_visibility": result.lighting.sun_visibility, "reason": result.lighting.reason}
    return doc


def write_insert_outputs(result: InsertResult, out_dir: str | Path, image_suffix: str = ".png", debug: bool = False) -> Path:
    """Write ``image.png|jpg`` and ``labels.json`` (and with ``debug`` the mask and shadow maps) atomically."""
    out_dir = Path(out_dir)
    image_name = "image" + (".jpg" if image_suffix.lower() in (".jpg", ".jpeg") else ".png")
    write_image_rgb(out_dir / image_name, result.image)
    if debug:
        write_image_rgb(out_dir / "mask.png", np.clip(np.round(result.mask * 255), 0, 255).astype(np.uint8))
        write_exr(out_dir / "shadow.exr", result.shadow_ratio.astype(np.float32))
    # labels.json last: its presence marks the output as complete.
    write_json_atomic(out_dir / "labels.json", labels_document(result, image_name))
    return out_dir / image_name


__all__ = [
    "InsertOptions", "InsertResult", "SampleInsertResult", "insert_into_sample", "insert_into_view",
    "insert_into_image", "write_insert_outputs", "sample_lighting", "place_in_view",
    "scene_depth_for_view", "item_seed", "labels_document",
]
