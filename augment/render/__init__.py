"""The renderer: one object inserted into one image, physically lit, with its shadow and occlusion.

A one-way chain of stages, each a module that imports only the ones before it (and the core, the
assets and the light types)::

    surface (prepared asset, what is at a ray hit) -> footprint (pixel boxes) -> bounce (the object's own
      light along blocked rays) -> shadow (ratio map) -> shade / foreground (the object's pixels)
      -> composite (box-local layers into the image) -> insert (:func:`render_insertion`)

Callers use this package's API only: :func:`render_insertion` and its :class:`Insertion` result, the
:class:`RenderSettings` with their named :data:`QUALITY_PRESETS`, and :func:`footprint` to ask, before
rendering, whether an object or its shadow reaches an image at all (the renderer uses the same boxes), and
:func:`estimate_veil` / :func:`neutral_axis` to measure an image's haze and veiling glare and its camera's neutral
axis once for all the objects put into it.
"""

from .camera_look import NeutralAxis, neutral_axis
from .footprint import Footprint, PixelBox, footprint
from .insert import Insertion, render_insertion
from .settings import QUALITY_PRESETS, RenderSettings, resolve_settings
from .surface import prepare_asset
from .veil import Veil, estimate_veil

__all__ = ["Footprint", "Insertion", "NeutralAxis", "PixelBox", "QUALITY_PRESETS", "RenderSettings", "Veil",
           "estimate_veil", "footprint", "neutral_axis", "prepare_asset", "render_insertion", "resolve_settings"]
