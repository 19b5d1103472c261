"""Placement chooses between candidates wholly in the image and candidates cut by its frame as
``PlacementConfig.truncated_share`` says (place_one), falling back to the other kind when a zone has only one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely
from placement_fixtures import CAMERA, ego_to_global_xy, ground_grid_ego, lidar_sweep, make_sample

from streetaug.placement.config import PlacementConfig
from streetaug.placement.place import FULL_VIEW_FRACTION, ObjectBox, place_objects
from streetaug.placement.rules import box_corners_object, projected_inside_fraction
from streetaug.placement.scene import scene_depth

CAR = ObjectBox(np.array([1.8, 4.5, 1.5]))
SEEDS = range(40)


def _inside(view, placement) -> float:
    T = view.T_cam_from_global @ placement.T_global_from_object
    corners = box_corners_object(placement.wlh) @ T[:3, :3].T + T[:3, 3]
    return float(projected_inside_fraction(corners[None], CAMERA)[0])


def _place(sample, config: PlacementConfig, seed: int, depth_m: np.ndarray | None = None):
    view = sample.cameras["CAM_FRONT"]
    if depth_m is None:
        depth_m = DEPTH[sample.token]
    res = place_objects(sample, view, [CAR], np.random.default_rng(seed), config, depth_m=depth_m)
    assert len(res.placements) == 1, res.reason
    return view, res


DEPTH: dict[str, np.ndarray] = {}


@pytest.fixture(scope="module")
def road():
    """The straight road ahead (|y_ego| <= 5 m) on flat LiDAR ground: the near places by its sides are cut
    by the image's frame, the others wholly in view."""
    sample = make_sample(lidar=lidar_sweep(ground_grid_ego(0.5)))
    DEPTH[sample.token] = scene_depth(sample, sample.cameras["CAM_FRONT"])  # once, not per placement
    return sample


def test_share_zero_keeps_every_car_wholly_in_view(road):
    """The first candidate passing every rule is cut by the frame for some seeds (seed 9 on this road); with
    ``truncated_share`` 0 the first one wholly in view is taken instead, and it is the one marked chosen."""
    config = PlacementConfig(truncated_share=0.0)
    for seed in SEEDS:
        view, res = _place(road, config, seed)
        p = res.placements[0]
        assert _inside(view, p) >= FULL_VIEW_FRACTION, seed
        chosen = res.candidates_xy[res.rejected_by == ""]
        np.testing.assert_allclose(chosen, p.T_global_from_object[None, :2, 3], atol=1e-9)


def test_share_one_takes_cars_cut_by_the_frame(road):
    """Truncated candidates that pass every rule are few on an open road (the near road sides): the old rule
    (the first passing) chose one for 1 of 40 seeds; with ``truncated_share`` 1 they are taken wherever the
    candidates hold one, each still at least ``min_visible_fraction`` in the image."""
    config = PlacementConfig(truncated_share=1.0)
    inside = np.array([_inside(*(lambda v, r: (v, r.placements[0]))(*_place(road, config, s))) for s in SEEDS])
    assert np.all(inside >= config.min_visible_fraction - 1e-9)
    assert np.mean(inside < FULL_VIEW_FRACTION) >= 0.4


def test_default_share_is_drawn_per_object_and_deterministic(road):
    """By default about ``truncated_share`` (0.16) of the cars are cut by the frame where both kinds pass (the
    old rule: 1 of 40 on this road); the same seed gives the same placement."""
    config = PlacementConfig()
    assert config.truncated_share == pytest.approx(0.16)
    cut = []
    for seed in SEEDS:
        view, res = _place(road, config, seed)
        if seed < 5:
            _, again = _place(road, config, seed)
            np.testing.assert_array_equal(res.placements[0].T_global_from_object,
                                          again.placements[0].T_global_from_object)
        cut.append(_inside(view, res.placements[0]) < FULL_VIEW_FRACTION)
    assert 2 <= sum(cut) <= 10  # ~0.16 of the 21 seeds with a truncated survivor (truncated_share 1: 21 of 40)


def test_a_zone_with_only_cut_candidates_still_gives_one():
    """A road only at the right edge of the view (a 2.5 m strip 5.5-8 m right of the ego, 10-17.8 m ahead): a car
    on it with its centre in the view has its near corner out of it, and with ``truncated_share`` 0 the car still
    stands there (the fallback)."""
    strip = shapely.Polygon(ego_to_global_xy([[10.0, -8.0], [17.8, -8.0], [17.8, -5.5], [10.0, -5.5]]))
    sample = make_sample(polygons=[strip], lidar=lidar_sweep(ground_grid_ego(0.5)))
    config = dataclasses.replace(PlacementConfig(truncated_share=0.0), n_candidates=2000)
    view, res = _place(sample, config, 0, scene_depth(sample, sample.cameras["CAM_FRONT"]))
    inside = _inside(view, res.placements[0])
    assert config.min_visible_fraction <= inside < FULL_VIEW_FRACTION


def test_truncated_share_is_checked():
    with pytest.raises(ValueError, match="truncated_share"):
        PlacementConfig(truncated_share=1.5)
