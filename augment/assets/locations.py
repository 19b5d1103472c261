"""The city of a nuScenes log location (its map name), what regional asset styles (plates, paint) key on."""

from __future__ import annotations

from typing import Literal

City = Literal["singapore", "boston"]


def nuscenes_city(location: str | None) -> City | None:
    """``singapore`` for singapore-onenorth / -queenstown / -hollandvillage, ``boston`` for boston-seaport
    (any location name starting with the city's), None for any other or None."""
    loc = "" if location is None else str(location).strip().lower()
    if loc.startswith("singapore"):
        return "singapore"
    if loc.startswith("boston"):
        return "boston"
    return None
