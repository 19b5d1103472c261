"""The tables the renderer derives from an environment map, built once per map content.

:func:`environment_tables` returns the :class:`EnvironmentTables` of a camera-frame equirect map: its
box-filtered pyramid, the reduced copy the importance sampler draws from and the sampler itself, and
the irradiance map of every normal direction.  Each table is built on first use; the tables of the
last :data:`TABLES_CACHE_SIZE` maps are kept, keyed by the map's content (shape, dtype and a digest of
its bytes), so the objects of one image, the cameras of a sample and the frames of a track that share
a light share them too (and an array changed in place is never served stale tables).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Callable, Hashable

import cv2
import numpy as np

from ..core import check_shape
from .sampling import EnvSampler, env_pyramid, irradiance_map, lookup_irradiance

SAMPLER_MAX_WIDTH = 256
TABLES_CACHE_SIZE = 8
_TABLES: "OrderedDict[tuple, EnvironmentTables]" = OrderedDict()


@dataclass(frozen=True, eq=False)
class EnvironmentTables:
    """Derived tables of one camera-frame equirect map (cached properties, built on first use).

    Attributes:
        envmap: (H, W, 3) linear HDR radiance, camera-frame equirect convention (sun excluded); read-only.
    """

    envmap: np.ndarray

    @cached_property
    def pyramid(self) -> list[np.ndarray]:
        """Box-filtered float32 copies of the map, widths W, W/2, ... down to 8 (filtered importance sampling)."""
        return env_pyramid(self.envmap)

    @cached_property
    def sampler_map(self) -> np.ndarray:
        """(h, w, 3) float32 the pyramid level at most :data:`SAMPLER_MAX_WIDTH` wide that :attr:`sampler` samples.

        Environment samples must look their radiance up in this same copy, so that radiance / pdf stays
        bounded (a bright pixel of the full map inside a dimmer sampler texel would otherwise be a firefly).
        """
        return next((lev for lev in self.pyramid if lev.shape[1] <= SAMPLER_MAX_WIDTH), self.pyramid[-1])

    @cached_property
    def sampler(self) -> EnvSampler:
        """Importance sampler of :attr:`sampler_map` (luminance x solid angle)."""
        return EnvSampler.build(self.sampler_map)

    @cached_property
    def irradiance(self) -> np.ndarray:
        """(34, 64, 3) unoccluded irradiance per normal direction (:func:`~.sampling.irradiance_map`)."""
        return irradiance_map(self.envmap)

    def cell_filtered(self, n_dirs: int) -> np.ndarray:
        """The map box-filtered to about the angular size of one of ``n_dirs`` hemisphere lattice cells
        (float32; the map itself when that is as fine as the map); built once per ``n_dirs``."""
        return self.cached(f"cell_filtered_{int(n_dirs)}", (), lambda: _cell_filtered(self.envmap, int(n_dirs)))

    def cached(self, kind: str, key: Hashable, make: Callable[[], Any]) -> Any:
        """``make()`` for this map and ``key``, kept for the last ``key`` of each ``kind`` (a table derived from the
        map and small inputs: ``key`` must name everything besides the map that the value depends on)."""
        hit = self._memo.get(kind)
        if hit is None or hit[0] != key:
            hit = self._memo[kind] = (key, make())
        return hit[1]

    @cached_property
    def _memo(self) -> dict:
        return {}

    def sky_irradiance(self, normal_cam: np.ndarray) -> np.ndarray:
        """Irradiance (3,) on a surface with camera-frame ``normal_cam`` (3,) (normalised here), unoccluded."""
        n = np.asarray(normal_cam, dtype=np.float64)
        return lookup_irradiance(self.irradiance, (n / np.linalg.norm(n))[None])[0]


def environment_tables(envmap: np.ndarray) -> EnvironmentTables:
    """The :class:`EnvironmentTables` of ``envmap`` (H, W, 3), shared by every map of the same content."""
    check_shape(envmap, ("H", "W", 3), "envmap")
    data = np.ascontiguousarray(envmap)
    key = (data.shape, data.dtype.str, hashlib.sha1(data).digest())  # sha1: twice blake2b's speed on a 6 MB map
    tables = _TABLES.get(key)
    if tables is None:
        frozen = data.copy()  # the tables own their map: a caller changing its array later cannot change them
        frozen.setflags(write=False)
        tables = _TABLES[key] = EnvironmentTables(frozen)
        while len(_TABLES) > TABLES_CACHE_SIZE:
            _TABLES.popitem(last=False)
    _TABLES.move_to_end(key)
    return tables


def _cell_filtered(envmap: np.ndarray, n_dirs: int) -> np.ndarray:
    """:meth:`EnvironmentTables.cell_filtered`: ``envmap`` box-filtered to cells of ``2 pi / n_dirs`` sr."""
    cell_rad = np.sqrt(2 * np.pi / n_dirs)
    width = int(2 ** np.round(np.log2(2 * np.pi / cell_rad)))
    width = int(np.clip(width, 8, envmap.shape[1]))
    if width >= envmap.shape[1]:
        return envmap
    return cv2.resize(np.asarray(envmap, dtype=np.float32), (width, max(width // 2, 1)), interpolation=cv2.INTER_AREA)
