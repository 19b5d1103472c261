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


def _top(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[0][0])


def _belt(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[3][0])


def _floor(spec: BodySpec, d: float) -> float:
    return float(body_profiles(spec, np.array([d]))[1][0]) + 0.06


def _x(spec: BodySpec, d: float) -> float:
    return spec.length / 2 - d


def _room_half_width(spec: BodySpec, d: np.ndarray, z_lo: np.ndarray, z_hi: np.ndarray) -> float:
    """The body's smallest half width over the region between z_lo(d) and z_hi(d) at stations d (same shapes),
    less the margin (m): the room a part with that side outline (in x-z) has across the cabin."""
    t = np.linspace(0.0, 1.0, 6)
    dd = np.broadcast_to(np.asarray(d, np.float64)[:, None], (len(d), len(t)))
    zz = np.asarray(z_lo)[:, None] + (np.asarray(z_hi) - np.asarray(z_lo))[:, None] * t[None, :]
    return float(section_half_width(spec, dd, zz).min()) - _MARGIN_M


DASH_TOP_CLEAR_M = 0.03  # the dashboard's top edge keeps this much room above it across its whole width
DASH_DEPTH_M = 0.70  # the dashboard's depth under the windscreen (d_ws + 0.03 onwards), at most to the seats' room


def dashboard_span(spec: BodySpec) -> tuple[float, float]:
    """(front, rear) distance from the nose d (m) of the dashboard: from the windscreen's foot back
    :data:`DASH_DEPTH_M` under the sloping glass, ending at least 0.55 m before the front seats' backrests."""
    d0 = spec.d_ws + 0.03
    d1 = min(d0 + DASH_DEPTH_M, spec.pillars[0] + 0.08 - 0.55)
    return d0, max(d1, d0 + 0.35)


