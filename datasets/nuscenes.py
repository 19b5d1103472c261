"""A nuScenes v1.0 reader that needs no devkit: tables, cameras, LiDAR, lidarseg, boxes, drivable area.

Layout read (as in nuScenes)::

    <dataroot>/<version>/{scene,sample,sample_data,...}.json   tables (lists of rows keyed by token)
    <dataroot>/samples/<CHANNEL>/...                          images (.jpg) and LiDAR (.pcd.bin)
    <dataroot>/lidarseg/<version>/<sd_token>_lidarseg.bin     optional lidarseg labels
    <dataroot>/maps/expansion/<location>.json                 optional map expansion (drivable_area, lanes)
    <dataroot>/maps/<hash>.png                                semantic-prior raster (map.json), used without expansion

Frames: ``calibrated_sensor`` gives sensor -> ego (``T_ego_from_cam``; nuScenes camera frames are
OpenCV frames), ``ego_pose`` gives ego -> global at the sample_data's own timestamp.  Quaternions are
``[w, x, y, z]``.  Tables load on first use, once; images and LiDAR load only when accessed.  The large
tables (:data:`INDEXED_TABLES`, hundreds of MB in trainval) are not parsed whole to find one sample's rows: a
byte-offset index of the file (:mod:`.table_index`, cached on disk) finds them and only those rows are parsed.

Usage::

    reader = NuScenesReader("/data/nuscenes", "v1.0-mini")
    token = reader.sample_tokens("scene-0061")[0]
    sample = reader.sample(token)
    cam = sample.cameras["CAM_FRONT"]          # cam.image decodes on first access
    points_cam = sample.lidar.points_in(cam.T_cam_from_global)
"""

from __future__ import annotations

import copy
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from streetaug.augment.core import ConventionError, InputError, make_transform, read_image_rgb
from streetaug.augment.core.paths import resolve_inside

from .errors import DatasetError
from .lidarseg import read_lidar_points, read_lidarseg_labels
from .nuscenes_map import (DrivableArea, LaneCenterlines, map_expansion_path, read_area_layer, read_lanes,
                           read_map_expansion)
from .raster_map import MAP_SOURCE_EXPANSION, MAP_SOURCE_RASTER, RasterDrivable, read_semantic_prior, semantic_prior_row
from .sample import Box, CameraView, LidarSweep, Sample
from .tables import integer_field, read_table_rows, rotation_field, row_where, size_field, token_index, vector_field

if TYPE_CHECKING:
    from .table_index import TableIndex

__all__ = ["DatasetError", "NuScenesReader", "read_lidar_points", "read_lidarseg_labels"]

REQUIRED_TABLES = (
    "scene",
    "sample",
    "sample_data",
    "calibrated_sensor",
    "ego_pose",
    "log",
    "map",
    "sample_annotation",
    "instance",
    "category",
    "sensor",
)
OPTIONAL_TABLES = ("attribute", "visibility", "lidarseg")
LIDAR_CHANNEL = "LIDAR_TOP"
INDEXED_TABLES: dict[str, tuple[str, ...]] = {  # table -> the fields its rows are looked up by (token first)
    "sample_data": ("token", "sample_token"),
    "sample_annotation": ("token", "sample_token"),
    "ego_pose": ("token",),
    "instance": ("token",),
}
INDEX_MIN_BYTES = 8 << 20  # an indexed table file this large or larger is read through its index
_MAX_LISTED = 10


def _listing(values: list[str]) -> str:
    shown = ", ".join(values[:_MAX_LISTED])
    return shown + (f", ... ({len(values)} in total)" if len(values) > _MAX_LISTED else "")


