"""What an insertion produced: :class:`InsertResult` (one camera image) and :class:`SampleInsertResult`
(all cameras of a sample, one placement in the global frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from streetaug.placement.place import Placement, PlacementResult

from ..assets.asset import Asset
from ..lighting.types import LightingEstimate
from ..render import PixelBox


def changed_pixel_box(changed: np.ndarray) -> PixelBox:
    """The smallest pixel box holding every True pixel of ``changed`` (H, W) bool (empty when none is)."""
    rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if not len(rows):
        return PixelBox(0, 0, 0, 0)
    return PixelBox(int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)


@dataclass(frozen=True)
class InsertResult:
    """What one insertion into one image produced.

    Attributes:
        image: (H, W, 3) uint8 augmented image.
        objects: label dicts (contract ``labels.json`` objects), one per inserted object.
        changed_box: the pixel box holding every pixel the objects or their shadows touch (empty when none).
        mask_box, shadow_ratio_box: (changed_box.height, changed_box.width) float32 the union of the objects'
            alpha and the product of their shadow ratio maps inside ``changed_box`` (0 and 1 outside it);
            :attr:`mask` and :attr:`shadow_ratio` give them over the full image. Only the box is held: a
            sample's results keep every camera's (two full-frame layers were ~12 MB per camera at 1600 x 900).
        timing_s: seconds per stage and ``total`` (inputs decoded -> outputs ready).
        lighting: the lighting estimate (None for the image form).
        placement: the placement in this camera's view (its ``report``, candidates, reason; None for the
            image form and for a camera of a sample in which no object was placed for it).
        skipped_reason: set when nothing could be inserted (the image is then unchanged).
    """

    image: np.ndarray
    objects: list[dict]
    changed_box: PixelBox
    mask_box: np.ndarray
    shadow_ratio_box: np.ndarray
    timing_s: dict[str, float]
    lighting: LightingEstimate | None = None
    placement: PlacementResult | None = None
    skipped_reason: str | None = None

    @classmethod
    def of(cls, image: np.ndarray, objects: list[dict], mask: np.ndarray | None, shadow_ratio: np.ndarray | None,
           timing_s: dict[str, float], **rest) -> InsertResult:
        """The result of full-frame (H, W) ``mask`` / ``shadow_ratio`` (None: nothing inserted), held inside the
        box of the pixels they change (copies: the full-frame arrays are not referenced)."""
        if mask is None or shadow_ratio is None:
            empty = np.zeros((0, 0), np.float32)
            return cls(image, objects, PixelBox(0, 0, 0, 0), empty, empty + 1.0, timing_s, **rest)
        box = changed_pixel_box((mask != 0) | (shadow_ratio != 1))
        return cls(image, objects, box, mask[box.slices].astype(np.float32), shadow_ratio[box.slices].astype(np.float32),
                   timing_s, **rest)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) float32 union of the objects' alpha (a new array)."""
        return self.changed_box.paste(self.mask_box, self.image.shape[:2], 0.0)

    @property
    def shadow_ratio(self) -> np.ndarray:
        """(H, W) float32 product of the objects' shadow ratio maps, 1 = unchanged (a new array)."""
        return self.changed_box.paste(self.shadow_ratio_box, self.image.shape[:2], 1.0)

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
