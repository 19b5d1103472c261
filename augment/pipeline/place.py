"""Placement for the cameras of a sample: each view's objects in turn, each clear of those placed before."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample
from streetaug.placement.class_rules import read_class_rules
from streetaug.placement.config import PlacementConfig
from streetaug.placement.place import Placement, PlacementResult, place_objects

from ..assets.asset import Asset
from .context import SampleContext
from .options import InsertOptions, item_seed


def place_in_view(sample: Sample, view: CameraView, assets: Sequence[Asset], placed: Sequence[Placement],
                  options: InsertOptions, depth_m: np.ndarray | None = None) -> PlacementResult:
    """Place ``assets`` in ``view``, clear (as dynamic boxes) of the objects ``placed`` for other cameras.

    Seeded by (seed, sample token, channel). ``depth_m``: the view's scene depth (the renderer's), None to
    let placement compute the same. Each placement's ``asset_index`` indexes ``assets``.
    """
    if placed:  # earlier objects count as annotated boxes (their class's clearance); LiDAR is shared, not re-read
        sample = sample.evolve(boxes=sample.boxes + tuple(p.box for p in placed))
    config = PlacementConfig(yaw_sigma_deg=options.yaw_sigma_deg, n_objects=len(assets))
    return place_objects(sample, view, assets, item_seed(options.seed, sample.token, view.channel), config,
                         depth_m=depth_m, class_rules=read_class_rules(options.class_rules))


@dataclass(frozen=True)
class SamplePlacement:
    """Objects placed for several cameras of one sample (global frame).

    Attributes:
        placements: every placed object, in placement order (= object index).
        placed_for: channel in whose view each object was placed.
        assets: the asset of each object.
        results: channel -> the placement in that view (candidates, rule report, reason).
        seconds: channel -> seconds spent placing in that view.
        label_fields: per object, extra fields of its image labels (e.g. its track), or empty.
    """

    placements: list[Placement]
    placed_for: list[str]
    assets: list[Asset]
    results: dict[str, PlacementResult]
    seconds: dict[str, float]
    label_fields: tuple[dict, ...] = ()

    @property
    def reason(self) -> str | None:
        """Why nothing was placed (None when something was)."""
        if self.placements:
            return None
        return "; ".join(f"{ch}: {r.reason}" for ch, r in self.results.items() if r.reason) or "no valid placement"

    def first_in(self, channel: str) -> Placement | None:
        """The first object placed for ``channel``'s view (None when none was)."""
        return next((p for p, ch in zip(self.placements, self.placed_for) if ch == channel), None)


def place_in_sample(sample: Sample, views: Sequence[CameraView], assets_by_channel: dict[str, Sequence[Asset]],
                    options: InsertOptions, context: SampleContext | None = None) -> SamplePlacement:
    """Place each view's assets in that view in turn, each object clear of those placed before.

    With ``context`` (of the same sample and views) placement tests occlusion on its views' scene depth,
    the one the renderer then uses; without, placement computes the same depth itself.
    """
    placements, placed_for, placed_assets, results, seconds = [], [], [], {}, {}
    for view in views:
        t = time.perf_counter()
        assets = list(assets_by_channel.get(view.channel, ()))
        if assets:
            depth_m = None if context is None else context.view(view.channel).depth_m
            res = place_in_view(sample, view, assets, placements, options, depth_m)
            results[view.channel] = res
            for p in res.placements:
                placements.append(p)
                placed_for.append(view.channel)
                placed_assets.append(assets[p.asset_index])
        seconds[view.channel] = time.perf_counter() - t
    return SamplePlacement(placements, placed_for, placed_assets, results, seconds)
