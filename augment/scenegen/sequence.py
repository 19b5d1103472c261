"""A generated scene through time: the ego drives along a generated street, vehicles park or drive.

``make_sequence_scene(out_dir)`` writes a nuScenes dataroot (version ``v1.0-sequence``) with ONE scene of
``n_keyframes`` samples 0.5 s apart, every sample_data row of its cameras and LIDAR_TOP (keyframes and
sweeps), keyframe images, keyframe LiDAR + lidarseg, annotation tracks, the map expansion and the
ground-truth lighting. With ``sweeps=True`` it also renders the sweep files (``sweeps/<CHANNEL>/``);
without, the tables are the same (they list the sweeps, as nuScenes' metadata does when only the keyframe
blobs were downloaded) and the sweep files are absent. Same arguments -> byte-identical files.

Timing (as nuScenes): sample k is at ``t_k = t_0 + k x 0.5 s``, the LIDAR_TOP keyframe's timestamp; a
camera's keyframe is at ``t_k`` + the camera's capture offset (``CameraRig.time_offset_us``). Between
keyframes the cameras capture at 12 Hz (5 sweeps per interval) and the LiDAR at 20 Hz (9 sweeps).
Convention: a sweep's ``sample_token`` is the sample at the END of its interval (the first keyframe after
it): the devkit's ``NuScenes.get_boxes`` interpolates a sweep's boxes between ``sample.prev`` and
``sample``, clamping the sweep's time into that interval. The scene starts and ends with keyframes.

Motion (street frame, see :mod:`.street`): the ego drives along +x at ``ego_speed_mps`` in its lane (the
left lane: Singapore); the street's ``vehicle.moving`` cars drive straight along their heading (each in the
left lane of its direction) at ``moving_speeds_mps``; parked cars and cones stay. Every frame is rendered
with the ego pose and the vehicles at that frame's timestamp; annotations hold the boxes at the sample's
(LiDAR) timestamp, so ``NuScenes.box_velocity`` returns the true velocity.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from streetaug.augment.core import (
    PinholeCamera,
    encode_image_rgb,
    hdr_to_ldr_uint8,
    make_transform,
    rotate_vectors,
    transform_points,
    write_bytes_atomic,
    write_exr,
    yaw_to_quat,
)
from streetaug.augment.lighting.sun import sun_direction_global
from streetaug.datasets.nuscenes_format import content_token, visibility_token
from streetaug.datasets.sample import Box

from .lidar import T_ego_from_lidar, points_in_box, simulate_lidar
from .make import (CAMERA_RIGS, ENVMAP_SIZE, JPEG_QUALITY, RenderedCamera, RenderedCameras, SceneSpec, _ground_truth,
                   _round_floats, _unit, choose_exposure, object_visibility)
from .nuscenes_tables import dumps
from .render import SkyParams, StreetRenderer
from .sequence_tables import SequenceTables
from .street import StreetParams, StreetScene, build_street

SEQUENCE_VERSION = "v1.0-sequence"
KEYFRAME_PERIOD_US = 500_000  # 2 Hz samples
CAMERA_FRAMES_PER_KEYFRAME = 6  # 12 Hz cameras: a keyframe + 5 sweeps per interval
LIDAR_FRAMES_PER_KEYFRAME = 10  # 20 Hz LiDAR: a keyframe + 9 sweeps per interval
LIDAR_CHANNEL = "LIDAR_TOP"


@dataclass(frozen=True)
class SequenceSpec:
    """A generated sequence scene.

    Attributes:
        scene: street, place, time (of the first sample) and sky; ``scene.cameras`` are the rendered cameras.
        n_keyframes: number of samples (0.5 s apart).
        ego_speed_mps: the ego's speed along its lane, m/s.
        moving_speeds_mps: speed of each ``vehicle.moving`` car of the street, in the order the street
            generator makes them (ahead in the ego's lane, oncoming, oncoming behind), m/s along its heading.
    """

    scene: SceneSpec
    n_keyframes: int = 5
    ego_speed_mps: float = 8.0
    moving_speeds_mps: tuple[float, ...] = (7.0, 9.0, 6.0)

    @property
    def name(self) -> str:
        return self.scene.name


SEQUENCE_SCENE = SequenceSpec(SceneSpec(
    name="sequence-onenorth",
    description=("Generated street, singapore-onenorth (left-hand traffic), clear late afternoon (sun elevation "
                 "~38 deg, ahead-left): the ego drives 8 m/s for 2 s past parked cars; three cars drive."),
    location="singapore-onenorth", local_time="2018-08-01T16:30:00+08:00", origin_xy=(800.0, 1200.0),
    heading_deg=120.0, turbidity=2.8, cloud_cover=0.1, drive_on_left=True, street_seed=4,
))


@dataclass(frozen=True)
class Frame:
    """One capture of one channel.

    Attributes:
        channel: e.g. ``CAM_FRONT`` or ``LIDAR_TOP``.
        index: position among the channel's frames (0 = the first keyframe).
        timestamp_us: capture time, microseconds.
        sample_index: the sample the frame belongs to (a keyframe's own; a sweep's next keyframe).
        is_key_frame: a keyframe (``samples/``) or a sweep (``sweeps/``).
    """

    channel: str
    index: int
    timestamp_us: int
    sample_index: int
    is_key_frame: bool

    @property
    def modality(self) -> str:
        return "lidar" if self.channel == LIDAR_CHANNEL else "camera"

    def filename(self, logfile: str) -> str:
        folder = "samples" if self.is_key_frame else "sweeps"
        ext = "pcd.bin" if self.modality == "lidar" else "jpg"
        return f"{folder}/{self.channel}/{logfile}__{self.channel}__{self.timestamp_us}.{ext}"


def sequence_frames(spec: SequenceSpec, channels: tuple[str, ...]) -> list[Frame]:
    """Every frame of ``channels`` (cameras of ``CAMERA_RIGS`` and/or ``LIDAR_TOP``), ordered by (time, channel)."""
    t0 = spec.scene.timestamp_us
    frames = []
    for channel in channels:
        if channel == LIDAR_CHANNEL:
            per, offset = LIDAR_FRAMES_PER_KEYFRAME, 0
        else:
            per, offset = CAMERA_FRAMES_PER_KEYFRAME, CAMERA_RIGS[channel].time_offset_us
        for j in range((spec.n_keyframes - 1) * per + 1):
            t = t0 + offset + int(round(j * KEYFRAME_PERIOD_US / per))
            frames.append(Frame(channel, j, t, -(-j // per), j % per == 0))
    return sorted(frames, key=lambda f: (f.timestamp_us, f.channel))


@dataclass
class SequenceWorld:
    """The street of a :class:`SequenceSpec` at any time: ego pose, object boxes, scene mesh.

    Attributes:
        spec: the sequence.
        base: the street at ``t0_us`` (the first sample).
        t0_us: timestamp of the first sample, microseconds.
        velocities_global: (n_objects, 3) float64 velocity of every object, global frame, m/s (0: static).
        ego_velocity_global: (3,) float64 the ego's velocity, global frame, m/s.
    """

    spec: SequenceSpec
    base: StreetScene
    t0_us: int
    velocities_global: np.ndarray
    ego_velocity_global: np.ndarray
    _object_vertices: list[np.ndarray] = field(default_factory=list, repr=False)

    @classmethod
    def build(cls, spec: SequenceSpec, seed: int = 0) -> "SequenceWorld":
        """Generate the street (seeded like the sample scenes) and the velocity of every object."""
        s = spec.scene
        T_global_from_street = make_transform(yaw_to_quat(np.radians(s.heading_deg)), [*s.origin_xy, 0.0])
        base = build_street(StreetParams(seed=seed * 7919 + s.street_seed, drive_on_left=s.drive_on_left),
                            T_global_from_street)
        moving = [i for i, a in enumerate(base.object_attributes) if a == "vehicle.moving"]
        if len(moving) != len(spec.moving_speeds_mps):
            raise ValueError(f"sequence {spec.name}: the street has {len(moving)} moving vehicles but "
                             f"moving_speeds_mps has {len(spec.moving_speeds_mps)} speeds")
        velocities = np.zeros((len(base.objects), 3))
        for i, speed in zip(moving, spec.moving_speeds_mps):
            heading_global = rotate_vectors(base.objects[i].T_global_from_box, np.array([[1.0, 0.0, 0.0]]))[0]
            velocities[i] = speed * heading_global
        ego_velocity = spec.ego_speed_mps * T_global_from_street[:3, 0]
        obj_faces = base.face_object >= 0
        vertex_object = np.full(len(base.vertices_global), -1)
        vertex_object[base.faces[obj_faces].reshape(-1)] = np.repeat(base.face_object[obj_faces], 3)
        object_vertices = [np.flatnonzero(vertex_object == i) for i in range(len(base.objects))]
        return cls(spec, base, s.timestamp_us, velocities, ego_velocity, object_vertices)

    def dt_s(self, timestamp_us: int) -> float:
        """Seconds from the first sample to ``timestamp_us``."""
        return (int(timestamp_us) - self.t0_us) * 1e-6

    def T_global_from_ego(self, timestamp_us: int) -> np.ndarray:
        """(4, 4) ego pose at ``timestamp_us``."""
        T = self.base.T_global_from_ego.copy()
        T[:3, 3] += self.ego_velocity_global * self.dt_s(timestamp_us)
        return T

    def boxes_at(self, timestamp_us: int) -> tuple[Box, ...]:
        """Every object's box (global frame) at ``timestamp_us``."""
        dt_s = self.dt_s(timestamp_us)
        return tuple(b if not v.any() else replace(b, center=b.center + v * dt_s)
                     for b, v in zip(self.base.objects, self.velocities_global))

    def scene_at(self, timestamp_us: int) -> StreetScene:
        """The street mesh with every moving object where it is at ``timestamp_us``."""
        dt_s = self.dt_s(timestamp_us)
        vertices = self.base.vertices_global.copy()
        for i, v in enumerate(self.velocities_global):
            if v.any():
                vertices[self._object_vertices[i]] += v * dt_s
        return replace(self.base, vertices_global=vertices, objects=self.boxes_at(timestamp_us),
                       T_global_from_ego=self.T_global_from_ego(timestamp_us))


@dataclass(frozen=True)
class RenderOptions:
    """Image size and sampling of every rendered camera frame (keyframes and sweeps alike)."""

    width: int = 800
    height: int = 450
    spp: int = 4
    sky_rays: int = 2
    seed: int = 0


class _SequenceWriter:
    """Writes one sequence scene; one method per stage (tables, cameras, LiDAR, annotations, ground truth)."""

    def __init__(self, spec: SequenceSpec, out_dir: Path, options: RenderOptions, sweeps: bool,
                 render_images: bool = True) -> None:
        self.spec, self.out_dir, self.opt, self.sweeps = spec, out_dir, options, sweeps
        self.render_images = render_images
        s = spec.scene
        self.world = SequenceWorld.build(spec, options.seed)
        self.sun = sun_direction_global(s.location, s.timestamp_us)
        sky = SkyParams(self.sun.direction_global, s.turbidity, s.cloud_cover, 0.15,
                        float(np.radians(s.sun_half_angle_deg)))
        self.base_renderer = StreetRenderer(self.world.base, sky)
        self._renderers: dict[int, StreetRenderer] = {}
        self.tables = SequenceTables(SEQUENCE_VERSION)
        cams = [c for c in ("CAM_FRONT",) if c in s.cameras] + [c for c in s.cameras if c != "CAM_FRONT"]
        self.cameras = tuple(cams)  # the first one sets the exposure of all
        self.frames = sequence_frames(spec, self.cameras + (LIDAR_CHANNEL,))
        self.sample_tokens = [content_token("sample", spec.name, k) for k in range(spec.n_keyframes)]
        self.sd_token: dict[tuple[str, int], str] = {}
        self.k_exposure: float | None = None
        self.written: list[Path] = []

    # ------------------------------------------------------------------ helpers

    def renderer_at(self, timestamp_us: int) -> StreetRenderer:
        """The renderer of the street at ``timestamp_us`` (cached: the frames of one time share it)."""
        if timestamp_us not in self._renderers:
            if len(self._renderers) > 8:
                self._renderers.clear()
            scene = self.world.scene_at(timestamp_us)
            self._renderers[timestamp_us] = self.base_renderer.with_scene(scene)
        return self._renderers[timestamp_us]

    def T_global_from_cam(self, channel: str, timestamp_us: int) -> np.ndarray:
        return self.world.T_global_from_ego(timestamp_us) @ CAMERA_RIGS[channel].T_ego_from_cam()

    def _write(self, rel: str, data: bytes) -> None:
        write_bytes_atomic(self.out_dir / rel, data)
        self.written.append(self.out_dir / rel)

    # ------------------------------------------------------------------ stages

    def register_tables(self) -> None:
        """log, scene, samples, calibrated sensors, every frame (sample_data + ego_pose) and the map."""
        s, t = self.spec.scene, self.tables
        log_token = t.add_log(s.name, s.logfile, s.location, s.local_time[:10])
        scene_token = t.add_sequence_scene(s.name, s.description, log_token, self.sample_tokens)
        n = len(self.sample_tokens)
        for k, tok in enumerate(self.sample_tokens):
            t.add_linked_sample(tok, scene_token, s.timestamp_us + k * KEYFRAME_PERIOD_US,
                                self.sample_tokens[k - 1] if k else "", self.sample_tokens[k + 1] if k + 1 < n else "")
        w, h = self.opt.width, self.opt.height
        cs_token = {c: t.add_calibrated_sensor(s.name, c, "camera", CAMERA_RIGS[c].T_ego_from_cam(),
                                               CAMERA_RIGS[c].K(w, h))
                    for c in self.cameras}
        cs_token[LIDAR_CHANNEL] = t.add_calibrated_sensor(s.name, LIDAR_CHANNEL, "lidar", T_ego_from_lidar(), None)
        for f in self.frames:
            size = (0, 0) if f.modality == "lidar" else (w, h)
            self.sd_token[f.channel, f.index] = t.add_frame(
                s.name, f.channel, f.modality, cs_token[f.channel], self.sample_tokens[f.sample_index], f.timestamp_us,
                f.filename(s.logfile), *size, self.world.T_global_from_ego(f.timestamp_us), f.is_key_frame)
        t.link_frames()
        base = self.world.base
        for poly in base.drivable_polygons_global:
            t.add_map_polygon(s.location, log_token, poly)
        for start_xy, end_xy, width_m in base.lanes_global:
            t.add_map_lane(s.location, start_xy, end_xy, width_m)

    def render_camera(self, f: Frame) -> RenderedCamera:
        """Render and write one camera frame (the first camera's first keyframe sets the exposure)."""
        o = self.opt
        rig = CAMERA_RIGS[f.channel]
        K = rig.K(o.width, o.height)
        T_global_from_cam = self.T_global_from_cam(f.channel, f.timestamp_us)
        filename = f.filename(self.spec.scene.logfile)
        if self.render_images:
            ci = self.cameras.index(f.channel)
            render_seed = (o.seed * 100_003 + f.index) * 101 + ci
            res = self.renderer_at(f.timestamp_us).render(K, T_global_from_cam, o.width, o.height, spp=o.spp,
                                                          sky_rays=o.sky_rays, seed=render_seed)
            if self.k_exposure is None:
                self.k_exposure = choose_exposure(res.radiance, res.label)
            image = hdr_to_ldr_uint8(res.radiance * self.k_exposure)
            self._write(filename, encode_image_rgb(image, ".jpg", JPEG_QUALITY))
        T_cam_from_global = np.linalg.inv(T_global_from_cam)
        sd_tok = self.sd_token[f.channel, f.index]
        sun_cam = rotate_vectors(T_cam_from_global, self.sun.direction_global[None])[0]
        up_cam = rotate_vectors(T_cam_from_global, np.array([[0.0, 0.0, 1.0]]))[0]
        meta = {"sample_data_token": sd_tok, "sun_direction_camera": _unit(sun_cam).tolist(),
                "up_direction_camera": _unit(up_cam).tolist()}
        return RenderedCamera(f.channel, PinholeCamera(K, o.width, o.height), T_global_from_cam, filename, sd_tok, meta)

    def write_lidar(self, f: Frame) -> tuple[np.ndarray, np.ndarray]:
        """Simulate and write one LiDAR frame (keyframes also get lidarseg).

        Returns:
            points_global: (N, 3) float64 the stored float32 points, global frame.
            object_index: (N,) int64 the object each beam hit (-1: none).
        """
        T_global_from_lidar = self.world.T_global_from_ego(f.timestamp_us) @ T_ego_from_lidar()
        renderer = self.renderer_at(f.timestamp_us)
        scan = simulate_lidar(renderer.scene, T_global_from_lidar, seed=self.opt.seed * 100_003 + f.index,
                              rays=renderer.rays)
        data = scan.to_pcd_bin()
        self._write(f.filename(self.spec.scene.logfile), data)
        if f.is_key_frame:
            seg_file = self.tables.add_lidarseg(self.sd_token[f.channel, f.index])
            self._write(seg_file, scan.labels.astype(np.uint8).tobytes())
        points_sensor = np.frombuffer(data, dtype=np.float32).reshape(-1, 5)[:, :3].astype(np.float64)
        return transform_points(T_global_from_lidar, points_sensor), scan.object_index

    def annotate(self, keyframe_lidar: dict[int, tuple[np.ndarray, np.ndarray]],
                 keyframe_cameras: dict[int, list[RenderedCamera]]) -> int:
        """Annotate every object the LiDAR hits in some keyframe, in every sample from its first to its last
        hit (a contiguous track, as nuScenes tracks); returns the number of annotations."""
        world, spec = self.world, self.spec
        n_obj = len(world.base.objects)
        n_pts = np.zeros((spec.n_keyframes, n_obj), dtype=np.int64)
        hit = np.zeros((spec.n_keyframes, n_obj), dtype=bool)
        visibility = np.zeros((spec.n_keyframes, n_obj))
        stored: dict[int, list[Box]] = {}
        for k in range(spec.n_keyframes):
            t_k = world.t0_us + k * KEYFRAME_PERIOD_US
            points_global, object_index = keyframe_lidar[k]
            # count with the boxes exactly as stored (mm / 1e-10 rounding), as the devkit would
            stored[k] = [Box(np.round(b.center, 3), np.round(b.wlh, 3), np.round(b.rotation, 10), b.category)
                         for b in world.boxes_at(t_k)]
            for i, box in enumerate(stored[k]):
                n_pts[k, i] = int(points_in_box(box, points_global).sum())
                hit[k, i] = n_pts[k, i] > 0 or bool(np.any(object_index == i))
            renderer = self.renderer_at(t_k)
            visibility[k] = object_visibility(renderer.scene, renderer.rays,
                                              [(c.camera, c.T_global_from_cam) for c in keyframe_cameras[k]])
        n_ann = 0
        for i in range(n_obj):
            ks = np.flatnonzero(hit[:, i])
            if len(ks) == 0:
                continue
            attr = world.base.object_attributes[i]
            for k in range(ks[0], ks[-1] + 1):
                b = world.boxes_at(world.t0_us + k * KEYFRAME_PERIOD_US)[i]
                self.tables.add_track_annotation(spec.name, i, k, self.sample_tokens[k], b.category, b.center, b.wlh,
                                                 b.rotation, attr, n_pts[k, i], visibility_token(visibility[k, i]))
                n_ann += 1
        self.tables.link_annotations()
        return n_ann

    def ground_truth(self, first_cameras: list[RenderedCamera], n_annotations: int) -> None:
        """``ground_truth/<scene>/lighting.json`` (first sample's cameras) + ``envmap_world.exr``."""
        s, o = self.spec.scene, self.opt
        gt_dir = self.out_dir / "ground_truth" / s.name
        renderer = self.base_renderer
        write_exr(gt_dir / "envmap_world.exr", renderer.sky.envmap_world(*ENVMAP_SIZE) * np.float32(self.k_exposure))
        render = {"width": o.width, "height": o.height, "spp": o.spp, "sky_rays": o.sky_rays, "seed": o.seed}
        doc = _ground_truth(s, renderer, self.sun, RenderedCameras(first_cameras, self.k_exposure),
                            self.sample_tokens[0], n_annotations, render)
        doc["sequence"] = {
            "n_keyframes": self.spec.n_keyframes, "keyframe_period_us": KEYFRAME_PERIOD_US,
            "camera_hz": 1e6 / KEYFRAME_PERIOD_US * CAMERA_FRAMES_PER_KEYFRAME,
            "lidar_hz": 1e6 / KEYFRAME_PERIOD_US * LIDAR_FRAMES_PER_KEYFRAME,
            "ego_velocity_global_mps": self.world.ego_velocity_global.tolist(),
            "note": "exposure_k is fixed for the whole sequence; 'cameras' are the first sample's keyframes "
                    "(the ego drives straight, so the sun's direction in each camera is the same in every frame)",
            "moving_objects": [
                {"instance_token": content_token("instance", s.name, i), "velocity_global_mps": v.tolist()}
                for i, v in enumerate(self.world.velocities_global) if v.any()
            ],
        }
        write_bytes_atomic(gt_dir / "lighting.json", dumps(_round_floats(doc)))
        self.written += [gt_dir / "envmap_world.exr", gt_dir / "lighting.json"]

    def run(self) -> list[Path]:
        self.register_tables()
        keyframe_cameras: dict[int, list[RenderedCamera]] = {k: [] for k in range(self.spec.n_keyframes)}
        keyframe_lidar: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        # keyframes first, the exposure-setting camera's first keyframe before everything
        order = sorted(self.frames, key=lambda f: (not f.is_key_frame, f.sample_index, self.channel_rank(f.channel)))
        for f in order:
            if not (f.is_key_frame or self.sweeps):
                continue
            if f.modality == "lidar":
                lidar = self.write_lidar(f)
                if f.is_key_frame:
                    keyframe_lidar[f.sample_index] = lidar
            else:
                cam = self.render_camera(f)
                if f.is_key_frame:
                    keyframe_cameras[f.sample_index].append(cam)
        n_ann = self.annotate(keyframe_lidar, keyframe_cameras)
        if self.render_images:  # the ground truth holds the images' exposure
            self.ground_truth(keyframe_cameras[0], n_ann)
        self.written += self.tables.write(self.out_dir)
        readme = self.out_dir / "README.md"
        write_bytes_atomic(readme, _readme(self.spec, self.opt, self.cameras).encode())
        self.written.append(readme)
        return sorted(self.written)

    def channel_rank(self, channel: str) -> int:
        return self.cameras.index(channel) if channel in self.cameras else len(self.cameras)


def make_sequence_scene(out_dir: str | Path, spec: SequenceSpec = SEQUENCE_SCENE, *, sweeps: bool = False,
                        width: int = 800, height: int = 450, seed: int = 0, spp: int = 4, sky_rays: int = 2,
                        n_keyframes: int | None = None, cameras: tuple[str, ...] | None = None,
                        render_images: bool = True) -> list[Path]:
    """Generate a sequence scene as a nuScenes dataroot (version ``v1.0-sequence``) in ``out_dir``.

    Args:
        out_dir: dataroot to write (created; existing files of the same names are replaced).
        spec: the sequence (default :data:`SEQUENCE_SCENE`).
        sweeps: also render the sweep files (camera 12 Hz, LiDAR 20 Hz); the tables list the sweeps either way.
        width, height: image size of every camera frame (the nuScenes field of view is kept for any size).
        seed: seed of the street layout and of the render sampling.
        spp, sky_rays: primary samples per pixel and sky rays per primary sample.
        n_keyframes: override ``spec.n_keyframes`` (e.g. fewer for quick tests).
        cameras: override ``spec.scene.cameras`` (keys of ``CAMERA_RIGS``).
        render_images: False skips the camera images and the ground-truth lighting (which holds their
            exposure): the tables, LiDAR, lidarseg, map and README only, the same bytes (a quick check that a
            written dataroot matches this generator).

    Returns:
        The written files (sorted).
    """
    if n_keyframes is not None:
        spec = replace(spec, n_keyframes=int(n_keyframes))
    if cameras is not None:
        spec = replace(spec, scene=replace(spec.scene, cameras=tuple(cameras)))
    unknown = [c for c in spec.scene.cameras if c not in CAMERA_RIGS]
    if unknown or not spec.scene.cameras:
        raise ValueError(f"cameras must be a non-empty subset of {sorted(CAMERA_RIGS)}, got {list(spec.scene.cameras)}")
    if spec.n_keyframes < 2:
        raise ValueError(f"a sequence needs at least 2 keyframes, got n_keyframes={spec.n_keyframes}")
    if width < 16 or height < 9:
        raise ValueError(f"image size must be at least 16 x 9, got {width} x {height}")
    options = RenderOptions(width, height, spp, sky_rays, seed)
    return _SequenceWriter(spec, Path(out_dir), options, sweeps, render_images).run()


def _readme(spec: SequenceSpec, opt: RenderOptions, cameras: tuple[str, ...]) -> str:
    """Deterministic description of a generated sequence dataroot (the same with or without sweep files)."""
    s = spec.scene
    sun = sun_direction_global(s.location, s.timestamp_us)
    n_cam_sweeps = (spec.n_keyframes - 1) * (CAMERA_FRAMES_PER_KEYFRAME - 1)
    n_lidar_sweeps = (spec.n_keyframes - 1) * (LIDAR_FRAMES_PER_KEYFRAME - 1)
    duration = dt.timedelta(microseconds=(spec.n_keyframes - 1) * KEYFRAME_PERIOD_US)
    t_end = dt.datetime.fromisoformat(s.local_time) + duration
    traffic = "left-hand traffic" if s.drive_on_left else "right-hand traffic"
    n_renders = n_cam_sweeps * len(cameras)
    default = (opt == RenderOptions() and spec.n_keyframes == SEQUENCE_SCENE.n_keyframes
               and cameras == tuple(SEQUENCE_SCENE.scene.cameras))
    args = "" if default else " (non-default arguments: see ground_truth/*/lighting.json 'render')"
    lines = [
        "# streetaug sequence scene (generated)",
        "",
        "A procedural street rendered through time by streetaug's own ray tracer",
        "(`streetaug.augment.scenegen.sequence`), written as a nuScenes dataset:",
        f"`NuScenes(version='{SEQUENCE_VERSION}', dataroot=<this folder>)`.",
        "",
        f"- scene `{s.name}`, {s.location} ({traffic}), {s.local_time} .. {t_end.time().isoformat()}; "
        f"sun elevation {sun.elevation_deg:.1f} deg, azimuth {sun.azimuth_deg:.1f} deg; turbidity {s.turbidity}, "
        f"cloud cover {s.cloud_cover}",
        f"- {spec.n_keyframes} samples (keyframes) 0.5 s apart; the ego drives {spec.ego_speed_mps:g} m/s along "
        "its lane",
        f"- cameras {', '.join(cameras)} at {opt.width} x {opt.height} (nuScenes-like calibration and capture "
        "offsets), LIDAR_TOP (32 beams, every beam stored) with lidarseg labels on keyframes",
        f"- sweeps: {n_cam_sweeps} per camera (12 Hz) and {n_lidar_sweeps} LiDAR sweeps (20 Hz) are listed in "
        "`sample_data` (`is_key_frame` false, files under `sweeps/<CHANNEL>/`, `prev`/`next` chained through keyframes "
        "and sweeps per channel; a sweep's `sample_token` is the next keyframe's sample, as the devkit's `get_boxes` "
        f"expects). Their files are written only with `--sweeps` ({n_renders} camera renders and {n_lidar_sweeps} "
        "LiDAR simulations: minutes; ~0.64 MB per LiDAR sweep)",
        f"- annotation tracks: parked cars (`vehicle.parked`), cones, and {len(spec.moving_speeds_mps)} cars driving "
        f"({', '.join(f'{v:g}' for v in spec.moving_speeds_mps)} m/s, `vehicle.moving`, each in its direction's "
        f"{'left' if s.drive_on_left else 'right'} lane); boxes at the sample (LiDAR) time, so the devkit's "
        "`box_velocity` is the true velocity",
        "- map expansion: `drivable_area` (the road) and the four travel `lane`s with `arcline_path_3` centre lines",
        "- `ground_truth/<scene>/lighting.json` + `envmap_world.exr`: the exact light (first sample's cameras; "
        "one exposure for the whole sequence) and the true velocities",
        "",
        f"Regenerate (byte-identical on the same machine){args}: `streetaug make-samples --sequence --out <dir>`;",
        "add `--sweeps` to render the sweep files too (the other files do not change).",
        "",
        "Generated data; no third-party content. Same license as the streetaug repository.",
        "",
    ]
    return "\n".join(lines)
