"""The scene's light: from a camera view, a sample's cameras or a bare image to an HDR lighting estimate.

The front door is :mod:`.api` (the only place choosing the sun's source: the ephemeris, the learned image model
of :mod:`.skynet`, or none, for every level L0..L3 and ``auto``); the results are the typed
:class:`LightingEstimate` (one camera, its frame and scale) and :class:`SampleLighting` (a sample's cameras
sharing one sun, sky dome and volume), written out by :func:`write_lighting_outputs`. Inside: image evidence
(:mod:`.evidence`), the parametric sky fit (:mod:`.parametric`, :mod:`.sky`, :mod:`.sun`), the learned sky
(:mod:`.learned`), the hybrid volume (:mod:`.observe`, :mod:`.skydome`, :mod:`.build`, :mod:`.volume`,
:mod:`.multiview`) and the light types the renderer reads (:mod:`.light`).
"""

from importlib import import_module

# public name -> the module defining it; imported on first use (PEP 562) so that reading the light types
# (``lighting.light``, what the renderer imports) does not import torch and the learned models
_PUBLIC = {
    "estimate_lighting": "api", "estimate_lighting_from_image": "api", "estimate_sample_lighting": "api",
    "estimate_views_lighting": "api", "image_only_view": "api",
    "DistantLight": "light", "SunLight": "light",
    "write_lighting_outputs": "outputs",
    "LEVEL_REQUESTS": "types", "Level": "types", "LevelRequest": "types", "LightingEstimate": "types",
    "ParametricFit": "types", "SampleLighting": "types", "SunSource": "types",
}
__all__ = list(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f".{_PUBLIC[name]}", __name__), name)
