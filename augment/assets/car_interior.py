"""The interior of a procedural car, seen through its glass: dashboard, steering wheel, seats with headrests.

Parts are closed boxes / prisms / a torus inside the body (object frame before centring: x = L/2 - d,
d the distance from the nose, y left, z up, metres), sized from the body's own profiles
(:func:`~.car_body.body_profiles`, :func:`~.car_body.section_half_width`) with a margin, so nothing
pokes through the shell.  The steering wheel sits on the driver's side: left (+y) for left-hand
drive, right (-y) for right-hand drive (Singapore).
"""

from __future__ import annotations

import numpy as np

from .car_body import DASH, INTERIOR, BodySpec, body_profiles, section_half_width
from .mesh_parts import MeshPart
from .revolve import box, capsule, prism, rot_y, torus

_MARGIN_M = 0.05  # clearance between an interior part and the body shell


def _inner_half_width(spec: BodySpec, d0: float, d1: float, z0: float, z1: float) -> float:
    """The body's smallest half width over the box d0..d1 x z0..z1, less the margin (m)."""
    dd, zz = np.meshgrid(np.linspace(d0, d1, 5), np.linspace(z0, z1, 5))
    return float(section_half_width(spec, dd, zz).min()) - _MARGIN_M


def _top(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[0][0])


def _belt(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[3][0])


def _floor(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[1][0]) + 0.06


def _x(spec: BodySpec, d: float) -> float:
    return spec.length / 2 - d


def dashboard_part(spec: BodySpec) -> MeshPart:
    """The dashboard: a wedge under the windscreen across the cabin."""
    d0, d1 = spec.d_ws + 0.03, spec.d_ws + 0.48
    belt = _belt(spec, d0)
    z_bot = belt - 0.30
    z_front = min(_top(spec, d0) - _MARGIN_M, belt + 0.02)
    z_rear = min(_top(spec, d1) - 0.10, belt + 0.08)
    hw = _inner_half_width(spec, d0, d1, z_bot, max(z_front, z_rear))
    outline = [(_x(spec, d0), z_bot), (_x(spec, d0), z_front), (_x(spec, d1), z_rear), (_x(spec, d1), z_bot + 0.12)]
    return prism(np.array(outline), np.array([0.0, -hw, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                 np.array([0.0, 1.0, 0.0]), 2 * hw, DASH)


def steering_wheel_parts(spec: BodySpec, right_hand_drive: bool) -> list[MeshPart]:
    """Steering wheel (a torus facing the driver, tilted back) and its column into the dashboard."""
    d_c = spec.d_ws + 0.66
    belt = _belt(spec, d_c)
    hw = _inner_half_width(spec, d_c - 0.1, d_c + 0.1, belt - 0.2, belt + 0.2)
    y_c = (-1.0 if right_hand_drive else 1.0) * min(0.38, 0.5 * hw)
    centre = np.array([_x(spec, d_c), y_c, belt + 0.03])
    tilt = np.radians(62.0)  # the wheel's axis from the vertical, towards the rear
    axis = np.array([-np.sin(tilt), 0.0, np.cos(tilt)])
    radius = 0.185
    ring = torus(centre, axis, radius, 0.017, DASH, n_major=20, n_minor=6)
    column = capsule(centre, centre + np.array([0.30, 0.0, -0.13]), 0.035, 0.045, DASH, n_around=8, n_cap=1)
    return [ring, column]


def _seat(spec: BodySpec, d_back: float, y0: float, y1: float, headrests: list[float]) -> list[MeshPart]:
    """A seat from y0 to y1 whose backrest stands at d_back: cushion, reclined backrest, headrests."""
    belt = _belt(spec, d_back)
    floor = _floor(spec, d_back)
    z_cushion = max(floor + 0.12, belt - 0.40)
    x_back = _x(spec, d_back)
    parts = [box(np.array([x_back, y0, floor]), np.array([x_back + 0.48, y1, z_cushion]), INTERIOR)]
    top_room = _top(spec, d_back + 0.1) - _MARGIN_M  # the roof (or the sloping rear window) above
    back_h = float(np.clip(top_room - 0.30 - z_cushion, 0.30, 0.62))
    recline = rot_y(-np.radians(16.0))
    pivot = np.array([x_back, 0.0, z_cushion])
    parts.append(box(np.array([x_back - 0.11, y0 + 0.02, z_cushion]), np.array([x_back, y1 - 0.02, z_cushion + back_h]),
                     INTERIOR, rotation=recline, pivot=pivot))
    z_head0 = z_cushion + back_h + 0.04
    z_head1 = min(z_head0 + 0.20, top_room)
    for yh in headrests:
        lo = np.array([x_back - 0.10, yh - 0.13, z_head0])
        hi = np.array([x_back - 0.01, yh + 0.13, z_head1])
        parts.append(box(lo, hi, INTERIOR, rotation=recline, pivot=pivot))
        for yp in (yh - 0.07, yh + 0.07):  # the two posts
            parts.append(box(np.array([x_back - 0.06, yp - 0.006, z_head0 - 0.05]),
                             np.array([x_back - 0.045, yp + 0.006, z_head0 + 0.01]), INTERIOR, rotation=recline,
                             pivot=pivot))
    return parts


def seat_parts(spec: BodySpec) -> list[MeshPart]:
    """Two front seats behind the B pillar's front edge and a rear bench under the roof."""
    d_front = spec.pillars[0] + 0.08
    belt = _belt(spec, d_front)
    hw = _inner_half_width(spec, d_front - 0.5, d_front + 0.15, _floor(spec, d_front), belt + 0.45)
    parts = []
    for s in (1.0, -1.0):
        yc = s * 0.5 * hw
        parts += _seat(spec, d_front, yc - 0.24, yc + 0.24, [yc])
    # Rear bench: as far back as the roof leaves room for the headrests, at most 0.9 m behind.
    cand = np.linspace(d_front + 0.95, d_front + 0.6, 8)
    ok = [d for d in cand if _top(spec, d + 0.1) - _MARGIN_M - _belt(spec, d) > 0.42 and d < spec.d_rear - 0.05]
    if ok:
        d_rear = ok[0]
        hw_r = _inner_half_width(spec, d_rear - 0.5, d_rear + 0.15, _floor(spec, d_rear), _belt(spec, d_rear) + 0.4)
        parts += _seat(spec, d_rear, -hw_r + 0.02, hw_r - 0.02, [0.5 * hw_r, -0.5 * hw_r])
    return parts


def interior_parts(spec: BodySpec, right_hand_drive: bool) -> list[MeshPart]:
    """Every interior part of a car with body ``spec``; the steering wheel on the right with ``right_hand_drive``."""
    return [dashboard_part(spec), *steering_wheel_parts(spec, right_hand_drive), *seat_parts(spec)]


__all__ = ["dashboard_part", "interior_parts", "seat_parts", "steering_wheel_parts"]
