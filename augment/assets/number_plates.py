"""Number plates of procedural cars: country styles (size, colours, driving side) and the plate meshes.

A plate is a thin box on the bumper (its face in the object frame's y-z plane, x front) with a row of
dark character blocks slightly proud of it, so it reads as a bright rectangle with a dark band at
distance and as characters up close.  Styles follow the nuScenes locations: Singapore (``sg``,
right-hand drive, white front / yellow rear plates), Boston (``us``, the 12 x 6 inch plate) and
``eu`` (the 520 x 110 mm plate with the blue band) for anything else.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .car_body import PLATE_BAND, PLATE_FRONT, PLATE_INK, PLATE_REAR
from .mesh_parts import MeshPart, box_mesh, merge_parts
from .validate import smooth_vertex_normals


@dataclass(frozen=True)
class PlateStyle:
    """A country's plates.

    Attributes:
        name: style key (``sg``, ``us``, ``eu``).
        size_m: (width, height) of the plate, metres.
        front_rgb, rear_rgb: linear RGB (3,) base colour of the front / rear plate.
        ink_rgb: linear RGB (3,) of the characters.
        band_rgb: linear RGB (3,) of a band at the plate's left end (EU blue), or None.
        n_chars: number of character blocks.
        right_hand_drive: the steering wheel on the car's right (traffic on the left).
    """

    name: str
    size_m: tuple[float, float]
    front_rgb: tuple[float, float, float]
    rear_rgb: tuple[float, float, float]
    ink_rgb: tuple[float, float, float]
    band_rgb: tuple[float, float, float] | None
    n_chars: int
    right_hand_drive: bool


PLATE_STYLES: dict[str, PlateStyle] = {
    "sg": PlateStyle("sg", (0.520, 0.115), (0.80, 0.80, 0.78), (0.85, 0.62, 0.04), (0.012, 0.012, 0.012), None, 7,
                     True),
    "us": PlateStyle("us", (0.305, 0.152), (0.78, 0.78, 0.80), (0.78, 0.78, 0.80), (0.10, 0.012, 0.015), None, 6,
                     False),
    "eu": PlateStyle("eu", (0.520, 0.110), (0.80, 0.80, 0.78), (0.80, 0.80, 0.78), (0.012, 0.012, 0.012),
                     (0.01, 0.04, 0.35), 7, False),
}

_SINGAPORE = ("singapore-onenorth", "singapore-queenstown", "singapore-hollandvillage")
_BOSTON = ("boston-seaport",)


def plate_style_for_location(location: str) -> str:
    """The plate style of a nuScenes log location (its map name): ``sg``, ``us`` or ``eu`` (any other)."""
    loc = str(location).strip().lower()
    if loc in _SINGAPORE or loc.startswith("singapore"):
        return "sg"
    if loc in _BOSTON or loc.startswith("boston"):
        return "us"
    return "eu"


def check_plate_style(style: str) -> PlateStyle:
    """The :class:`PlateStyle` of ``style``, else a ValueError naming the valid ones."""
    if style not in PLATE_STYLES:
        raise ValueError(f"plate_style must be one of {', '.join(PLATE_STYLES)}, got {style!r}")
    return PLATE_STYLES[style]


def _box(lo: np.ndarray, hi: np.ndarray, mat: int) -> MeshPart:
    V, F = box_mesh(np.minimum(lo, hi), np.maximum(lo, hi))
    return MeshPart(V, F, np.full(len(F), mat, dtype=np.int64), smooth_vertex_normals(V, F))


def plate_part(style: PlateStyle, x_face: float, x_back: float, z_centre: float, rear: bool,
               rng: np.random.Generator) -> MeshPart:
    """One plate: a box from ``x_back`` to ``x_face`` (its visible face at ``x_face``, metres in the
    object frame; ``x_face > x_back`` at the front, ``<`` at the rear) centred on y = 0 at ``z_centre``,
    with character blocks (and the EU band) 1.5 mm proud of the face."""
    w, h = style.size_m
    out = 1.0 if x_face > x_back else -1.0
    parts = [_box(np.array([x_back, -w / 2, z_centre - h / 2]), np.array([x_face, w / 2, z_centre + h / 2]),
                  PLATE_REAR if rear else PLATE_FRONT)]
    x0, x1 = x_face, x_face + out * 0.0015
    # The viewer's left end of the plate: at the front the car's right (-y), at the rear its left (+y).
    left_y = -1.0 if out > 0 else 1.0
    margin = 0.06 * w
    y_start, y_end = -w / 2 + margin, w / 2 - margin
    if style.band_rgb is not None:
        band_w = 0.085 * w
        yb = left_y * (w / 2 - 0.004)
        parts.append(_box(np.array([x0, yb, z_centre - h / 2 + 0.004]),
                          np.array([x1, yb - left_y * band_w, z_centre + h / 2 - 0.004]), PLATE_BAND))
        if left_y < 0:
            y_start = -w / 2 + band_w + 0.02
        else:
            y_end = w / 2 - band_w - 0.02
    # Characters: n blocks with a random wider space (a group separator) and slightly varied widths.
    n = style.n_chars
    widths = rng.uniform(0.8, 1.0, n)
    spaces = np.full(n + 1, 0.35)
    spaces[0] = spaces[-1] = 0.0
    spaces[int(rng.integers(2, n - 1))] = 1.1
    unit = (y_end - y_start) / (widths.sum() + spaces.sum())
    ch = 0.62 * h
    y = y_start
    for k in range(n):
        y += spaces[k] * unit
        parts.append(_box(np.array([x0, y, z_centre - ch / 2]), np.array([x1, y + widths[k] * unit, z_centre + ch / 2]),
                          PLATE_INK))
        y += widths[k] * unit
    V, F, M = merge_parts(parts)
    return MeshPart(V, F, M, np.concatenate([p.normals for p in parts]))


__all__ = ["PLATE_STYLES", "PlateStyle", "check_plate_style", "plate_part", "plate_style_for_location"]