def dashboard_part(spec: BodySpec) -> MeshPart:
    """The dashboard: a wedge under the windscreen across the whole cabin (its width the room the body leaves over
    the wedge's own side outline, not over its bounding box: the box's top front corner lies above the cowl)."""
    d0, d1 = dashboard_span(spec)
    belt = _belt(spec, d0)
    z_bot = belt - 0.30
    z_front = min(_top(spec, d0) - 0.08, belt + 0.02)
    z_rear = min(_top(spec, d1) - 0.10, belt + 0.08)
    dd = np.linspace(d0, d1, 8)
    z_hi = np.interp(dd, [d0, d1], [z_front, z_rear])
    z_lo = np.interp(dd, [d0, d1], [z_bot, z_bot + 0.12])
    # The room 3 cm above the top edge too: at the cowl the shell slopes down to the sides, and the width at the
    # top edge's own height alone left the top front corners ~1 cm under the glass.
    hw = _room_half_width(spec, dd, z_lo, z_hi + DASH_TOP_CLEAR_M)
    outline = [(_x(spec, d0), z_bot), (_x(spec, d0), z_front), (_x(spec, d1), z_rear), (_x(spec, d1), z_bot + 0.12)]
    return prism(np.array(outline), np.array([0.0, -hw, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                 np.array([0.0, 1.0, 0.0]), 2 * hw, DASH)


def steering_wheel_parts(spec: BodySpec, right_hand_drive: bool) -> list[MeshPart]:
    """Steering wheel (a torus facing the driver, tilted back) at the dashboard's rear edge, its column into the
    dashboard; centred in front of the driver's seat."""
    _, d_dash = dashboard_span(spec)
    d_c = d_dash + 0.08
    belt = _belt(spec, d_c)
    centre_y, _ = _front_seat_y(spec)
    y_c = (-1.0 if right_hand_drive else 1.0) * centre_y
    centre = np.array([_x(spec, d_c), y_c, belt + 0.03])
    tilt = np.radians(62.0)  # the wheel's axis from the vertical, towards the rear
    axis = np.array([-np.sin(tilt), 0.0, np.cos(tilt)])
    radius = 0.185
    ring = torus(centre, axis, radius, 0.017, DASH, n_major=20, n_minor=6)
    column = capsule(centre, centre + np.array([0.22, 0.0, -0.10]), 0.035, 0.045, DASH, n_around=8, n_cap=1)
    return [ring, column]


def _seat_heights(spec: BodySpec, d_back: float) -> tuple[float, float, float, float]:
    """Heights (m) of a seat whose backrest stands at d_back: cushion top, backrest height, headrest bottom and top
    (before the backrest's recline)."""
    belt = _belt(spec, d_back)
    z_cushion = max(_floor(spec, d_back) + 0.12, belt - 0.40)
    top_room = _top(spec, d_back + 0.1) - _MARGIN_M  # the roof (or the sloping rear window) above
    back_h = float(np.clip(top_room - 0.30 - z_cushion, 0.30, 0.62))
    z_head0 = z_cushion + back_h + 0.04
    return z_cushion, back_h, z_head0, min(z_head0 + 0.20, top_room)


def _seat(spec: BodySpec, d_back: float, y0: float, y1: float, headrests: list[float], cushion_m: float = 0.48
          ) -> list[MeshPart]:
    """A seat from y0 to y1 whose backrest stands at d_back: cushion (``cushion_m`` long), reclined backrest,
    headrests at y ``headrests``."""
    floor = _floor(spec, d_back)
    z_cushion, back_h, z_head0, z_head1 = _seat_heights(spec, d_back)
    x_back = _x(spec, d_back)
    parts = [box(np.array([x_back, y0, floor]), np.array([x_back + cushion_m, y1, z_cushion]), INTERIOR)]
    recline = rot_y(-np.radians(16.0))
    pivot = np.array([x_back, 0.0, z_cushion])
    parts.append(box(np.array([x_back - 0.11, y0 + 0.02, z_cushion]), np.array([x_back, y1 - 0.02, z_cushion + back_h]),
                     INTERIOR, rotation=recline, pivot=pivot))
    for yh in headrests:
        lo = np.array([x_back - 0.10, yh - 0.13, z_head0])
        hi = np.array([x_back - 0.01, yh + 0.13, z_head1])
        parts.append(box(lo, hi, INTERIOR, rotation=recline, pivot=pivot))
        for yp in (yh - 0.07, yh + 0.07):  # the two posts
            parts.append(box(np.array([x_back - 0.06, yp - 0.006, z_head0 - 0.05]),
                             np.array([x_back - 0.045, yp + 0.006, z_head0 + 0.01]), INTERIOR, rotation=recline,
                             pivot=pivot))
    return parts


CONSOLE_HALF_M = 0.09  # half the gap between the front seats (the centre console)
SEAT_MAX_W_M = 0.56  # a front seat's largest width


def _seat_room(spec: BodySpec, d_back: float) -> tuple[float, float]:
    """(cushion / backrest, headrest) half widths (m) of the cabin at a seat whose backrest stands at d_back: the
    body's room from the floor to the backrest's top, and at the headrests' height (the roof's sides lean in)."""
    floor = _floor(spec, d_back)
    z_cushion, back_h, z_head0, z_head1 = _seat_heights(spec, d_back)
    dd = np.linspace(d_back - 0.5, d_back + 0.15, 6)
    hw_seat = _room_half_width(spec, dd, np.full_like(dd, floor), np.full_like(dd, z_cushion + back_h))
    # The headrests lean back with the backrest (16 deg about the cushion's rear edge): up to ~0.25 m behind it.
    dh = np.linspace(d_back, d_back + 0.3, 6)
    hw_head = _room_half_width(spec, dh, np.full_like(dh, z_head0 - 0.05), np.full_like(dh, z_head1))
    return hw_seat, hw_head


def _front_seat_y(spec: BodySpec) -> tuple[float, float]:
    """(centre |y|, width) (m) of a front seat: it fills its half of the cabin between the console and the side
    (at most :data:`SEAT_MAX_W_M` wide), its headrest kept inside the roof's narrower room."""
    hw_seat, hw_head = _seat_room(spec, spec.pillars[0] + 0.08)
    room = hw_seat - CONSOLE_HALF_M
    width = min(SEAT_MAX_W_M, room - 0.02)
    yc = CONSOLE_HALF_M + 0.5 * room
    return min(yc, hw_head - 0.13), width


def seat_parts(spec: BodySpec) -> list[MeshPart]:
    """Two front seats behind the B pillar's front edge, each as wide as its half of the cabin allows, and a rear
    bench under the roof across the cabin."""
    d_front = spec.pillars[0] + 0.08
    yc, width = _front_seat_y(spec)
    _, d_dash = dashboard_span(spec)
    cushion = float(np.clip(d_front - d_dash - 0.15, 0.35, 0.52))  # leg room left between the dashboard and the seat
    parts = []
    for s in (1.0, -1.0):
        c = s * yc
        parts += _seat(spec, d_front, c - 0.5 * width, c + 0.5 * width, [c], cushion)
    # Rear bench: as far back as the roof leaves room for the headrests, at most 0.9 m behind.
    cand = np.linspace(d_front + 0.95, d_front + 0.6, 8)
    ok = [d for d in cand if _top(spec, d + 0.1) - _MARGIN_M - _belt(spec, d) > 0.42 and d < spec.d_rear - 0.05]
    if ok:
        d_rear = ok[0]
        hw_r, hw_rh = _seat_room(spec, d_rear)
        yh = min(0.5 * hw_r + 0.1, hw_rh - 0.13)
        parts += _seat(spec, d_rear, -hw_r + 0.02, hw_r - 0.02, [yh, -yh])
    return parts


def interior_parts(spec: BodySpec, right_hand_drive: bool) -> list[MeshPart]:
    """Every interior part of a car with body ``spec``; the steering wheel on the right with ``right_hand_drive``."""
    return [dashboard_part(spec), *steering_wheel_parts(spec, right_hand_drive), *seat_parts(spec)]


__all__ = ["dashboard_part", "dashboard_span", "interior_parts", "seat_parts", "steering_wheel_parts"]
