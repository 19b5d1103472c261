"""The Asset data object: a triangle mesh in metres with PBR materials and a canonical box.

Convention (object frame, same as a nuScenes box frame): x = the object's front, y = its left,
z = up; the origin is at the bottom centre of the axis-aligned bounding box (so the box spans
z in [0, h]).  ``wlh`` = (extent along y, along x, along z).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..core import check_shape


@dataclass(frozen=True)
class Material:
    """UE4 / simplified Disney material (all colours linear RGB in [0, 1]).

    Attributes:
        name: material name from the asset (or a generated one).
        base_color: (3,) base colour.
        metallic, roughness, specular: UE4 parameters (specular 0.5 = 4 % reflectance at normal incidence).
        opacity: 1 = opaque; < 1 for glass (the renderer blends the environment seen through it).
        emission: (3,) emitted radiance (lights), usually zero.
        clearcoat: 0..1 strength of a smooth clear-coat lobe over the base (car paint).
        retroreflective: 0..1 strength of a retro-reflective lobe (light sent back towards where it came
            from: the reflective bands of cones and barriers, number plates).
        flake: 0..1 share of the base layer that is metallic flakes (metallic car paint: a glossier,
            base-coloured metallic lobe under the clear coat); 0 for plain paint and other materials.
        base_color_texture: optional (h, w, 3) float32 linear texture multiplied with ``base_color``.
        metallic_roughness_texture: optional (h, w, 3) float32 (glTF: G = roughness, B = metallic).
        normal_texture: optional (h, w, 3) float32 tangent-space normal map in [0, 1].
    """

    name: str
    base_color: np.ndarray
    metallic: float = 0.0
    roughness: float = 0.5
    specular: float = 0.5
    opacity: float = 1.0
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    clearcoat: float = 0.0
    retroreflective: float = 0.0
    flake: float = 0.0
    base_color_texture: np.ndarray | None = None
    metallic_roughness_texture: np.ndarray | None = None
    normal_texture: np.ndarray | None = None


@dataclass(frozen=True)
class Asset:
    """A renderable object.

    Attributes:
        name: identifier (file stem or generator description).
        vertices: (V, 3) float64 positions in the object frame, metres.
        faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside.
        face_material: (F,) int64 index into ``materials`` per face.
        materials: the material table.
        vertex_normals: (V, 3) float64 unit smooth-shading normals (object frame).
        uv: (V, 2) float64 texture coordinates, or None.
        category: nuScenes category of the object, e.g. ``vehicle.car``.
        attribute: the nuScenes attribute the asset's own shape implies, or None: ``cycle.with_rider`` /
            ``cycle.without_rider`` (a rider is modelled or not), ``pedestrian.moving`` /
            ``pedestrian.standing`` (walking or standing pose). Vehicle motion states come from placement.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    materials: tuple[Material, ...]
    vertex_normals: np.ndarray
    uv: np.ndarray | None = None
    category: str = "vehicle.car"
    attribute: str | None = None
    # Values later stages derive from this (immutable) asset, e.g. the renderer's BVH: see :meth:`derived`.
    _derived: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def derived(self, key: str, build: Callable[["Asset"], Any]) -> Any:
        """``build(self)``, computed on the first call for ``key`` and kept with this asset afterwards.

        For data a later stage derives from the asset (the renderer keys its prepared ray-tracing copy
        ``"render.prepared.<backend>"``): it lives exactly as long as the asset and is never pickled.
        """
        if key not in self._derived:
            self._derived[key] = build(self)
        return self._derived[key]

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_derived"] = {}  # derived data (BVHs) is rebuilt where it is needed, not shipped
        return state

    def __post_init__(self) -> None:
        check_shape(self.vertices, ("V", 3), f"asset {self.name}: vertices")
        check_shape(self.faces, ("F", 3), f"asset {self.name}: faces")
        check_shape(self.face_material, (len(self.faces),), f"asset {self.name}: face_material")
        check_shape(self.vertex_normals, (len(self.vertices), 3), f"asset {self.name}: vertex_normals")

    @property
    def wlh(self) -> np.ndarray:
        """Box size (3,) = (width along y, length along x, height along z), metres."""
        ext = self.vertices.max(axis=0) - self.vertices.min(axis=0)
        return np.array([ext[1], ext[0], ext[2]])

    @property
    def box_center_object(self) -> np.ndarray:
        """Centre (3,) of the axis-aligned box in the object frame (x, y ~ 0, z = h / 2)."""
        return (self.vertices.max(axis=0) + self.vertices.min(axis=0)) / 2.0
