"""Car paint colours: shades grouped in colour families, and each region's share of every family.

Family shares follow Axalta's *Global Automotive Color Popularity Report* (new cars built, by region).
Approximate: ``global`` is the 2022 report's world figures (white 34 %, black 21 %, grey 19 %, blue 8 %,
red 5 %, green 1 %, silver the rest of the 82 % of neutrals, ~8 %); the regions take the figures the
reports' summaries quote (Asia: white 49 % in the 2019 report; North America: white ~25 %, the most red
of any region, 8-11 %, 2014-2021 reports; Europe: grey 27 % and black 22 %, 2021 report) and fill the
other families near the world shares so that each sums to 100 %.  Not fitted to any scene.  Regions:
``asia_pacific`` (nuScenes' Singapore logs), ``north_america`` (Boston), ``europe`` and ``global`` (any
other or unknown location).  Within a family the shades' shares are the same everywhere (grey: light,
mid and dark greys in similar shares).

White paints are neutral by construction (sRGB channels equal within 1-2 levels, CIELAB b* between -1.5
and +0.5): real white paints seen in daylight measure about neutral (solid "pure" whites of chip books
are b* ~ -1 to +1); the old cream / warm pearl whites (b* +3.6 / +7.4) made every white car yellowish.
White paints are also not brighter than paint is: solid whites of paint chip books measure L* ~90-94 with the
specular excluded (what a base colour is: the clear coat's 4 % comes on top), and a car in service carries a
road film; the old F2F2F2 / EAEBEC / EDEFF1 (L* 95.2 / 93.0 / 94.0), times the per-car variation of up to 7 %,
drew a third of the white cars at L* 95-98. The whites are now L* 91.2-92.0 and every drawn paint is scaled down to
:data:`MAX_PAINT_ALBEDO` (L* 93) in its brightest channel.
"metallic" is how metallic a paint looks: the flakes' share of the base coat (``Material.flake``).
"""

from __future__ import annotations

import numpy as np

from .locations import nuscenes_city

# (family, name, sRGB hex, metallic, share within the family)
_SHADES: tuple[tuple[str, str, str, float, float], ...] = (
    ("white", "pure white", "E8E8E8", 0.0, 0.40),
    ("white", "pearl white", "E5E6E7", 0.3, 0.35),
    ("white", "arctic white", "E6E8EA", 0.0, 0.25),
    ("black", "jet black", "0C0C0D", 0.0, 0.45),
    ("black", "black metallic", "141518", 0.5, 0.40),
    ("black", "midnight black", "1A1B20", 0.4, 0.15),
    ("grey", "graphite grey", "3C3F44", 0.6, 0.20),
    ("grey", "gunmetal grey", "53565C", 0.6, 0.20),
    ("grey", "dark grey", "2E3034", 0.5, 0.10),
    ("grey", "mid grey", "6E7074", 0.4, 0.20),
    ("grey", "nardo grey", "8A8C8C", 0.0, 0.15),
    ("grey", "cement grey", "9C9E9E", 0.2, 0.15),
    ("silver", "silver", "B5B8BB", 0.7, 0.55),
    ("silver", "bright silver", "C8CACC", 0.7, 0.30),
    ("silver", "champagne silver", "BDB5A6", 0.6, 0.15),
    ("blue", "navy blue", "1B2A4A", 0.5, 0.25),
    ("blue", "dark blue", "1F3560", 0.5, 0.25),
    ("blue", "royal blue", "2A4F9C", 0.4, 0.20),
    ("blue", "sky blue", "6F9CC8", 0.3, 0.12),
    ("blue", "steel blue", "4A6580", 0.5, 0.18),
    ("red", "bright red", "B01C1C", 0.0, 0.35),
    ("red", "dark red", "6E1418", 0.4, 0.20),
    ("red", "candy red", "9A1420", 0.5, 0.30),
    ("red", "maroon", "4E1A22", 0.4, 0.15),
    ("brown", "beige", "C2B28F", 0.2, 0.40),
    ("brown", "bronze", "7A5B3C", 0.6, 0.30),
    ("brown", "brown", "4A3528", 0.4, 0.30),
    ("green", "racing green", "1E3B2C", 0.4, 0.35),
    ("green", "olive green", "55603E", 0.3, 0.35),
    ("green", "teal", "1F5D63", 0.4, 0.30),
    ("yellow", "yellow", "E3B521", 0.1, 0.60),
    ("yellow", "taxi yellow", "F0B21A", 0.0, 0.40),
    ("other", "orange", "D9621C", 0.2, 0.60),
    ("other", "purple", "3E2A52", 0.5, 0.40),
)

MAX_PAINT_ALBEDO = 0.83  # linear, the brightest channel of any drawn paint (sRGB 0.92, L* ~93)

# Percent of new cars per colour family (Axalta reports, approximate: see the module docstring).
REGION_FAMILY_SHARES: dict[str, dict[str, float]] = {
    "global": {"white": 34, "black": 21, "grey": 19, "silver": 8, "blue": 8, "red": 5, "brown": 2, "green": 1,
               "yellow": 1, "other": 1},
    "asia_pacific": {"white": 48, "black": 15, "grey": 11, "silver": 11, "blue": 5, "red": 5, "brown": 2,
                     "green": 1, "yellow": 1, "other": 1},
    "north_america": {"white": 25, "black": 21, "grey": 20, "silver": 11, "blue": 9, "red": 9, "brown": 2,
                      "green": 1, "yellow": 1, "other": 1},
    "europe": {"white": 24, "black": 22, "grey": 27, "silver": 9, "blue": 9, "red": 5, "brown": 2, "green": 1,
               "yellow": 0.5, "other": 0.5},
}



def paint_region_for_location(location: str | None) -> str:
    """The paint region of a nuScenes log location (its map name): ``asia_pacific`` (Singapore),
    ``north_america`` (Boston) or ``global`` (any other, or None)."""
    return {"singapore": "asia_pacific", "boston": "north_america"}.get(nuscenes_city(location), "global")


def check_paint_region(region: str) -> str:
    """``region`` if it is a key of :data:`REGION_FAMILY_SHARES`, else a ValueError naming the valid ones."""
    if region not in REGION_FAMILY_SHARES:
        raise ValueError(f"paint_region must be one of {', '.join(REGION_FAMILY_SHARES)}, got {region!r}")
    return region


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB in [0, 1] -> linear RGB (same shape)."""
    c = np.asarray(srgb, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def paint_palette(region: str = "global") -> list[tuple[str, np.ndarray, float, float]]:
    """The paint palette of ``region`` as (name, linear RGB (3,), metallic, weight) entries (>= 30 colours);
    the weights sum to 1 (the region's family share x the shade's share within its family)."""
    shares = REGION_FAMILY_SHARES[check_paint_region(region)]
    total = sum(shares.values())
    out = []
    for family, name, hexcode, metallic, within in _SHADES:
        srgb = np.array([int(hexcode[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0
        out.append((name, srgb_to_linear(srgb), metallic, shares[family] / total * within))
    return out


def paint_family(name: str) -> str:
    """The colour family (``white``, ``black``, ``grey``, ...) of the palette shade ``name``."""
    for family, shade, *_ in _SHADES:
        if shade == name:
            return family
    raise KeyError(name)


__all__ = ["MAX_PAINT_ALBEDO", "REGION_FAMILY_SHARES", "check_paint_region", "paint_family", "paint_palette",
           "paint_region_for_location", "srgb_to_linear"]
