"""Render quality settings and the named presets (``--quality draft|default|high``)."""

from __future__ import annotations

from dataclasses import dataclass

from ..core import InputError


@dataclass(frozen=True)
class RenderSettings:
    """Knobs of the renderer.

    Attributes:
        aa_grid: n, camera samples per pixel = n x n (stratified, jittered) over the object's box.
        edge_grid: k, extra k x k camera samples in silhouette pixels (anti-aliasing where it matters).
        sun_samples: sun-disc directions per shading sample (with self-shadowing rays).
        env_samples: environment-map importance samples per shading sample (MIS).
        brdf_samples: BRDF (GGX / cosine) samples per shading sample (MIS).
        max_glass_depth: how many surfaces a camera ray may pass through (glass) before it stops.
        shadow_factor: the shadow ratio map is computed every ``shadow_factor`` pixels and upsampled.
        shadow_sky_dirs: sky directions per shadow cell (a Fibonacci spiral in the cone towards the object).
        shadow_sun_dirs: sun-disc directions per pixel at the sun shadow's edge (penumbra, anti-aliasing).
        shadow_max_length_m: longest sun shadow considered (low suns), metres along the ground.
        denoise: smooth the object's Monte Carlo noise with a G-buffer-guided cross-bilateral filter.
        match_camera: blur the object and add noise like the input image's (estimated from it, see
            :mod:`streetaug.augment.render.camera_effects`); on by default (False turns it off).
    """

    aa_grid: int = 1
    edge_grid: int = 4
    sun_samples: int = 1
    env_samples: int = 1
    brdf_samples: int = 2
    max_glass_depth: int = 3
    shadow_factor: int = 4
    shadow_sky_dirs: int = 24
    shadow_sun_dirs: int = 8
    shadow_max_length_m: float = 30.0
    denoise: bool = True
    match_camera: bool = True

    def __post_init__(self) -> None:
        for name in ("aa_grid", "edge_grid", "shadow_factor", "shadow_sky_dirs", "shadow_sun_dirs", "max_glass_depth"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"RenderSettings.{name} must be >= 1, got {getattr(self, name)}")
        for name in ("sun_samples", "env_samples", "brdf_samples"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"RenderSettings.{name} must be >= 0, got {getattr(self, name)}")
        if self.env_samples + self.brdf_samples == 0:
            raise ValueError("RenderSettings: env_samples + brdf_samples must be >= 1")


QUALITY_PRESETS: dict[str, RenderSettings] = {
    "draft": RenderSettings(aa_grid=1, edge_grid=3, sun_samples=1, env_samples=1, brdf_samples=1,
                            max_glass_depth=2, shadow_factor=6, shadow_sky_dirs=12, shadow_sun_dirs=4),
    "default": RenderSettings(),
    "high": RenderSettings(aa_grid=2, edge_grid=6, sun_samples=2, env_samples=2, brdf_samples=4,
                           max_glass_depth=4, shadow_factor=3, shadow_sky_dirs=32, shadow_sun_dirs=16),
}


def resolve_settings(quality: str | RenderSettings) -> RenderSettings:
    """Explicit settings as they are, or the :data:`QUALITY_PRESETS` entry of a name (else a clear error)."""
    if isinstance(quality, RenderSettings):
        return quality
    if quality not in QUALITY_PRESETS:
        raise InputError(f"quality: expected one of {sorted(QUALITY_PRESETS)}, got {quality!r}")
    return QUALITY_PRESETS[quality]
