"""The insertion pipeline, stage by stage: sample -> lighting -> placement -> render -> labels.

Each stage is a plain function call on plain data objects (see ``docs``/architecture); this module
only wires them together, times them, and writes the contract's output files.  The CLI is a thin
shell over :func:`insert_into_view`, :func:`insert_into_image` and :func:`write_insert_outputs`.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample

from .assets.asset import Asset
from .conventions import (
    pose_camera_to_transform,
    rotate_vectors,
    transform_points,
)
from .io import InputError, write_exr, write_image_rgb, write_json_atomic
from .lighting.light import DistantLight

LABELS_SCHEMA = "streetaug.labels/1"


@dataclass(frozen=True)
class InsertOptions:
    """Options of one insertion (the CLI maps its flags onto these).

    Attributes:
        quality: render preset, ``draft`` | ``default`` | ``high``.
        level: lighting level, ``L0`` (constant dome) | ``L1`` (sun + parametric sky).
        seed: base seed; per-image seeds derive from (seed, sample token, camera).
        n_objects: how many objects to insert into one image.
        yaw_sigma_deg: Gaussian yaw noise around the ego heading (3 realistic, 15 augmentation).
        ev: exposure of the camera response (contract: LDR = response(HDR * 2^EV)).
    """

    quality: str = "default"
    level: str = "L1"
    seed: int = 0
    n_objects: int = 1
    yaw_sigma_deg: float = 3.0
    ev: float = 0.0


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
    from .render.depth import densify_lidar_depth, ground_plane_depth

    normal, offset = ego_ground_plane_cam(view)
    lidar = sample.lidar
    if lidar is None:
        return ground_plane_depth(view.K, view.width, view.height, normal, offset)
    points_cam = lidar.points_in(view.T_cam_from_global)
    return densify_lidar_depth(points_cam, view.K, view.width, view.height, ground_fill=(normal, offset))


def insert_into_view(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions) -> InsertResult:
    """Insert ``assets`` (one per object) into one camera image of a sample.

    Stages: lighting estimate (camera frame) -> placement on the drivable ground -> render each object
    (occluded by scene depth and by previously inserted objects) -> labels.
    """
    from streetaug.placement.config import PlacementConfig
    from streetaug.placement.labels import object_label
    from streetaug.placement.place import place_objects

    from .lighting.estimate import estimate_lighting
    from .render.insert import render_insertion

    timing: dict[str, float] = {}
    image = view.image  # file decoding is excluded from the contract's "total": decode first
    _ = sample.lidar
    t0 = time.perf_counter()
    rng = item_seed(options.seed, sample.token, view.channel)

    estimate = estimate_lighting(view, sample.location, level=options.level)
    timing["lighting"] = time.perf_counter() - t0

    t = time.perf_counter()
    config = PlacementConfig(yaw_sigma_deg=options.yaw_sigma_deg, n_objects=options.n_objects)
    placement = place_objects(sample, view, [a.wlh for a in assets], rng, config,
                              categories=[a.category for a in assets])
    timing["placement"] = time.perf_counter() - t

    t = time.perf_counter()
    depth_m = scene_depth_for_view(sample, view)
    timing["depth"] = time.perf_counter() - t

    if not placement.placements:
        timing["total"] = time.perf_counter() - t0
        return InsertResult(
            image=image, objects=[], mask=np.zeros(image.shape[:2], np.float32),
            shadow_ratio=np.ones(image.shape[:2], np.float32), timing_s=timing, lighting=estimate,
            placement_report=placement.report, skipped_reason=placement.reason or "no valid placement",
            extras={"placement": placement},
        )

    placed_assets = _assets_of_placements(assets, placement.placements)
    result = _render_objects(
        image, view.K, depth_m, estimate.light_cam, placed_assets,
        [view.T_cam_from_global @ p.T_global_from_object for p in placement.placements],
        [rotate_vectors(view.T_cam_from_global, p.ground_normal_global[None])[0] for p in placement.placements],
        options, rng, timing, render_insertion,
    )
    objects = [
        object_label(T_cam_from_object, asset.wlh, asset.category, view.K, view.width, view.height,
                     ins.mask, ins.coverage, T_global_from_cam=view.T_global_from_cam, attribute=p.attribute)
        for (T_cam_from_object, asset, ins), p in zip(result["objects"], placement.placements)
    ]
    timing["total"] = time.perf_counter() - t0
    return InsertResult(
        image=result["image"], objects=objects, mask=result["mask"], shadow_ratio=result["shadow"],
        timing_s=timing, lighting=estimate, placement_report=placement.report,
        extras={"placement": placement},
    )


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
        image, K, depth_m, light, [asset], [T_cam_from_object], [ground_normal], options,
        item_seed(options.seed, "image"), timing, render_insertion,
    )
    (_, _, ins), = result["objects"]
    objects = [object_label(T_cam_from_object, asset.wlh, asset.category, K, W, H, ins.mask, ins.coverage)]
    timing["total"] = time.perf_counter() - t0
    return InsertResult(result["image"], objects, result["mask"], result["shadow"], timing)


def _render_objects(image, K, depth_m, light, assets, T_cam_from_objects, ground_normals_cam, options, rng, timing, render_insertion) -> dict:
    """Render objects one after the other; each later one is occluded by the earlier ones."""
    mask_union = np.zeros(image.shape[:2], np.float32)
    shadow = np.ones(image.shape[:2], np.float32)
    rendered = []
    t = time.perf_counter()
    for asset, T_cam_from_object, normal in zip(assets, T_cam_from_objects, ground_normals_cam):
        ins = render_insertion(
            image, K, depth_m, light, asset, T_cam_from_object, ground_normal_cam=normal,
            quality=options.quality, ev=options.ev, seed=int(rng.integers(2**31)),
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
    from .conventions import project_points, unproject_depth

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
    "InsertOptions", "InsertResult", "insert_into_view", "insert_into_image", "write_insert_outputs",
    "scene_depth_for_view", "item_seed", "labels_document",
]
