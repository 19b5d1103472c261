"""A kerb car in a row of parked cars takes the row's heading, nose-in or nose-out as its neighbour stands."""

from __future__ import annotations

import numpy as np
import pytest

from streetaug.augment.core import yaw_to_quat
from streetaug.datasets.nuscenes_format import VEHICLE_PARKED
from streetaug.datasets.sample import Box
from streetaug.placement.parking import STYLE_REACH_M, kerb_poses, parking_style, row_neighbour

L, W = 4.5, 1.85


class TurningEdge:
    """Zones whose road edge turns round at x = 0 (a U-shaped kerb, or the two sides of a parking strip as a distance
    field sees them): the road's normal is +y for x < 0 and -y for x >= 0; everywhere 2 m inside the road."""

    def road_normal(self, xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.where((xy[:, 0] < 0)[:, None], [0.0, 1.0], [0.0, -1.0])

    def edge_tangent(self, xy):
        n = self.road_normal(xy)
        return np.c_[-n[:, 1], n[:, 0]]

    def signed_distance(self, xy):
        return np.full(len(np.asarray(xy, float).reshape(-1, 2)), 2.0)


def _parked(x: float, y: float, yaw: float) -> Box:
    return Box(np.array([x, y, 0.8]), np.array([W, L, 1.6]), yaw_to_quat(yaw), "vehicle.car",
               attributes=(VEHICLE_PARKED,))


def _style(boxes):
    return parking_style(TurningEdge(), boxes, {"vehicle.car"}, np.zeros(2), 200.0, kerb_distance_m=2.0)


def _yaw(x: float, y: float, style) -> float:
    _, yaw, styled = kerb_poses(TurningEdge(), style, np.array([[x, y]]), np.zeros(1), L, W)
    assert styled[0]
    return float(yaw[0])


def _angle_deg(a: float, b: float) -> float:
    return float(np.degrees(abs(np.angle(np.exp(1j * (a - b))))))


@pytest.mark.parametrize("neighbour_yaw", [np.pi / 2, -np.pi / 2, 0.0, np.pi])
def test_a_car_beside_a_parked_car_takes_its_full_heading_where_the_edge_turns_round(neighbour_yaw):
    """The neighbour stands where the edge runs one way, the candidate (one free bay beside it, 6 m between centres)
    where it runs the other: the heading against the edge alone would turn the car round (nose-in beside a nose-out
    car); the row's heading keeps the direction."""
    style = _style([_parked(-3.0, 0.0, neighbour_yaw)])
    along_neighbour = abs(np.cos(neighbour_yaw)) > 0.5  # nose to tail: offset along its heading
    x = 3.0 if not along_neighbour else L + 1.5 - 3.0
    assert _angle_deg(_yaw(x, 0.0, style), neighbour_yaw) < 1e-6


def test_a_car_away_from_any_row_keeps_the_edge_style():
    """No parked box within a car length's gap: the nearest one's heading against the local edge, as before."""
    style = _style([_parked(-3.0, 0.0, np.pi / 2)])
    x = 3.0 + 2 * L + 1.0  # gap to the box beyond one candidate length, within STYLE_REACH_M
    assert x + 3.0 < STYLE_REACH_M
    # the style box: heading +y against the tangent (-1, 0) -> -90 deg; at x >= 0 the tangent is (+1, 0)
    assert _angle_deg(_yaw(x, 0.0, style), -np.pi / 2) < 1e-6


def test_row_neighbours_are_beside_or_nose_to_tail_not_across_an_aisle():
    style = _style([_parked(0.0, 0.0, np.pi / 2), _parked(40.0, 0.0, 0.0)])  # perpendicular bay; a parallel one
    xy = np.array([
        [2.6, 0.0],         # the next bay: neighbour 0
        [2 * 2.6, 0.3],     # one free bay between: neighbour 0
        [0.0, L + 6.0],     # across a 6 m aisle, facing it: none
        [40.0 + L + 1.0, 0.0],  # nose to tail behind the parallel one: neighbour 1
        [40.0, 8.0],        # across the road from it: none
    ])
    assert row_neighbour(style, xy, L, W).tolist() == [0, 0, -1, 1, -1]


def test_parked_rows_away_from_the_edge_still_give_the_heading():
    """Parked cars none of which stands by the road edge (a car park's inner rows): no edge style, but a candidate
    in their row takes their heading."""
    style = parking_style(TurningEdge(), [_parked(-3.0, 0.0, 2.0)], {"vehicle.car"}, np.zeros(2), 200.0,
                          kerb_distance_m=0.5)
    assert style is not None and len(style.xy) == 0
    assert _angle_deg(_yaw(-0.4, 0.0, style), 2.0) < 1e-6
    # and away from the row: along the edge, the direction nearer to the given heading
    _, yaw, styled = kerb_poses(TurningEdge(), style, np.array([[-20.0, 0.0]]), np.zeros(1), L, W)
    assert not styled[0]
    assert _angle_deg(float(yaw[0]), 0.0) < 1e-6  # the edge's direction nearer to the given heading (0)

