"""What the user asks of one insertion (:class:`InsertOptions`) and the seeds derived from it."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np

from ..render import RenderSettings, resolve_settings


@dataclass(frozen=True)
class InsertOptions:
    """Options of one insertion (the CLI maps its flags onto these).

    Attributes:
        quality: render preset, ``draft`` | ``default`` | ``high``.
        level: lighting level, ``L0`` (constant dome) | ``L1`` (sun + parametric sky) | ``L2`` (+ the scene
            volume near the placement) | ``L3`` (full scene volume) | ``auto`` (the cheapest level whose
            predicted error is near the best's, per placement).
        seed: base seed; per-image seeds derive from (seed, sample token, camera).
        n_objects: how many objects to insert into one image.
        yaw_sigma_deg: Gaussian yaw noise around the ego heading (3 realistic, 15 augmentation).
        ev: exposure of the camera response (contract: LDR = response(HDR * 2^EV)).
        match_camera: blur the objects and add noise like the image around them (estimated locally;
            ``RenderSettings.match_camera``), so they are not sharper or cleaner than the photo.
        class_rules: a class-rules file overriding the built-in placement rules per class (None: built-in;
            :func:`streetaug.placement.class_rules.read_class_rules`).
    """

    quality: str = "default"
    level: str = "auto"
    seed: int = 0
    n_objects: int = 1
    yaw_sigma_deg: float = 3.0
    ev: float = 0.0
    match_camera: bool = True
    class_rules: str | None = None


def item_seed(seed: int, *keys: str) -> np.random.Generator:
    """A generator seeded from (seed, keys...) independently of worker count, order and Python's hash salt."""
    digest = hashlib.sha256("|".join([str(seed), *keys]).encode()).digest()
    return np.random.default_rng([seed, int.from_bytes(digest[:8], "little")])


def render_settings(options: InsertOptions) -> RenderSettings:
    """The render preset of ``options.quality`` with ``options.match_camera`` applied."""
    return replace(resolve_settings(options.quality), match_camera=options.match_camera)