class NuScenesReader:
    """Read one nuScenes-format dataset version (e.g. ``v1.0-mini``) from ``dataroot``.

    Args:
        dataroot: folder holding ``<version>/`` (the tables), ``samples/`` and optionally ``maps/``
            and ``lidarseg/``.
        version: table folder name, e.g. ``v1.0-mini`` or ``v1.0-trainval``.
        with_map: attach the location's drivable area to each ``Sample`` (parsed once per location: the map
            expansion, else the semantic-prior raster of ``map.json``; see :meth:`map_source`).
        index_min_bytes: a file of :data:`INDEXED_TABLES` at least this large (bytes) is read through a
            byte-offset index (only the rows asked for are parsed); None: every table is parsed whole.

    Raises:
        DatasetError: ``dataroot`` or ``dataroot/version`` is missing, or a required table file is
            absent.  (Table contents are parsed lazily, on first use.)
    """

    def __init__(self, dataroot: str | Path, version: str, *, with_map: bool = True,
                 index_min_bytes: int | None = INDEX_MIN_BYTES) -> None:
        self.dataroot = Path(dataroot)
        self.version = str(version)
        self.with_map = with_map
        self.index_min_bytes = index_min_bytes
        if not self.dataroot.is_dir():
            raise DatasetError(f"{self.dataroot}: dataset root folder not found (check --dataroot)")
        self.table_dir = self.dataroot / self.version
        if not self.table_dir.is_dir():
            found = sorted(p.name for p in self.dataroot.iterdir() if p.is_dir() and p.name.startswith("v"))
            hint = f"versions found: {', '.join(found)}" if found else "no version folders found"
            raise DatasetError(
                f"{self.table_dir}: table folder for version '{self.version}' not found ({hint}; "
                "check --version)"
            )
        missing = [t for t in REQUIRED_TABLES if not (self.table_dir / f"{t}.json").is_file()]
        if missing:
            raise DatasetError(
                f"{self.table_dir / (missing[0] + '.json')}: required nuScenes table missing "
                f"(missing: {', '.join(missing)}); the dataset is incomplete, re-extract the metadata archive"
            )
        self._rows: dict[str, list[dict]] = {}
        self._index: dict[str, dict[str, int]] = {}  # table -> token -> position in self._rows[table]
        self._row_numbers: dict[str, dict[str, int]] = {}  # tables given to with_tables: token -> row in the file
        self._indexes: dict[str, TableIndex | None] = {}  # indexed table -> its TableIndex, or None: parsed whole
        self._sample_data_by_sample: dict[str, list[dict]] | None = None
        self._annotations_by_sample: dict[str, list[dict]] | None = None
        self._lidarseg_by_sd: dict[str, dict] | None = None
        self._drivable: dict[str, DrivableArea | None] = {}
        self._lanes: dict[str, LaneCenterlines | None] = {}
        self._map_errors: dict[str, InputError] = {}
        self._pedestrian_areas: dict[str, dict[str, list]] = {}  # location -> walkway / ped_crossing polygons
        self._map_source: dict[str, str | None] = {}  # location -> "expansion" / "semantic-prior raster" / None
        self._rasters: dict[str, RasterDrivable] = {}  # raster file -> its vectorised drivable area

    def __repr__(self) -> str:
        return f"NuScenesReader({str(self.dataroot)!r}, {self.version!r})"

    def with_tables(self, tables: dict[str, list[dict]],
                    row_numbers: dict[str, dict[str, int]] | None = None) -> "NuScenesReader":
        """A reader of the same files whose tables ``tables`` (name -> rows) replace the table files.

        Lets a batch worker build one ``Sample`` from that sample's rows without parsing the whole
        (multi-GB for trainval) tables; tables not given still load from their files. The parsed map
        (drivable area) is shared with this reader. ``row_numbers`` (table -> token -> row in the table
        file, see :meth:`row_numbers_of`) lets messages name the rows of the files; without it they name
        the token only.
        """
        other = copy.copy(self)
        other._rows = dict(tables)
        other._indexes = {name: index for name, index in self._indexes.items() if name not in tables}
        other._index, other._sample_data_by_sample, other._annotations_by_sample = {}, None, None
        other._lidarseg_by_sd = None
        other._row_numbers = {name: (row_numbers or {}).get(name, {}) for name in tables}
        return other

    def row_numbers_of(self, tables: dict[str, list[dict]]) -> dict[str, dict[str, int]]:
        """Table -> token -> row in this reader's table files, for the rows of ``tables`` (a slice of them)."""
        return {name: {r["token"]: self.row_number(name, r["token"]) for r in rows} for name, rows in tables.items()}

    def row_number(self, table: str, token: str) -> int | None:
        """The row index of ``token`` in the file ``<version>/<table>.json``, or None when not known."""
        if table in self._row_numbers:
            return self._row_numbers[table].get(token)
        index = self._table_index(table)
        if index is not None:
            return index.find(token)
        return self._token_index(table).get(token)

    def where(self, table: str, row: dict, field: str | None) -> str:
        """``"v1.0-mini/sample_data.json row 4 (token ab12) field 'filename'"``: where a value was read."""
        token = row.get("token")
        number = self.row_number(table, token) if isinstance(token, str) else None
        return row_where(f"{self.version}/{table}.json", number, token, field)

    def path_field(self, table: str, row: dict, field: str = "filename") -> Path:
        """The file a row's ``field`` names, resolved inside the dataroot (symlinks included).

        Raises:
            InputError: the path is absolute or leads outside the dataroot (names the table, row and field).
        """
        return resolve_inside(self.dataroot, self._field(row, table, field), self.where(table, row, field))

    # ------------------------------------------------------------------ tables

    def table(self, name: str) -> list[dict]:
        """Raw rows of table ``name`` (parsed once, the whole file; do not mutate).  Absent optional tables -> [].

        Parses even an indexed table whole: ask :meth:`get`, :meth:`sample_data_rows` ... for the rows needed.
        """
        if name not in self._rows:
            path = self.table_dir / f"{name}.json"
            if not path.is_file():
                if name in OPTIONAL_TABLES:
                    self._rows[name] = []
                    return self._rows[name]
                raise DatasetError(f"{path}: nuScenes table '{name}' not found")
            rows = read_table_rows(path)
            self._index[name] = token_index(rows, str(path))  # duplicated tokens refused on reading
            self._rows[name] = rows
        return self._rows[name]

    def check_table(self, name: str) -> int:
        """The number of rows of table ``name``, raising its table-wide faults (not a list of rows with a
        ``token`` each, a token in two rows). An indexed table is scanned, not parsed: a row that is not
        valid JSON is found when that row is read."""
        index = self._table_index(name)
        return len(index) if index is not None else len(self.table(name))

    def _table_index(self, table: str) -> TableIndex | None:
        """The byte-offset index (:class:`.table_index.TableIndex`) table ``table`` is read through, or None
        (parsed whole: not an indexed table, a small file, already parsed, or a layout the scan does not read)."""
        if table in self._rows or table not in INDEXED_TABLES or self.index_min_bytes is None:
            return None
        if table not in self._indexes:
            path = self.table_dir / f"{table}.json"
            index = None
            if path.is_file() and path.stat().st_size >= self.index_min_bytes:
                from .table_index import open_index  # deferred: only large tables need it

                index = open_index(path, INDEXED_TABLES[table])
            self._indexes[table] = index
        return self._indexes[table]

    def _token_index(self, table: str) -> dict[str, int]:
        if table not in self._index:
            self._index[table] = token_index(self.table(table), str(self.table_dir / f"{table}.json"))
        return self._index[table]

    def _find(self, table: str, token: Any) -> dict | None:
        """The row of ``table`` with ``token``, or None."""
        index = self._table_index(table)
        if index is not None:
            number = index.find(token)
            return None if number is None else index.row(number)
        position = self._token_index(table).get(token)
        return None if position is None else self._rows[table][position]

    def get(self, table: str, token: str) -> dict:
        """The row of ``table`` with ``token``; DatasetError naming the table and token otherwise."""
        lazy = self._table_index(table)
        if lazy is not None:
            number = lazy.find(token)
            if number is None:
                raise DatasetError(
                    f"{self.table_dir / (table + '.json')}: no {table} with token '{token}' ({len(lazy)} rows)"
                )
            return lazy.row(number)
        index = self._token_index(table)
        position = index.get(token)
        if position is None:
            raise DatasetError(
                f"{self.table_dir / (table + '.json')}: no {table} with token '{token}' "
                f"({len(index)} rows)"
            )
        return self._rows[table][position]

    def _field(self, row: dict, table: str, key: str) -> Any:
        if key not in row:
            raise DatasetError(
                f"{self.table_dir / (table + '.json')}: row '{row.get('token')}' has no field '{key}'"
            )
        return row[key]

    # ------------------------------------------------------------------ scenes and samples

    def scene_names(self) -> list[str]:
        """Names of all scenes in table order, e.g. ``['scene-0061', ...]``."""
        return [self._field(s, "scene", "name") for s in self.table("scene")]

    def find_scene(self, name_or_token: str) -> dict:
        """The scene row whose ``name`` or ``token`` equals ``name_or_token``."""
        for s in self.table("scene"):
            if s.get("name") == name_or_token or s["token"] == name_or_token:
                return s
        raise DatasetError(
            f"{self.table_dir / 'scene.json'}: no scene named or with token '{name_or_token}' "
            f"(known scenes: {_listing(self.scene_names())})"
        )

    def sample_tokens(self, scene: str | None = None) -> list[str]:
        """Sample tokens in time order, following ``first_sample_token`` / ``next``.

        Args:
            scene: scene name or token; None = all scenes, in scene-table order.
        """
        scenes = self.table("scene") if scene is None else [self.find_scene(scene)]
        tokens: list[str] = []
        for s in scenes:
            token = self._field(s, "scene", "first_sample_token")
            seen: set[str] = set()
            while token:
                if token in seen:
                    raise DatasetError(
                        f"{self.table_dir / 'sample.json'}: 'next' links of scene '{s.get('name')}' form a "
                        f"cycle at sample '{token}'"
                    )
                seen.add(token)
                tokens.append(token)
                token = self.get("sample", token).get("next", "")
        return tokens

    def _sample_row(self, sample_token: str) -> dict:
        rows = self.table("sample")  # parse errors surface as such, not as an unknown token
        try:
            return self.get("sample", sample_token)
        except DatasetError:
            n = len(rows)
            first = ", ".join(r["token"] for r in rows[:3])
            raise DatasetError(
                f"{self.table_dir / 'sample.json'}: unknown sample token '{sample_token}' "
                f"({n} samples, e.g. {first}); list them with sample_tokens()"
            ) from None

    def scene_of(self, sample_token: str) -> dict:
        """The scene row of a sample."""
        return self.get("scene", self._field(self._sample_row(sample_token), "sample", "scene_token"))

    def location_of(self, sample_token: str) -> str:
        """``log.location`` of the sample's scene, e.g. ``singapore-onenorth`` (names its global frame)."""
        log = self.get("log", self._field(self.scene_of(sample_token), "scene", "log_token"))
        return self._field(log, "log", "location")

    # ------------------------------------------------------------------ per-sample indices

    def sample_data_rows(self, sample_token: str) -> list[dict]:
        """All ``sample_data`` rows of a sample (keyframes and sweeps), in table order."""
        lazy = self._table_index("sample_data")
        if lazy is not None:
            return lazy.rows_where("sample_token", sample_token)
        if self._sample_data_by_sample is None:
            index: dict[str, list[dict]] = defaultdict(list)
            for r in self.table("sample_data"):
                index[r.get("sample_token", "")].append(r)
            self._sample_data_by_sample = dict(index)
        return self._sample_data_by_sample.get(sample_token, [])

    def annotation_rows(self, sample_token: str) -> list[dict]:
        """All ``sample_annotation`` rows of a sample, in table order."""
        lazy = self._table_index("sample_annotation")
        if lazy is not None:
            return lazy.rows_where("sample_token", sample_token)
        if self._annotations_by_sample is None:
            index: dict[str, list[dict]] = defaultdict(list)
            for r in self.table("sample_annotation"):
                index[r.get("sample_token", "")].append(r)
            self._annotations_by_sample = dict(index)
        return self._annotations_by_sample.get(sample_token, [])

    def sensor_of(self, sample_data: dict) -> dict:
        """The ``sensor`` row (``channel``, ``modality``) of a ``sample_data`` row."""
        calib = self.get("calibrated_sensor", self._field(sample_data, "sample_data", "calibrated_sensor_token"))
        return self.get("sensor", self._field(calib, "calibrated_sensor", "sensor_token"))

    def keyframe_sample_data(self, sample_token: str, modality: str) -> dict[str, dict]:
        """Channel -> keyframe ``sample_data`` row of the given modality (``camera``/``lidar``/``radar``)."""
        out: dict[str, dict] = {}
        for sd in self.sample_data_rows(sample_token):
            if not sd.get("is_key_frame", False):
                continue
            sensor = self.sensor_of(sd)
            if sensor.get("modality") == modality:
                out[sensor["channel"]] = sd
        return out

    def lidar_sample_data(self, sample_token: str) -> dict | None:
        """The keyframe LiDAR ``sample_data`` row a ``Sample`` uses (LIDAR_TOP, else any LiDAR), or None."""
        lidars = self.keyframe_sample_data(sample_token, "lidar")
        return lidars.get(LIDAR_CHANNEL) or (next(iter(lidars.values())) if lidars else None)

    # ------------------------------------------------------------------ poses

    def _transform(self, row: dict, table: str) -> np.ndarray:
        """4x4 transform from a row's ``rotation`` ([w, x, y, z]) and ``translation``."""
        try:
            return make_transform(self._field(row, table, "rotation"), self._field(row, table, "translation"))
        except (ConventionError, ValueError, TypeError) as e:
            if isinstance(e, DatasetError):
                raise
            raise DatasetError(
                f"{self.table_dir / (table + '.json')}: row '{row.get('token')}' has an invalid pose "
                f"(rotation [w, x, y, z] and translation [x, y, z] expected): {e}"
            ) from None

    def T_ego_from_sensor(self, sample_data: dict) -> np.ndarray:
        """(4, 4) sensor -> ego transform of a ``sample_data`` row (from its calibrated_sensor)."""
        calib = self.get("calibrated_sensor", self._field(sample_data, "sample_data", "calibrated_sensor_token"))
        return self._transform(calib, "calibrated_sensor")

    def T_global_from_ego(self, sample_data: dict) -> np.ndarray:
        """(4, 4) ego -> global transform at the ``sample_data``'s own timestamp."""
        pose = self.get("ego_pose", self._field(sample_data, "sample_data", "ego_pose_token"))
        return self._transform(pose, "ego_pose")

    def ego_poses_around(self, sample_data: dict) -> tuple[tuple[float, np.ndarray], tuple[float, np.ndarray]] | None:
        """The ego poses just before and after a ``sample_data`` row: ``((dt_s, T_global_from_ego), (dt_s, T))``.

        From the row's ``prev`` / ``next`` sample_data (sweeps) when the table holds them, else from the
        same channel's keyframe in the sample's ``prev`` / ``next`` sample; a missing side is the row
        itself (dt 0).  None when neither side exists (a single frame): no motion is known.
        """
        sample_token = sample_data.get("sample_token") or ""
        sensor = self.sensor_of(sample_data)

        def neighbour(direction: str) -> dict | None:
            token = sample_data.get(direction) or ""
            row = self._find("sample_data", token)
            if row is not None:
                return row
            sample = self._find("sample", sample_token)
            if sample is None:
                return None
            other = sample.get(direction) or ""
            if self._find("sample", other) is None:
                return None
            return self.keyframe_sample_data(other, sensor.get("modality", "camera")).get(sensor.get("channel"))

        before, after = neighbour("prev"), neighbour("next")
        if before is None and after is None:
            return None
        t0 = self._timestamp(sample_data, "sample_data")
        sides = []
        for row in (before, after):
            row = sample_data if row is None else row
            sides.append(((self._timestamp(row, "sample_data") - t0) * 1e-6, self.T_global_from_ego(row)))
        if sides[1][0] - sides[0][0] <= 0:
            return None
        return sides[0], sides[1]

    # ------------------------------------------------------------------ sensors

    def camera_view(self, sample_data_token: str) -> CameraView:
        """A ``CameraView`` for a camera ``sample_data`` row; the image is not decoded here."""
        sd = self.get("sample_data", sample_data_token)
        calib = self.get("calibrated_sensor", self._field(sd, "sample_data", "calibrated_sensor_token"))
        sensor = self.get("sensor", self._field(calib, "calibrated_sensor", "sensor_token"))
        K = np.asarray(self._field(calib, "calibrated_sensor", "camera_intrinsic"), dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise DatasetError(
                f"{self.table_dir / 'calibrated_sensor.json'}: row '{calib['token']}' "
                f"({sensor.get('channel')}): camera_intrinsic must be a finite 3x3 matrix, got shape {K.shape}"
            )
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0.0, 0.0, 1.0]):
            raise DatasetError(
                f"{self.table_dir / 'calibrated_sensor.json'}: row '{calib['token']}' "
                f"({sensor.get('channel')}): camera_intrinsic must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] "
                f"with fx, fy > 0, got {K.tolist()}"
            )
        return CameraView(
            channel=sensor["channel"],
            sample_data_token=sd["token"],
            image_path=str(self.dataroot / self._field(sd, "sample_data", "filename")),
            K=K,
            width=integer_field(sd.get("width", 0), self.where("sample_data", sd, "width")),
            height=integer_field(sd.get("height", 0), self.where("sample_data", sd, "height")),
            T_ego_from_cam=self._transform(calib, "calibrated_sensor"),
            T_global_from_ego=self.T_global_from_ego(sd),
            timestamp_us=self._timestamp(sd, "sample_data"),
            _load_image=lambda: self.camera_image(sd),
            ego_poses_around=self.ego_poses_around(sd),
        )

    def camera_image(self, sample_data: dict) -> np.ndarray:
        """(H, W, 3) uint8 RGB of a camera ``sample_data`` row (what ``CameraView.image`` decodes).

        Raises:
            InputError: the file lies outside the dataroot, cannot be decoded, or its size differs from the
                row's ``width`` / ``height`` (each names the file or the table, row and field).
        """
        path = self.path_field("sample_data", sample_data)
        image = read_image_rgb(path)
        want = (sample_data.get("width", 0), sample_data.get("height", 0))
        got = (image.shape[1], image.shape[0])
        if all(want) and tuple(int(v) for v in want) != got:
            where = self.where("sample_data", sample_data, None)
            raise DatasetError(f"{path}: the image is {got[0]} x {got[1]} but {where} says {want[0]} x {want[1]}; "
                               "the table and the file do not belong together")
        return image

    def _timestamp(self, row: dict, table: str) -> int:
        return integer_field(self._field(row, table, "timestamp"), self.where(table, row, "timestamp"))

    def lidarseg_path(self, sample_data_token: str) -> Path | None:
        """Path of the lidarseg labels of a LiDAR ``sample_data``, or None when the dataset has none.

        Uses ``lidarseg.json``'s ``filename`` when the table lists the token, else
        ``lidarseg/<version>/<token>_lidarseg.bin`` if that file exists.
        """
        if self._lidarseg_by_sd is None:
            self._lidarseg_by_sd = {r.get("sample_data_token", ""): r for r in self.table("lidarseg")}
        row = self._lidarseg_by_sd.get(sample_data_token)
        if row is not None:
            return self.path_field("lidarseg", row)
        fallback = resolve_inside(self.dataroot, f"lidarseg/{self.version}/{sample_data_token}_lidarseg.bin",
                                  f"the lidarseg file of sample_data token {sample_data_token!r}")
        return fallback if fallback.is_file() else None

    def lidar_sweep(self, sample_data_token: str) -> LidarSweep:
        """Read the LiDAR sweep (and its lidarseg labels when present) of a LiDAR ``sample_data``."""
        sd = self.get("sample_data", sample_data_token)
        points = read_lidar_points(self.path_field("sample_data", sd))
        seg_path = self.lidarseg_path(sd["token"])
        labels = None if seg_path is None else read_lidarseg_labels(seg_path, num_points=len(points))
        return LidarSweep(
            points_sensor=points[:, :3].astype(np.float64),
            intensity=points[:, 3].copy(),
            T_ego_from_lidar=self.T_ego_from_sensor(sd),
            T_global_from_ego=self.T_global_from_ego(sd),
            timestamp_us=self._timestamp(sd, "sample_data"),
            labels=labels,
        )

    # ------------------------------------------------------------------ boxes

    def box(self, annotation: dict) -> Box:
        """A ``Box`` (global frame) from a ``sample_annotation`` row."""
        table = "sample_annotation"
        instance_token = self._field(annotation, table, "instance_token")
        instance = self.get("instance", instance_token)
        category = self.get("category", self._field(instance, "instance", "category_token"))
        attributes = tuple(self.get("attribute", t)["name"] for t in annotation.get("attribute_tokens", []))
        center = vector_field(self._field(annotation, table, "translation"), 3,
                              self.where(table, annotation, "translation"), "the box centre [x, y, z] in metres")
        wlh = size_field(self._field(annotation, table, "size"), self.where(table, annotation, "size"))
        rotation = rotation_field(self._field(annotation, table, "rotation"), self.where(table, annotation, "rotation"))
        return Box(center, wlh, rotation, category["name"], annotation["token"], attributes, instance_token)

    # ------------------------------------------------------------------ map

    def _read_map(self, location: str, log_token: str | None = None) -> None:
        """Read ``location``'s drivable area once: the map expansion if present, else the log's raster.

        Sources, best first: ``maps/expansion/<location>.json`` (drivable area and lanes; ``map_source``
        ``"expansion"``), else the ``semantic_prior`` PNG the ``map`` table names for the log (``log_token``,
        or the logs of ``location`` in ``log.json``), vectorised (:mod:`.raster_map`; no lanes; ``map_source``
        ``"semantic-prior raster"``). Neither (no expansion and a map row with an empty ``filename``): None.

        A corrupt or inconsistent map (unreadable expansion, a raster that is missing, not a PNG or not
        8-bit greyscale, a map row of another category, no map row for the log) is an error (remembered:
        every sample of the location fails with it), never a silent fall back to another source.
        """
        if location in self._map_errors:
            raise self._map_errors[location]
        try:
            relative = map_expansion_path(".", location)
            path = resolve_inside(self.dataroot, str(relative), f"the map expansion of location {location!r} (log.json field 'location')")
            if path.is_file():
                data = read_map_expansion(path)
                drivable, lanes = DrivableArea.from_file(path, data), read_lanes(path, data=data)
                pedestrian_areas = {layer: read_area_layer(path, layer, data, required=False)
                                    for layer in ("walkway", "ped_crossing")}
                source = MAP_SOURCE_EXPANSION
            else:
                drivable, lanes, pedestrian_areas = self._read_raster(location, log_token), None, {}
                source = None if drivable is None else MAP_SOURCE_RASTER
        except InputError as e:
            self._map_errors[location] = e
            raise
        self._drivable[location], self._lanes[location] = drivable, lanes
        self._pedestrian_areas[location] = pedestrian_areas
        self._map_source[location] = source

    def _map_row(self, location: str, log_token: str | None) -> dict:
        """The ``map`` row of ``log_token`` (None: of the logs of ``location``), checked (see raster_map)."""
        table_path = f"{self.version}/map.json"
        if log_token is not None:
            return semantic_prior_row(self.table("map"), log_token, table_path)
        logs = [r["token"] for r in self.table("log") if r.get("location") == location and "token" in r]
        if not logs:
            raise DatasetError(f"{self.table_dir / 'log.json'}: no log at location {location!r}; cannot find "
                               "its semantic-prior raster in map.json")
        rows = {id(row): row for row in (semantic_prior_row(self.table("map"), t, table_path) for t in logs)}
        files = sorted({str(r["filename"]) for r in rows.values()})
        if len(files) > 1:
            raise DatasetError(f"{table_path}: the logs of location {location!r} name different rasters "
                               f"{files}; one semantic-prior raster per location expected")
        return next(iter(rows.values()))

    def _read_raster(self, location: str, log_token: str | None) -> DrivableArea | None:
        """The vectorised semantic-prior raster of the log (cached per file), or None if its row names no file."""
        row = self._map_row(location, log_token)
        if row["filename"] == "":
            return None
        path = self.path_field("map", row)
        if not path.is_file():
            raise DatasetError(f"{path}: semantic-prior raster not found ({self.where('map', row, 'filename')}); "
                               f"install maps/expansion/{location}.json or restore the PNG from the nuScenes "
                               "metadata archive")
        key = str(path)
        if key not in self._rasters:
            self._rasters[key] = read_semantic_prior(path)
        return self._rasters[key].area

    def _ensure_map(self, location: str, log_token: str | None) -> None:
        if location not in self._drivable:
            self._read_map(location, log_token)

    def map_source(self, location: str, log_token: str | None = None) -> str | None:
        """Which map gave ``location``'s drivable area: ``"expansion"``, ``"semantic-prior raster"`` or None.

        ``log_token`` picks the raster's map row (default: the logs of ``location`` in ``log.json``).
        """
        self._ensure_map(location, log_token)
        return self._map_source[location]

    @property
    def map_sources(self) -> dict[str, str | None]:
        """Location -> map source of every location read so far (see :meth:`map_source`)."""
        return dict(self._map_source)

    def raster_map(self, location: str, log_token: str | None = None) -> RasterDrivable | None:
        """The vectorised raster (with its size, timings) behind ``location``'s drivable area, if that is the source."""
        if self.map_source(location, log_token) != MAP_SOURCE_RASTER:
            return None
        path = self.path_field("map", self._map_row(location, log_token))
        return self._rasters.get(str(path))

    def drivable_area(self, location: str, log_token: str | None = None) -> DrivableArea | None:
        """The drivable area (with spatial index) of ``location``, or None without any map (see :meth:`_read_map`)."""
        self._ensure_map(location, log_token)
        return self._drivable[location]

    def lanes(self, location: str, log_token: str | None = None) -> LaneCenterlines | None:
        """Lane centre lines of ``location``, or None without a map expansion or without lanes."""
        self._ensure_map(location, log_token)
        return self._lanes[location]

    def drivable_area_global(self, location: str, log_token: str | None = None) -> list | None:
        """Drivable-area (Multi)Polygons of ``location`` in global x/y (metres); None without a map."""
        area = self.drivable_area(location, log_token)
        return None if area is None else area.geometries

    def map_areas(self, location: str, layer: str, log_token: str | None = None) -> list:
        """The map expansion's ``walkway`` or ``ped_crossing`` (Multi)Polygons of ``location`` (global x/y);
        empty without an expansion or without that layer."""
        if layer not in ("walkway", "ped_crossing"):
            raise ValueError(f"map_areas: layer must be 'walkway' or 'ped_crossing', got {layer!r}")
        self._ensure_map(location, log_token)
        return self._pedestrian_areas[location].get(layer, [])

    def drivable_area_near(self, location: str, xy_global: np.ndarray, radius_m: float,
                           log_token: str | None = None):
        """Drivable area clipped to the square of half-side ``radius_m`` around global ``xy_global`` (2,).

        Returns a shapely geometry in global x/y (possibly empty), or None without a map.
        """
        area = self.drivable_area(location, log_token)
        return None if area is None else area.near(xy_global, radius_m)

    # ------------------------------------------------------------------ the Sample

    def sample(self, token: str) -> Sample:
        """Build the ``Sample`` of a keyframe: cameras (lazy images), boxes, lazy LiDAR, drivable area."""
        row = self._sample_row(token)
        scene = self.scene_of(token)
        location = self.location_of(token)
        log_token = self._field(scene, "scene", "log_token")
        cameras = {
            channel: self.camera_view(sd["token"])
            for channel, sd in sorted(self.keyframe_sample_data(token, "camera").items())
        }
        boxes = tuple(self.box(a) for a in self.annotation_rows(token))
        lidar_sd = self.lidar_sample_data(token)
        load_lidar = None if lidar_sd is None else (lambda t=lidar_sd["token"]: self.lidar_sweep(t))
        return Sample(
            token=row["token"],
            scene_name=self._field(scene, "scene", "name"),
            location=location,
            timestamp_us=self._timestamp(row, "sample"),
            cameras=cameras,
            boxes=boxes,
            drivable_area_global=self.drivable_area_global(location, log_token) if self.with_map else None,
            _load_lidar=load_lidar,
            lanes=self.lanes(location, log_token) if self.with_map else None,
            map_source=self.map_source(location, log_token) if self.with_map else None,
            walkways_global=tuple(self.map_areas(location, "walkway", log_token)) if self.with_map else (),
            ped_crossings_global=tuple(self.map_areas(location, "ped_crossing", log_token)) if self.with_map else (),
        )
