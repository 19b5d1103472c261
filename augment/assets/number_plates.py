"""Number plates of procedural cars: country styles (size, colours, driving side) and the plate meshes.

A plate is a thin box on the bumper (its face in the object frame's y-z plane, x front) with a row of
dark character blocks slightly proud of it, so it reads as a bright rectangle with a dark band at
distance and as characters up close; or (``anonymised``) a plain plate of its face's mean colour:
nuScenes blurs the plates of its images, and a blurred plate is about that.  Styles follow the nuScenes
locations: Singapore (``sg``, right-hand drive, white front / yellow rear plates or, on most cars, the black
plate with white characters: :data:`PLATE_VARIANTS`), Boston (``us``, the
12 x 6 inch plate) and ``eu`` (the 520 x 110 mm plate with the blue band) for anything else.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .car_body import PLATE_BAND, PLATE_FRONT, PLATE_INK, PLATE_REAR
from .locations import nuscenes_city
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

# Singapore also has (and its older cars mostly carry) the traditional black plate with white characters, front and
# rear.  Share: an estimate; none of the 13 plates of scene-0916 seen at 5-18 m from CAM_FRONT / CAM_BACK is yellow
# (their blurred mean colour: CIELAB b* -8..+4, L* 21-53), while a yellow rear plate blurred keeps b* ~ +60.
SG_BLACK_PLATE = PlateStyle("sg_black", (0.520, 0.115), (0.02, 0.02, 0.02), (0.02, 0.02, 0.02), (0.55, 0.55, 0.55),
                            None, 7, True)
PLATE_VARIANTS: dict[str, tuple[tuple[PlateStyle, float], ...]] = {"sg": ((SG_BLACK_PLATE, 0.7),)}



def plate_style_for_location(location: str) -> str:
    """The plate style of a nuScenes log location (its map name): ``sg``, ``us`` or ``eu`` (any other)."""
    return {"singapore": "sg", "boston": "us"}.get(nuscenes_city(location), "eu")


def check_plate_style(style: str) -> PlateStyle:
    """The :class:`PlateStyle` of ``style``, else a ValueError naming the valid ones."""
    if style not in PLATE_STYLES:
        raise ValueError(f"plate_style must be one of {', '.join(PLATE_STYLES)}, got {style!r}")
    return PLATE_STYLES[style]


def car_plate_style(plate_style: str, seed: int) -> PlateStyle:
    """The plates of the procedural car of ``seed`` in style ``plate_style``: the style itself or one of its
    :data:`PLATE_VARIANTS` (drawn by their shares from the car's own stream ``[seed, 0x9A7E]``)."""
    style = check_plate_style(plate_style)
    u = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x9A7E]).random()
    for variant, share in PLATE_VARIANTS.get(style.name, ()):
        if u < share:
            return variant
        u -= share
    return style


def _box(lo: np.ndarray, hi: np.ndarray, mat: int) -> MeshPart:
    V, F = box_mesh(np.minimum(lo, hi), np.maximum(lo, hi))
    return MeshPart(V, F, np.full(len(F), mat, dtype=np.int64), smooth_vertex_normals(V, F))


def _layout(style: PlateStyle, widths: np.ndarray, separator: int, left_y: float
            ) -> tuple[tuple[float, float, float, float] | None, list[tuple[float, float, float, float]]]:
    """The band and the character blocks of a plate as (y0, y1, dz0, dz1) rectangles (y across the plate,
    dz from its centre height, metres): ``widths`` (n,) the characters' relative widths, ``separator`` the
    index of the wider space, ``left_y`` -1 / +1 the viewer's left end of the plate."""
    w, h = style.size_m
    margin = 0.06 * w
    y_start, y_end = -w / 2 + margin, w / 2 - margin
    band = None
    if style.band_rgb is not None:
        band_w = 0.085 * w
        yb = left_y * (w / 2 - 0.004)
        ya, yc = sorted((yb, yb - left_y * band_w))
        band = (ya, yc, -h / 2 + 0.004, h / 2 - 0.004)
        if left_y < 0:
            y_start = -w / 2 + band_w + 0.02
        else:
            y_end = w / 2 - band_w - 0.02
    n = style.n_chars
    spaces = np.full(n + 1, 0.35)
    spaces[0] = spaces[-1] = 0.0
    spaces[separator] = 1.1
    unit = (y_end - y_start) / (widths.sum() + spaces.sum())
    ch = 0.62 * h
    chars, y = [], y_start
    for k in range(n):
        y += spaces[k] * unit
        chars.append((y, y + widths[k] * unit, -ch / 2, ch / 2))
        y += widths[k] * unit
    return band, chars


