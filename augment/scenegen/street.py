"""Procedural street scenes: layout, triangle meshes, surface materials and annotated objects.

Frames: the street is laid out in a *street frame* (x = the ego's direction of travel along the road,
y = left, z = up, metres, origin on the road's centre line (the ego stands at x = 0 in its lane)) and
placed into the global (map) frame by ``T_global_from_street`` (a yaw about z plus a translation).
The road surface is the plane z = 0 (nuScenes: ego z = 0 at ground level).

Everything is deterministic for a given :class:`StreetParams` (seeded ``numpy.random.Generator``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from streetaug.augment.core import make_transform, rotation_to_quat, transform_points, yaw_to_quat
from streetaug.datasets.nuscenes_format import (LIDARSEG_CAR, LIDARSEG_DRIVEABLE, LIDARSEG_MANMADE, LIDARSEG_SIDEWALK,
                                                LIDARSEG_TERRAIN, LIDARSEG_TRAFFICCONE, LIDARSEG_VEGETATION)
from streetaug.datasets.sample import Box

from .primitives import Mesh, box_solid, frustum, icosphere, prism, quad, rect_xy, wheel_cylinder

ROAD_HALF_WIDTH_M = 8.0  # kerb to kerb 16 m: 2 x (2 lanes of 2.8 m + a 2.4 m parking strip)
LANE_WIDTH_M = 2.8
SIDEWALK_WIDTH_M = 4.0
KERB_HEIGHT_M = 0.15
ROAD_X_RANGE_M = (-150.0, 600.0)
BUILDING_X_RANGE_M = (-110.0, 330.0)
GROUND_HALF_SIZE_M = 700.0
GROUND_Z_M = -0.02  # terrain plane sits just below the road so the road always wins


@dataclass(frozen=True)
class SurfaceMaterial:
    """A diffuse street material with an optional procedural pattern.

    Attributes:
        name: unique name.
        albedo: (3,) linear RGB base albedo in [0, 1].
        label: nuScenes-lidarseg class index of points on this surface.
        pattern: ``plain`` | ``asphalt`` | ``paving`` | ``grass`` | ``facade`` | ``paint`` | ``foliage``.
        gloss: strength (0..1) of a mirror-like sky reflection (glass, windows of facades).
        lidar_reflectivity: 0..1, scales the simulated LiDAR intensity.
        window_albedo: (3,) albedo of window panes (``facade`` pattern only).
        floor_height_m, window_pitch_m: facade grid (``facade`` pattern only).
    """

    name: str
    albedo: tuple[float, float, float]
    label: int
    pattern: str = "plain"
    gloss: float = 0.0
    lidar_reflectivity: float = 0.3
    window_albedo: tuple[float, float, float] = (0.04, 0.05, 0.06)
    floor_height_m: float = 3.2
    window_pitch_m: float = 2.6


@dataclass(frozen=True)
class StreetObject:
    """An annotated object in the street frame (becomes a nuScenes ``sample_annotation``).

    Attributes:
        category: nuScenes category name.
        center_street: (3,) box centre (gravity centre), street frame, metres.
        wlh: (3,) width, length, height in metres.
        yaw_street: heading (rad) of the box's +x in the street frame, counter-clockwise from +x.
        attribute: nuScenes attribute name or '' (none).
    """

    category: str
    center_street: np.ndarray
    wlh: np.ndarray
    yaw_street: float
    attribute: str = ""


@dataclass(frozen=True)
class StreetParams:
    """Knobs of one generated street.

    Attributes:
        seed: RNG seed of every random choice.
        drive_on_left: left-hand traffic (Singapore): the ego drives in a lane with y > 0.
        free_ahead_m: (start, end) of the stretch ahead of the ego kept free of parked cars and cones
            on the ego's side of the road (travel lanes are always free up to ``free_ahead_m[1]``).
    """

    seed: int = 0
    drive_on_left: bool = False
    free_ahead_m: tuple[float, float] = (8.0, 42.0)


@dataclass(frozen=True)
class StreetScene:
    """A whole street as one triangle mesh in the global frame.

    Attributes:
        vertices_global: (V, 3) float64 vertex positions, global frame, metres.
        faces: (F, 3) int64 vertex indices.
        face_material: (F,) int64 index into ``materials``.
        face_object: (F,) int64 index into ``objects`` for faces of annotated objects, else -1.
        materials: material table.
        objects: annotated objects as global-frame boxes (``Box.token`` is '').
        object_attributes: attribute name per object ('' for none).
        T_global_from_street: (4, 4) street frame -> global.
        T_global_from_ego: (4, 4) ego pose at the keyframe.
        drivable_polygons_global: list of (N, 2) float64 counter-clockwise polygons (global x, y).
        lanes_global: travel lanes as (start_xy (2,), end_xy (2,), width_m): straight centre lines in the
            direction of travel (global x, y).
    """

    vertices_global: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    face_object: np.ndarray
    materials: tuple[SurfaceMaterial, ...]
    objects: tuple[Box, ...]
    object_attributes: tuple[str, ...]
    T_global_from_street: np.ndarray
    T_global_from_ego: np.ndarray
    drivable_polygons_global: list = field(default_factory=list)
    lanes_global: list = field(default_factory=list)

    @property
    def face_label(self) -> np.ndarray:
        """(F,) uint8 lidarseg label of every face."""
        labels = np.array([m.label for m in self.materials], dtype=np.uint8)
        return labels[self.face_material]

    @property
    def face_normals_global(self) -> np.ndarray:
        """(F, 3) unit geometric normals (counter-clockwise winding), global frame."""
        tri = self.vertices_global[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


# ----------------------------------------------------------------------------- builder


class _MeshBuilder:
    """Accumulates parts (street frame) with a material and an optional annotated-object index."""

    def __init__(self) -> None:
        self.vertices: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.face_material: list[np.ndarray] = []
        self.face_object: list[np.ndarray] = []
        self.materials: list[SurfaceMaterial] = []
        self._material_index: dict[str, int] = {}
        self._n = 0

    def material(self, m: SurfaceMaterial) -> int:
        if m.name not in self._material_index:
            self._material_index[m.name] = len(self.materials)
            self.materials.append(m)
        return self._material_index[m.name]

    def add(self, part: tuple[np.ndarray, np.ndarray], material: SurfaceMaterial, obj: int = -1,
            T_street_from_part: np.ndarray | None = None) -> None:
        v, f = part
        if T_street_from_part is not None:
            v = transform_points(T_street_from_part, v)
        mid = self.material(material)
        self.vertices.append(np.asarray(v, dtype=np.float64))
        self.faces.append(np.asarray(f, dtype=np.int64) + self._n)
        self.face_material.append(np.full(len(f), mid, dtype=np.int64))
        self.face_object.append(np.full(len(f), obj, dtype=np.int64))
        self._n += len(v)


# ----------------------------------------------------------------------------- palettes

_BUILDING_COLOURS = [
    (0.42, 0.20, 0.14), (0.55, 0.45, 0.33), (0.60, 0.58, 0.54), (0.62, 0.58, 0.51), (0.35, 0.35, 0.36),
    (0.62, 0.52, 0.40), (0.50, 0.28, 0.20), (0.64, 0.62, 0.58), (0.45, 0.48, 0.52), (0.66, 0.60, 0.45),
]
_CAR_COLOURS = [
    (0.62, 0.62, 0.63), (0.03, 0.03, 0.035), (0.70, 0.71, 0.71), (0.30, 0.31, 0.33), (0.45, 0.03, 0.03),
    (0.04, 0.10, 0.30), (0.55, 0.55, 0.56), (0.12, 0.20, 0.12), (0.50, 0.40, 0.25), (0.62, 0.10, 0.04),
]

M_ASPHALT = SurfaceMaterial("asphalt", (0.12, 0.12, 0.125), LIDARSEG_DRIVEABLE, "asphalt", lidar_reflectivity=0.08)
M_PAINT_WHITE = SurfaceMaterial("paint_white", (0.62, 0.62, 0.60), LIDARSEG_DRIVEABLE, "paint", lidar_reflectivity=0.6)
M_PAINT_YELLOW = SurfaceMaterial("paint_yellow", (0.60, 0.42, 0.08), LIDARSEG_DRIVEABLE, "paint", lidar_reflectivity=0.55)
M_SIDEWALK = SurfaceMaterial("sidewalk", (0.30, 0.29, 0.27), LIDARSEG_SIDEWALK, "paving", lidar_reflectivity=0.2)
M_KERB = SurfaceMaterial("kerb", (0.38, 0.37, 0.35), LIDARSEG_SIDEWALK, "plain", lidar_reflectivity=0.25)
M_TERRAIN = SurfaceMaterial("terrain", (0.09, 0.12, 0.05), LIDARSEG_TERRAIN, "grass", lidar_reflectivity=0.15)
M_POLE = SurfaceMaterial("pole", (0.25, 0.26, 0.27), LIDARSEG_MANMADE, "plain", lidar_reflectivity=0.4)
M_LAMP = SurfaceMaterial("lamp", (0.55, 0.55, 0.52), LIDARSEG_MANMADE, "plain", lidar_reflectivity=0.4)
M_TRUNK = SurfaceMaterial("trunk", (0.16, 0.11, 0.07), LIDARSEG_VEGETATION, "plain", lidar_reflectivity=0.2)
M_FOLIAGE = SurfaceMaterial("foliage", (0.07, 0.14, 0.04), LIDARSEG_VEGETATION, "foliage", lidar_reflectivity=0.25)
M_TYRE = SurfaceMaterial("tyre", (0.03, 0.03, 0.03), LIDARSEG_CAR, "plain", lidar_reflectivity=0.1)
M_CAR_GLASS = SurfaceMaterial("car_glass", (0.02, 0.025, 0.03), LIDARSEG_CAR, "plain", gloss=0.3, lidar_reflectivity=0.05)
M_HEADLIGHT = SurfaceMaterial("headlight", (0.75, 0.75, 0.72), LIDARSEG_CAR, "plain", gloss=0.3, lidar_reflectivity=0.8)
M_TAILLIGHT = SurfaceMaterial("taillight", (0.45, 0.02, 0.02), LIDARSEG_CAR, "plain", gloss=0.3, lidar_reflectivity=0.8)
M_CONE = SurfaceMaterial("cone", (0.80, 0.18, 0.02), LIDARSEG_TRAFFICCONE, "plain", lidar_reflectivity=0.7)


# ----------------------------------------------------------------------------- street parts


def _add_ground(b: _MeshBuilder) -> None:
    x0, x1 = ROAD_X_RANGE_M
    hw = ROAD_HALF_WIDTH_M
    g = GROUND_HALF_SIZE_M
    b.add(quad([-g, -g, GROUND_Z_M], [g, -g, GROUND_Z_M], [g, g, GROUND_Z_M], [-g, g, GROUND_Z_M]), M_TERRAIN)
    b.add(quad([x0, -hw, 0], [x1, -hw, 0], [x1, hw, 0], [x0, hw, 0]), M_ASPHALT)
    h, w = KERB_HEIGHT_M, SIDEWALK_WIDTH_M
    for side in (-1, 1):
        y_in, y_out = side * hw, side * (hw + w)
        top = [[x0, y_in, h], [x1, y_in, h], [x1, y_out, h], [x0, y_out, h]]
        if side < 0:
            top = top[::-1]
        b.add(quad(*top), M_SIDEWALK)
        kerb = [[x0, y_in, 0], [x1, y_in, 0], [x1, y_in, h], [x0, y_in, h]]
        if side > 0:
            kerb = [kerb[1], kerb[0], kerb[3], kerb[2]]
        b.add(quad(*kerb), M_KERB)


def _add_lane_marks(b: _MeshBuilder) -> None:
    z = 0.004
    x0, x1 = ROAD_X_RANGE_M

    def strip(xa, xb, ya, yb, m):
        b.add(quad([xa, ya, z], [xb, ya, z], [xb, yb, z], [xa, yb, z]), m)

    for yc in (-0.14, 0.14):  # double yellow centre line
        strip(x0, x1, yc - 0.06, yc + 0.06, M_PAINT_YELLOW)
    edge = 2 * LANE_WIDTH_M
    for side in (-1, 1):
        yc = side * edge  # solid line between the travel lanes and the parking strip
        strip(x0, x1, yc - 0.075, yc + 0.075, M_PAINT_WHITE)
        yc = side * LANE_WIDTH_M  # dashed lane divider: 3 m dash, 9 m period
        starts = np.arange(x0, x1, 9.0)
        for xs in starts:
            strip(xs, xs + 3.0, yc - 0.075, yc + 0.075, M_PAINT_WHITE)
    # a zebra crossing beyond the free stretch
    for k in range(int(2 * ROAD_HALF_WIDTH_M / 1.0)):
        ya = -ROAD_HALF_WIDTH_M + 0.3 + k * 1.0
        if abs(ya + 0.25) < 0.35:
            continue
        strip(62.0, 66.0, ya, ya + 0.5, M_PAINT_WHITE)


def _add_buildings(b: _MeshBuilder, rng: np.random.Generator) -> None:
    y_front = ROAD_HALF_WIDTH_M + SIDEWALK_WIDTH_M
    for side in (-1, 1):
        x = BUILDING_X_RANGE_M[0] + rng.uniform(0, 10)
        k = 0
        while x < BUILDING_X_RANGE_M[1]:
            length = rng.uniform(12.0, 34.0)
            depth = rng.uniform(10.0, 22.0)
            height = rng.choice([rng.uniform(7.0, 14.0), rng.uniform(14.0, 36.0)])
            setback = rng.choice([0.0, 0.0, rng.uniform(0.5, 3.0)])
            colour = _BUILDING_COLOURS[rng.integers(len(_BUILDING_COLOURS))]
            tint = np.clip(np.asarray(colour) * rng.uniform(0.85, 1.1), 0, 1)
            m = SurfaceMaterial(
                f"building_{side:+d}_{k}", tuple(float(c) for c in tint), LIDARSEG_MANMADE, "facade",
                gloss=0.25, lidar_reflectivity=0.35,
                window_albedo=tuple(float(c) for c in rng.uniform(0.02, 0.07) * np.array([0.9, 1.0, 1.15])),
                floor_height_m=float(rng.uniform(3.0, 3.8)), window_pitch_m=float(rng.uniform(2.2, 3.4)),
            )
            y_in = side * (y_front + setback)
            y_out = side * (y_front + setback + depth)
            b.add(box_solid(x + length / 2, (y_in + y_out) / 2, length, depth, 0.0, height), m)
            x += length + rng.choice([0.0, 0.0, rng.uniform(2.0, 6.0)])
            k += 1
    # a few far blocks that close the view at the ends of the street
    for j, xc in enumerate((-260.0, 460.0, 520.0)):
        colour = _BUILDING_COLOURS[rng.integers(len(_BUILDING_COLOURS))]
        m = SurfaceMaterial(f"far_block_{j}", colour, LIDARSEG_MANMADE, "facade", gloss=0.2)
        yc = rng.uniform(-60.0, 60.0) if xc > 0 else 0.0
        yc = yc + np.sign(yc + 1e-9) * 25.0
        b.add(box_solid(xc, yc, 40.0, 30.0, 0.0, rng.uniform(25.0, 60.0)), m)


def _add_street_furniture(b: _MeshBuilder, rng: np.random.Generator) -> None:
    y_pole = ROAD_HALF_WIDTH_M + 0.5
    y_tree = ROAD_HALF_WIDTH_M + 2.2
    for side in (-1, 1):
        for x in np.arange(-90.0, 300.0, 32.0) + rng.uniform(0, 12):
            b.add(prism(x, side * y_pole, 0.11, KERB_HEIGHT_M, 8.0), M_POLE)
            b.add(box_solid(x, side * (y_pole - 0.9), 0.12, 1.9, 7.75, 7.9), M_POLE)  # arm over the road
            b.add(box_solid(x, side * (y_pole - 1.75), 0.35, 0.7, 7.6, 7.8, with_bottom=True), M_LAMP)
        x = -95.0 + rng.uniform(0, 10)
        while x < 300.0:
            trunk_h = rng.uniform(2.0, 3.0)
            b.add(prism(x, side * y_tree, 0.16, KERB_HEIGHT_M, trunk_h + 1.0, n=6), M_TRUNK)
            r = rng.uniform(1.6, 2.5)
            center = np.array([x, side * y_tree, trunk_h + r * 0.8])
            b.add(icosphere(center, r, rng), M_FOLIAGE)
            x += rng.uniform(11.0, 24.0)


def car_parts(length: float, width: float, height: float,
              paint: SurfaceMaterial) -> list[tuple[Mesh, SurfaceMaterial]]:
    """A boxy car in the object frame (x front, y left, z up, origin bottom centre).

    Returns a list of (part, material) pairs; everything lies inside the box
    [-l/2, l/2] x [-w/2, w/2] x [0, h].
    """
    l, w, h = length, width, height
    body_z0, body_z1 = 0.28, 0.56 * h + 0.1
    body_bottom = rect_xy(0.0, 0.0, l, w, 0.0)
    body_top = rect_xy(0.0, 0.0, l - 0.25, w - 0.06, 0.0)
    parts = [((frustum(body_bottom, body_top, body_z0, body_z1, with_bottom=True)), paint)]
    cab_bottom = rect_xy(-0.06 * l, 0.0, 0.60 * l, w - 0.14, 0.0)
    cab_top = rect_xy(-0.10 * l, 0.0, 0.38 * l, w - 0.34, 0.0)
    parts.append((frustum(cab_bottom, cab_top, body_z1, h - 0.02), M_CAR_GLASS))
    roof = rect_xy(-0.10 * l, 0.0, 0.38 * l - 0.02, w - 0.36, 0.0)
    parts.append((frustum(roof, roof * [0.99, 0.99], h - 0.02, h), paint))
    # head and tail lights: small boxes sunk into the (slanted) front and rear faces of the body
    lz0, lz1 = body_z1 - 0.2, body_z1 - 0.08
    inset = 0.125 * (lz1 - body_z0) / (body_z1 - body_z0)
    for sx, m in ((1, M_HEADLIGHT), (-1, M_TAILLIGHT)):
        for sy in (-1, 1):
            parts.append((box_solid(sx * (l / 2 - inset + 0.02), sy * (w / 2 - 0.25), 0.06, 0.3, lz0, lz1), m))
    r = 0.32
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append((wheel_cylinder(sx * 0.33 * l, sy * (w / 2 - 0.14), r, r, 0.24), M_TYRE))
    return parts


def _add_car(b: _MeshBuilder, objects: list[StreetObject], x: float, y: float, yaw: float,
             rng: np.random.Generator, attribute: str) -> None:
    l = float(rng.uniform(4.1, 4.9))
    w = float(rng.uniform(1.75, 1.95))
    h = float(rng.uniform(1.42, 1.70))
    colour = _CAR_COLOURS[rng.integers(len(_CAR_COLOURS))]
    paint = SurfaceMaterial(f"car_paint_{len(objects)}", colour, LIDARSEG_CAR, "plain", gloss=0.08,
                            lidar_reflectivity=0.5)
    T = make_transform(yaw_to_quat(yaw), [x, y, 0.0])
    for part, m in car_parts(l, w, h, paint):
        b.add(part, m, obj=len(objects), T_street_from_part=T)
    objects.append(StreetObject("vehicle.car", np.array([x, y, h / 2]), np.array([w, l, h]), yaw, attribute))


def _add_cone(b: _MeshBuilder, objects: list[StreetObject], x: float, y: float) -> None:
    h, r = 0.7, 0.2
    b.add(box_solid(x, y, 0.36, 0.36, 0.0, 0.03), M_CONE, obj=len(objects))
    a = 2 * np.pi * np.arange(8) / 8
    base = np.c_[x + r * np.cos(a), y + r * np.sin(a)]
    v = np.concatenate([np.c_[base, np.full(8, 0.03)], [[x, y, h]]])
    f = np.array([[i, (i + 1) % 8, 8] for i in range(8)])
    b.add((v, f), M_CONE, obj=len(objects))
    objects.append(StreetObject("movable_object.trafficcone", np.array([x, y, h / 2]), np.array([0.36, 0.36, h]), 0.0))


def _add_vehicles(b: _MeshBuilder, objects: list[StreetObject], params: StreetParams, rng: np.random.Generator) -> None:
    ego_side = 1 if params.drive_on_left else -1
    y_park = ROAD_HALF_WIDTH_M - 1.2
    free0, free1 = params.free_ahead_m
    for side in (-1, 1):
        yaw = 0.0 if side == ego_side else np.pi  # parked in the direction of traffic
        x = -60.0 + rng.uniform(0, 6)
        while x < 150.0:
            gap = rng.uniform(1.0, 9.0)
            if rng.uniform() < 0.8 and not (side == ego_side and free0 - 3 < x < free1 + 3):
                _add_car(b, objects, x, side * (y_park + rng.uniform(-0.15, 0.1)), yaw + rng.normal(0, 0.01), rng, "vehicle.parked")
            x += 5.2 + gap
    # traffic: one car ahead in the ego's lane beyond the free stretch, one oncoming
    lane_y = ego_side * LANE_WIDTH_M / 2
    _add_car(b, objects, free1 + rng.uniform(12, 25), lane_y, 0.0, rng, "vehicle.moving")
    _add_car(b, objects, rng.uniform(45, 70), -lane_y, np.pi, rng, "vehicle.moving")
    _add_car(b, objects, rng.uniform(-35, -18), -3 * lane_y, np.pi, rng, "vehicle.moving")
    for k in range(3):  # cones in the parking strip, in view of CAM_FRONT, clear of the travel lanes
        _add_cone(b, objects, 14.0 + 2.5 * k, ego_side * (y_park + 0.3))


def build_street(params: StreetParams, T_global_from_street: np.ndarray) -> StreetScene:
    """Generate the street of ``params`` and place it in the global frame.

    The ego stands at the street-frame point (0, lane centre, 0) looking along +x.
    """
    rng = np.random.default_rng(params.seed)
    b = _MeshBuilder()
    objects: list[StreetObject] = []
    _add_ground(b)
    _add_lane_marks(b)
    _add_buildings(b, rng)
    _add_street_furniture(b, rng)
    _add_vehicles(b, objects, params, rng)

    vertices_street = np.concatenate(b.vertices)
    vertices_global = transform_points(T_global_from_street, vertices_street)
    R = T_global_from_street[:3, :3]
    boxes = []
    for o in objects:
        c = transform_points(T_global_from_street, o.center_street[None])[0]
        q = rotation_to_quat(R @ make_transform(yaw_to_quat(o.yaw_street), [0, 0, 0])[:3, :3])
        boxes.append(Box(center=c, wlh=np.asarray(o.wlh, dtype=np.float64), rotation=q, category=o.category,
                         attributes=(o.attribute,) if o.attribute else ()))
    ego_y = (1 if params.drive_on_left else -1) * LANE_WIDTH_M / 2
    T_global_from_ego = T_global_from_street @ make_transform(np.eye(3), [0.0, ego_y, 0.0])
    x0, x1 = ROAD_X_RANGE_M
    hw = ROAD_HALF_WIDTH_M
    road = transform_points(T_global_from_street, np.array([[x0, -hw, 0], [x1, -hw, 0], [x1, hw, 0], [x0, hw, 0]]))
    return StreetScene(
        vertices_global=vertices_global,
        faces=np.concatenate(b.faces),
        face_material=np.concatenate(b.face_material),
        face_object=np.concatenate(b.face_object),
        materials=tuple(b.materials),
        objects=tuple(boxes),
        object_attributes=tuple(o.attribute for o in objects),
        T_global_from_street=T_global_from_street,
        T_global_from_ego=T_global_from_ego,
        drivable_polygons_global=[road[:, :2]],
        lanes_global=_travel_lanes(params, T_global_from_street),
    )


def _travel_lanes(params: StreetParams,
                  T_global_from_street: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The four travel lanes (two each way) as (start_xy, end_xy, width) in the direction of travel.

    Right-hand traffic drives along +x on the y < 0 side; left-hand traffic on the y > 0 side.
    """
    x0, x1 = ROAD_X_RANGE_M
    forward_side = 1 if params.drive_on_left else -1
    lanes = []
    for side in (forward_side, -forward_side):
        for k in (0.5, 1.5):
            y = side * k * LANE_WIDTH_M
            a, b = (x0, x1) if side == forward_side else (x1, x0)
            ends = transform_points(T_global_from_street, np.array([[a, y, 0.0], [b, y, 0.0]]))
            lanes.append((ends[0, :2], ends[1, :2], LANE_WIDTH_M))
    return lanes
