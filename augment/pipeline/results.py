"""What an insertion produced: :class:`InsertResult` (one camera image) and :class:`SampleInsertResult`
(all cameras of a sample, one placement in the global frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from streetaug.placement.place import Placement, PlacementResult

from ..assets.asset import Asset
from ..lighting.types import LightingEstimate


@dataclass(frozen=True)
class InsertResult:
    """What one insertion into one image produced.

    Attributes:
        image: (H, W, 3) uint8 augmented image.
        objects: label dicts (contract ``labels.json`` objects), one per inserted object.
        mask: (H, W) float32 union of the objects' alpha.
        shadow_ratio: (H, W) float32 product of the objects' shadow ratio maps.
        timing_s: seconds per stage and ``total`` (inputs decoded -> outputs ready).
        lighting: the lighting estimate (None for the image form).
        placement: the placement in this camera's view (its ``report``, candidates, reason; None for the
            image form and for a camera of a sample in which no object was placed for it).
        skipped_reason: set when nothing could be inserted (the image is then unchanged).
    """

    image: np.ndarray
    objects: list[dict]
    mask: np.ndarray
    shadow_ratio: np.ndarray
    timing_s: dict[str, float]
    lighting: LightingEstimate | None = None
    placement: PlacementResult | None = None
    skipped_reason: str | None = None

    @property
    def placement_report(self) -> dict[str, int] | None:
        """Rule name -> candidates rejected in this view (None without a placement)."""
        return None if self.placement is None else self.placement.report


@dataclass(frozen=True)
class SampleInsertResult:
    """What one multi-camera insertion produced: one placement in the global frame, rendered into every camera.

    Attributes:
        views: channel -> :class:`InsertResult` of that camera. A camera that sees neither an inserted
            object nor its shadow keeps its image unchanged, with ``skipped_reason`` set.
        placements: every placed object (global frame); an object's index here is its ``object_index``
            in the labels.
        placed_for: (n_objects,) channel in whose view each object was placed.
        assets: (n_objects,) the asset of each placement.
        placement_results: channel -> the placement in that view.
        visible_px, coverage_px: (n_objects,) float visible / total (unoccluded) object pixels, summed over
            the rendered cameras (their ratio is the object's visibility across cameras, as in nuScenes).
        lighting: channel -> lighting estimate of that camera.
        skipped_reason: set when no object could be placed in any view.
        timing_s: seconds of the sample-level stages (``lighting``, ``placement``) and ``total``.
        shared_lighting: the sample's lighting in the world (``SampleLighting``; ``.for_view`` gives any camera's).
    """

    views: dict[str, InsertResult]
    placements: list[Placement]
    placed_for: list[str]
    assets: list[Asset]
    placement_results: dict[str, PlacementResult]
    visible_px: np.ndarray
    coverage_px: np.ndarray
    lighting: dict[str, LightingEstimate]
    skipped_reason: str | None
    timing_s: dict[str, float]
    shared_lighting: object = None