# Share of a character's block its strokes cover in typical plate fonts (estimate: stroke width ~ 1/7 of
# the character height; "E" ~ 0.55, "L" ~ 0.3, "8" ~ 0.5): the blocks stand for whole characters.
CHAR_INK_SHARE = 0.45


def anonymised_plate_rgb(style: PlateStyle, rear: bool) -> np.ndarray:
    """Linear RGB (3,) of an anonymised plate: its face's area-weighted mean colour (base, band and the ink of
    the characters of a typical layout, :data:`CHAR_INK_SHARE` of their blocks), what the strong blur of an
    anonymised dataset leaves (nuScenes blurs the plates in its images)."""
    w, h = style.size_m
    n = style.n_chars
    band, chars = _layout(style, np.full(n, 0.9), n // 2, -1.0)
    area = lambda r: (r[1] - r[0]) * (r[3] - r[2])  # noqa: E731
    a_ink = CHAR_INK_SHARE * sum(area(r) for r in chars) / (w * h)
    a_band = area(band) / (w * h) if band is not None else 0.0
    base = np.array(style.rear_rgb if rear else style.front_rgb)
    band_rgb = np.array(style.band_rgb) if style.band_rgb is not None else base
    return (1.0 - a_ink - a_band) * base + a_ink * np.array(style.ink_rgb) + a_band * band_rgb


def plate_part(style: PlateStyle, x_face: float, x_back: float, z_centre: float, rear: bool,
               rng: np.random.Generator, anonymised: bool = False) -> MeshPart:
    """One plate: a box from ``x_back`` to ``x_face`` (its visible face at ``x_face``, metres in the
    object frame; ``x_face > x_back`` at the front, ``<`` at the rear) centred on y = 0 at ``z_centre``,
    with character blocks (and the EU band) 1.5 mm proud of the face; ``anonymised``: the plain box (its
    material then has :func:`anonymised_plate_rgb`; ``rng`` draws the same either way)."""
    w, h = style.size_m
    out = 1.0 if x_face > x_back else -1.0
    parts = [_box(np.array([x_back, -w / 2, z_centre - h / 2]), np.array([x_face, w / 2, z_centre + h / 2]),
                  PLATE_REAR if rear else PLATE_FRONT)]
    x0, x1 = x_face, x_face + out * 0.0015
    # The viewer's left end of the plate: at the front the car's right (-y), at the rear its left (+y).
    left_y = -1.0 if out > 0 else 1.0
    # Characters: n blocks with a random wider space (a group separator) and slightly varied widths.
    widths = rng.uniform(0.8, 1.0, style.n_chars)
    separator = int(rng.integers(2, style.n_chars - 1))
    if not anonymised:
        band, chars = _layout(style, widths, separator, left_y)
        if band is not None:
            parts.append(_box(np.array([x0, band[0], z_centre + band[2]]), np.array([x1, band[1], z_centre + band[3]]),
                              PLATE_BAND))
        for y0, y1, dz0, dz1 in chars:
            parts.append(_box(np.array([x0, y0, z_centre + dz0]), np.array([x1, y1, z_centre + dz1]), PLATE_INK))
    V, F, M = merge_parts(parts)
    return MeshPart(V, F, M, np.concatenate([p.normals for p in parts]))


__all__ = ["CHAR_INK_SHARE", "PLATE_STYLES", "PLATE_VARIANTS", "PlateStyle", "SG_BLACK_PLATE", "anonymised_plate_rgb",
           "car_plate_style", "check_plate_style", "plate_part",
           "plate_style_for_location"]
