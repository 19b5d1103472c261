"""The per-sample context: what placement, lighting and rendering read of a sample, computed once.

Per camera (:class:`ViewContext`): the LiDAR sweep in the camera frame and the one dense scene depth
(LiDAR densified, the ego's ground plane where LiDAR leaves holes below the horizon; the plane alone
without LiDAR) -- the same array for the placement's occlusion test and the renderer's. Per sample (:class:`SampleContext`): the cameras and, once the objects are placed, the
sample's lighting (one sun, sky and volume shared by the cameras, expressed in each camera's frame).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample

from ..core import PinholeCamera
from ..core.depth import densify_lidar_depth, ground_plane_depth
from ..lighting.light import DistantLight
from ..lighting.types import LightingEstimate


def scene_depth(view: CameraView, points_cam: np.ndarray | None) -> np.ndarray:
    """Dense metric depth (H, W) float32 of a camera (camera-frame z, metres; inf = sky / unknown).

    Args:
        points_cam: (N, 3) the sample's LiDAR points in this camera's frame, or None without LiDAR
            (then the ego's ground plane alone).
    """
    normal, offset = view.ego_ground_plane_cam
    if points_cam is None:
        return ground_plane_depth(view.K, view.width, view.height, normal, offset)
    return densify_lidar_depth(points_cam, view.K, view.width, view.height, ground_fill=(normal, offset))


def scene_depth_for_view(sample: Sample, view: CameraView) -> np.ndarray:
    """:func:`scene_depth` of ``view`` from the sample's own LiDAR (for a one-off; a sample's stages share
    :attr:`ViewContext.depth_m` instead)."""
    return ViewContext.of(sample, view).depth_m


@dataclass(frozen=True)
class ViewContext:
    """One camera of a sample and what every stage reads of it (derived values computed once, on first use).

    Attributes:
        view: the camera (image, intrinsics, poses).
        points_cam: (N, 3) float64 the sample's LiDAR points in this camera's frame (metres), or None
            when the sample has no LiDAR sweep.
    """

    view: CameraView
    points_cam: np.ndarray | None

    @classmethod
    def of(cls, sample: Sample, view: CameraView) -> "ViewContext":
        """The context of ``view``: the sample's LiDAR transformed into its frame once."""
        lidar = sample.lidar
        return cls(view, None if lidar is None else lidar.points_in(view.T_cam_from_global))

    @property
    def channel(self) -> str:
        return self.view.channel

    @functools.cached_property
    def camera(self) -> PinholeCamera:
        """The camera's intrinsics and image size."""
        return PinholeCamera(self.view.K, self.view.width, self.view.height)

    @functools.cached_property
    def depth_m(self) -> np.ndarray:
        """(H, W) float32 the scene's dense depth (:func:`scene_depth`), computed on first use."""
        return scene_depth(self.view, self.points_cam)


@dataclass(frozen=True)
class SampleContext:
    """A sample with its cameras' contexts and, once objects are placed, its lighting.

    Attributes:
        sample: the sample (boxes, map, LiDAR).
        views: the cameras to augment, in placement order.
        lighting: channel -> the sample's lighting in that camera's frame (empty before :meth:`with_lighting`).
    """

    sample: Sample
    views: tuple[ViewContext, ...]
    lighting: dict[str, LightingEstimate] = field(default_factory=dict)

    @classmethod
    def of(cls, sample: Sample, views: Sequence[CameraView]) -> "SampleContext":
        """The context of ``views`` of ``sample`` (decodes the LiDAR sweep and moves it into each camera)."""
        return cls(sample, tuple(ViewContext.of(sample, v) for v in views))

    def with_lighting(self, lighting: dict[str, LightingEstimate]) -> "SampleContext":
        """This context with the sample's lighting set."""
        return replace(self, lighting=dict(lighting))

    def view(self, channel: str) -> ViewContext:
        """The context of camera ``channel``."""
        return next(v for v in self.views if v.channel == channel)


def object_light(estimate: LightingEstimate, center_cam: np.ndarray) -> DistantLight:
    """The distant light an object centred at ``center_cam`` (3,) (camera frame, metres) is shaded with:
    the estimate's local light there (L2/L3 volume; L0/L1: the same light everywhere)."""
    return estimate.light_at(np.asarray(center_cam, dtype=np.float64))
