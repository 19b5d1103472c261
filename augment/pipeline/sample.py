"""All cameras of a sample: objects placed once in the global frame, lit by the sample's one lighting, and
rendered into every camera that sees them or their shadows (what multi-camera detectors need)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample
from streetaug.placement.place import Placement

from ..assets.asset import Asset
from ..lighting.api import estimate_views_lighting
from ..lighting.types import LightingEstimate
from .context import SampleContext
from .memory import check_insert_memory
from .options import InsertOptions, render_settings
from .place import SamplePlacement, place_in_sample
from .results import InsertResult, SampleInsertResult
from .view import render_into_view


def shared_sample_lighting(sample: Sample, views: Sequence[CameraView], level: str,
                           points_cam: dict[str, np.ndarray] | None = None):
    """The lighting of a sample built once from all ``views`` (a ``SampleLighting``: ``.for_view(view)`` gives it
    in any camera's frame, e.g. a sweep's); see :func:`sample_lighting`."""
    points_cam = points_cam or {}
    return estimate_views_lighting(list(views), sample.location, level, lidar=sample.lidar, boxes=sample.boxes,
                                   query_point_cam=points_cam.get(views[0].channel))


def sample_lighting(sample: Sample, views: Sequence[CameraView], level: str,
                    points_cam: dict[str, np.ndarray] | None = None) -> dict[str, LightingEstimate]:
    """The lighting of a sample, built once from all ``views`` and expressed in each camera's frame
    (channel -> estimate): one sun, sky and scene volume shared by the cameras, so that the same car is
    lit the same in every camera.  The one place the pipeline estimates lighting.

    ``points_cam``: channel -> (3,) placement in that camera's frame; the first view's point is where
    L2 centres its volume and where ``auto`` judges the level.
    """
    shared = shared_sample_lighting(sample, views, level, points_cam)
    return {view.channel: shared.for_view(view) for view in views}


def placement_points_cam(views: Sequence[CameraView], placed: SamplePlacement) -> dict[str, np.ndarray]:
    """Channel -> (3,) the bottom centre of the first object placed for that view, in its camera frame."""
    points = {}
    for view in views:
        first = placed.first_in(view.channel)
        if first is not None:
            points[view.channel] = (view.T_cam_from_global @ first.T_global_from_object)[:3, 3]
    return points


def insert_into_sample(
    sample: Sample, views: Sequence[CameraView], assets_by_channel: dict[str, Sequence[Asset]], options: InsertOptions,
) -> SampleInsertResult:
    """Insert objects into several cameras of one sample consistently (the same cars, seen by every camera).

    Stages: the sample's context (LiDAR in each camera) -> placement in each view in turn (each object
    clear of those placed before) -> lighting per sample -> for each camera: render every object or
    shadow in its view (occluded by the camera's scene depth and by the other objects) -> labels.

    Args:
        views: the cameras to augment; objects are placed in each view's field of view.
        assets_by_channel: channel -> the assets to place in that view (may be empty).
    """
    return _insert(sample, views, options,
                   lambda context: place_in_sample(sample, views, assets_by_channel, options, context))


def insert_placed_into_sample(sample: Sample, views: Sequence[CameraView], placements: Sequence[Placement],
                              assets: Sequence[Asset], options: InsertOptions,
                              label_fields: Sequence[dict] = (), lighting=None) -> SampleInsertResult:
    """Render objects whose places are already decided (e.g. the tracks of a scene at this keyframe) into
    ``views`` of ``sample``: lighting per sample, then every object or shadow each camera sees.

    Args:
        placements: the objects' placements (global frame), one per asset; ``asset_index`` = position.
        assets: their assets.
        label_fields: per object, extra fields for its image labels (e.g. ``{"track": ...}``), or empty.
        lighting: a sample's shared lighting (:func:`shared_sample_lighting`, ``result.shared_lighting``) to
            render with instead of estimating it here (e.g. a keyframe's, for the sweeps around it).
    Each object is logged under the first of ``views`` (``placed_for``): one annotation per sample.
    """
    placed = SamplePlacement(list(placements), [views[0].channel] * len(placements), list(assets), {},
                             {v.channel: 0.0 for v in views}, tuple(label_fields))
    return _insert(sample, views, options, lambda context: placed, lighting)


def _insert(sample: Sample, views: Sequence[CameraView], options: InsertOptions,
            place: Callable[[SampleContext], SamplePlacement], shared=None) -> SampleInsertResult:
    render_settings(options)  # a bad preset fails before any work
    check_insert_memory([(v.width, v.height) for v in views], options.quality, f"sample {sample.token}")
    t_start = time.perf_counter()
    for view in views:  # file decoding is excluded from the contract's "total": decode first
        _ = view.image
    _ = sample.lidar
    t0 = time.perf_counter()
    context = SampleContext.of(sample, views)
    placed = place(context)
    t = time.perf_counter()
    if shared is None:
        shared = shared_sample_lighting(sample, views, options.level, placement_points_cam(views, placed))
    lighting = {view.channel: shared.for_view(view) for view in views}
    lighting_s = (time.perf_counter() - t) / max(len(views), 1)
    context = context.with_lighting(lighting)

    n = len(placed.placements)
    visible_px, coverage_px = np.zeros(n), np.zeros(n)
    out: dict[str, InsertResult] = {}
    for view_context in context.views:
        channel = view_context.channel
        timing = {"lighting": lighting_s, "placement": placed.seconds[channel]}
        rendered = render_into_view(view_context, sample.token, placed, context.lighting[channel], options, timing)
        out[channel] = rendered.result
        visible_px += rendered.visible_px
        coverage_px += rendered.coverage_px
    timing_s = {"lighting": lighting_s * len(views), "placement": sum(placed.seconds.values()),
                "total": time.perf_counter() - t0, "with_decode": time.perf_counter() - t_start}
    return SampleInsertResult(out, placed.placements, placed.placed_for, placed.assets, placed.results, visible_px,
                              coverage_px, lighting, placed.reason, timing_s, shared)


def insert_into_view(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions) -> InsertResult:
    """Insert ``assets`` (one per object) into one camera image of a sample (see :func:`insert_into_sample`)."""
    result = insert_into_sample(sample, [view], {view.channel: assets}, options)
    out = result.views[view.channel]
    if result.skipped_reason:
        return replace(out, skipped_reason=result.skipped_reason)
    return out
