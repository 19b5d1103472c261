"""One camera of a sample: render every object placed in the sample (or its shadow) that reaches it."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from streetaug.datasets.sample import CameraView
from streetaug.placement.labels import object_label
from streetaug.placement.place import PlacementResult

from ..core import invert_transform, rotate_vectors, transform_points
from ..lighting.types import LightingEstimate
from ..render.camera_look import jpeg_quality_from_file
from .context import ViewContext, object_light
from .objects import reaches_view, render_objects
from .options import InsertOptions, item_seed
from .place import SamplePlacement
from .results import InsertResult


@dataclass(frozen=True)
class ViewInsertion:
    """What rendering a sample's objects into one camera produced.

    Attributes:
        result: the camera's augmented image and labels.
        visible_px, coverage_px: (n_objects,) float64 visible / unoccluded pixels of each object of the
            sample in this camera (0 for the objects it does not see).
    """

    result: InsertResult
    visible_px: np.ndarray
    coverage_px: np.ndarray


def velocity_in_camera_mps(view: CameraView, point_global: np.ndarray, velocity_global_mps: np.ndarray) -> np.ndarray | None:
    """(3,) velocity (m/s, camera frame) of a point moving at ``velocity_global_mps`` (3,) as the moving
    camera of ``view`` sees it (the ego's translation and turning included), or None when the ego's motion
    is unknown (a single frame).

    The camera-frame position is differenced between the ego poses around the capture
    (``view.ego_poses_around``), the point moving linearly in the global frame meanwhile.
    """
    if view.ego_poses_around is None:
        return None
    p = np.asarray(point_global, np.float64).reshape(3)
    v = np.asarray(velocity_global_mps, np.float64).reshape(3)
    (t0, T0), (t1, T1) = view.ego_poses_around
    p0 = transform_points(invert_transform(T0 @ view.T_ego_from_cam), (p + v * t0)[None])[0]
    p1 = transform_points(invert_transform(T1 @ view.T_ego_from_cam), (p + v * t1)[None])[0]
    return (p1 - p0) / (t1 - t0)


def _jpeg_quality(view: CameraView) -> int | None:
    """The source file's JPEG quality (None: not a JPEG, or unreadable: the look then skips re-encoding)."""
    try:
        return jpeg_quality_from_file(view.image_path)
    except (OSError, ValueError):
        return None


def skip_reason(placement: PlacementResult | None, n_placed: int) -> str:
    """Why a camera shows none of the sample's ``n_placed`` objects nor their shadows."""
    own = placement.reason if placement is not None else None
    if own and n_placed:
        return f"{own}; no other camera's object or shadow in view"
    if own or placement is not None:
        return own or "no valid placement"
    return "no inserted object or shadow in view" if n_placed else "no object placed in this sample"


def _object_velocity(placed: SamplePlacement, i: int) -> np.ndarray:
    """(3,) global velocity (m/s) of object ``i``: its track's (``label_fields['velocity']``), else 0 (parked)."""
    fields = placed.label_fields[i] if placed.label_fields else {}
    v = fields.get("velocity")
    return np.zeros(3) if v is None else np.asarray(v, np.float64).reshape(3)


def render_into_view(context: ViewContext, token: str, placed: SamplePlacement, estimate: LightingEstimate,
                     options: InsertOptions, timing: dict[str, float]) -> ViewInsertion:
    """Render every placed object (or its shadow) that reaches the camera of ``context``.

    Args:
        token: the sample token (seeds the render).
        estimate: the sample's lighting in this camera's frame.
        timing: the sample-level seconds of this camera (``lighting``, ``placement``); completed here.
    """
    view = context.view
    placements, assets = placed.placements, placed.assets
    placement = placed.results.get(view.channel)
    n = len(placements)
    visible_px, coverage_px = np.zeros(n), np.zeros(n)
    t0 = time.perf_counter()
    image = view.image
    T_cam_from_global = view.T_cam_from_global
    poses = [T_cam_from_global @ p.T_global_from_object for p in placements]
    t = time.perf_counter()
    lights = [object_light(estimate, T[:3, 3] + 0.5 * p.wlh[2] * T[:3, 2]) for T, p in zip(poses, placements)]
    timing["local_light"] = time.perf_counter() - t  # each object's environment at its centre (L2/L3: Eq. 1)
    shown = [i for i in range(n) if reaches_view(context.camera, assets[i], poses[i], lights[i], options)]
    if not shown:
        timing["total"] = timing["lighting"] + timing["placement"] + time.perf_counter() - t0
        result = InsertResult.of(image, [], None, None, timing, lighting=estimate, placement=placement,
                                 skipped_reason=skip_reason(placement, n))
        return ViewInsertion(result, visible_px, coverage_px)
    t = time.perf_counter()
    depth_m = context.depth_m
    timing["depth"] = time.perf_counter() - t
    rng = item_seed(options.seed, "render", token, view.channel)
    normals = [rotate_vectors(T_cam_from_global, placements[i].ground_normal_global[None])[0] for i in shown]
    velocities = [velocity_in_camera_mps(view, placements[i].box.center, _object_velocity(placed, i))
                  for i in shown] if options.match_camera else None
    jpeg_quality = _jpeg_quality(view) if options.match_camera else None
    rendered = render_objects(image, view.K, depth_m, [lights[i] for i in shown], [assets[i] for i in shown],
                              [poses[i] for i in shown], normals, options, rng, timing, velocities, jpeg_quality)
    objects = []
    for i, obj in zip(shown, rendered.objects):
        visible_px[i] = obj.visible_px
        coverage_px[i] = obj.coverage_px
        if obj.coverage_px <= 0:  # only its shadow reaches this camera
            continue
        label = object_label(obj.T_cam_from_object, obj.asset.wlh, obj.asset.category, context.camera,
                             obj.full_mask(), obj.full_coverage(), T_global_from_cam=view.T_global_from_cam,
                             attribute=placements[i].attribute)
        label.update(object_index=i, placed_for=placed.placed_for[i])
        if placed.label_fields:
            label.update(placed.label_fields[i])
        objects.append(label)
    timing["total"] = timing["lighting"] + timing["placement"] + time.perf_counter() - t0
    result = InsertResult.of(rendered.image, objects, rendered.mask, rendered.shadow_ratio, timing, lighting=estimate,
                             placement=placement)
    return ViewInsertion(result, visible_px, coverage_px)
