"""Placement for the cameras of a sample: each view's objects in turn, each clear of those placed before."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample
from streetaug.placement.config import PlacementConfig
from streetaug.placement.place import Placement, PlacementResult, place_objects

from ..assets.asset import Asset
from .options import InsertOptions, item_seed


def place_in_view(sample: Sample, view: CameraView, assets: Sequence[Asset], placed: Sequence[Placement],
                  options: InsertOptions) -> PlacementResult:
    """Place ``assets`` in ``view``, clear (as dynamic boxes) of the objects ``placed`` for other cameras.

    Seeded by (seed, sample token, channel).
    """
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
        results: channel -> the placement in that view (candidates, rule report, reason).
        seconds: channel -> seconds spent placing in that view.
    """

    placements: list[Placement]
    placed_for: list[str]
    assets: list[Asset]
    results: dict[str, PlacementResult]
    seconds: dict[str, float]

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
                    options: InsertOptions) -> SamplePlacement:
    """Place each view's assets in that view in turn, each object clear of those placed before."""
    placements, placed_for, placed_assets, results, seconds = [], [], [], {}, {}
    for view in views:
        t = time.perf_counter()
        assets = list(assets_by_channel.get(view.channel, ()))
        if assets:
            res = place_in_view(sample, view, assets, placements, options)
            results[view.channel] = res
            for p, asset in zip(res.placements, assets_of_placements(assets, res.placements)):
                placements.append(p)
                placed_for.append(view.channel)
                placed_assets.append(asset)
        seconds[view.channel] = time.perf_counter() - t
    return SamplePlacement(placements, placed_for, placed_assets, results, seconds)


def assets_of_placements(assets: Sequence[Asset], placements: Sequence[Placement]) -> list[Asset]:
    """The asset of each placement (placement may drop objects it could not place; sizes identify them)."""
    unused = list(assets)
    out = []
    for p in placements:
        i = next(i for i, a in enumerate(unused) if np.allclose(a.wlh, p.wlh))
        out.append(unused.pop(i))
    return out
