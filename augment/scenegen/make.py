"""Entry point of the bundled sample scenes: street -> images + LiDAR + tables + ground-truth lighting.

``make_sample_scenes(out_dir)`` writes a nuScenes-format dataroot (version ``v1.0-samples``) with one
keyframe per scene, plus ``ground_truth/<scene>/lighting.json`` and ``envmap_world.exr`` holding the
exact light the images were rendered with, on the images' radiometric scale.  Same arguments ->
byte-identical files.
"""

from __future__ import annotations

import argparse
import datetime as dt
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from streetaug.augment.core import (
    GAMMA,
    PinholeCamera,
    hdr_to_ldr_uint8,
    luminance,
    make_transform,
    rotate_vectors,
    scale_intrinsics,
    transform_points,
    yaw_to_quat,
)
from streetaug.augment.core import encode_image_rgb, write_bytes_atomic, write_exr
from streetaug.augment.core.raycast import RayScene
from streetaug.augment.lighting.sun import SunPosition, sun_direction_global
from streetaug.datasets.nuscenes_format import LIDARSEG_DRIVEABLE, content_token, visibility_token
from streetaug.datasets.sample import Box

from .lidar import LidarScan, T_ego_from_lidar, points_in_box, simulate_lidar
from .nuscenes_tables import NuScenesTables, dumps
from .render import SkyParams, StreetRenderer
from .street import StreetParams, StreetScene, build_street

VERSION = "v1.0-samples"
JPEG_QUALITY = 90
ENVMAP_SIZE = (64, 128)  # world equirect ground truth (H, W)
KEY_VALUE = 0.18  # auto-exposure: geometric mean luminance of CAM_FRONT -> 0.18 (linear)
ROAD_LDR_RANGE = (0.25, 0.45)  # ... clamped so that the median road pixel lands in this LDR range


@dataclass(frozen=True)
class CameraRig:
    """A nuScenes-like camera: intrinsics at 1600 x 900, mounting on the ego, capture-time offset.

    Attributes:
        K_1600: (3, 3) intrinsics for a 1600 x 900 image (pixel centres at integers).
        translation_ego: (3,) camera position in the ego frame, metres.
        yaw_deg: rotation about ego +z of the optical axis (0 = looking along ego +x, 90 = left).
        time_offset_us: sample_data timestamp minus the keyframe (LiDAR) timestamp.
    """

    K_1600: tuple
    translation_ego: tuple[float, float, float]
    yaw_deg: float
    time_offset_us: int

    def T_ego_from_cam(self) -> np.ndarray:
        """(4, 4) OpenCV camera -> ego: camera z -> ego forward (yawed), x -> right, y -> down."""
        R_front = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        R_yaw = make_transform(yaw_to_quat(np.radians(self.yaw_deg)), [0, 0, 0])[:3, :3]
        return make_transform(R_yaw @ R_front, self.translation_ego)

    def K(self, width: int, height: int) -> np.ndarray:
        """Intrinsics (3, 3) for an image of ``width`` x ``height`` (same field of view as 1600 x 900)."""
        return scale_intrinsics(np.array(self.K_1600, dtype=np.float64), width / 1600.0, height / 900.0)


CAMERA_RIGS: dict[str, CameraRig] = {
    "CAM_FRONT": CameraRig(((1266.417, 0.0, 816.267), (0.0, 1266.417, 491.507), (0.0, 0.0, 1.0)),
                           (1.700791, 0.015946, 1.510958), 0.0, -35491),
    "CAM_FRONT_LEFT": CameraRig(((1272.598, 0.0, 826.615), (0.0, 1272.598, 479.752), (0.0, 0.0, 1.0)),
                                (1.523878, 0.494631, 1.509328), 55.0, -43107),
    "CAM_BACK": CameraRig(((809.221, 0.0, 829.220), (0.0, 809.221, 481.778), (0.0, 0.0, 1.0)),
                          (0.028326, 0.003451, 1.579103), 180.0, -10426),
}


@dataclass(frozen=True)
class SceneSpec:
    """One bundled sample scene.

    Attributes:
        name: scene name (``scene.name``), e.g. ``sample-sunny``.
        description: ``scene.description``.
        location: nuScenes map name (sets the sun through the ephemeris).
        local_time: ISO 8601 local time with UTC offset, e.g. ``2018-09-18T13:10:00-04:00``.
        origin_xy: (x, y) global position (metres) of the street frame's origin.
        heading_deg: direction of travel of the ego, degrees counter-clockwise from east (global +x).
        turbidity, cloud_cover: sky model parameters.
        sun_half_angle_deg: angular radius of the sun disc used for shadows.
        drive_on_left: left-hand traffic (Singapore).
        street_seed: seed offset of the street layout.
        cameras: rendered camera channels (keys of ``CAMERA_RIGS``).
    """

    name: str
    description: str
    location: str
    local_time: str
    origin_xy: tuple[float, float]
    heading_deg: float
    turbidity: float = 3.0
    cloud_cover: float = 0.0
    sun_half_angle_deg: float = 0.2665
    drive_on_left: bool = False
    street_seed: int = 0
    cameras: tuple[str, ...] = ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_BACK")

    @property
    def timestamp_us(self) -> int:
        return int(round(dt.datetime.fromisoformat(self.local_time).timestamp() * 1e6))

    @property
    def logfile(self) -> str:
        t = dt.datetime.fromisoformat(self.local_time)
        off = t.strftime("%z")
        return f"n900-{t.strftime('%Y-%m-%d-%H-%M-%S')}{off}"


SAMPLE_SCENES: dict[str, SceneSpec] = {
    s.name: s
    for s in (
        SceneSpec(
            name="sample-sunny",
            description="Generated street, boston-seaport, clear early-afternoon sun (elevation ~49 deg) ahead-right: hard shadows.",
            location="boston-seaport", local_time="2018-09-18T13:10:00-04:00",
            origin_xy=(1000.0, 1400.0), heading_deg=-52.0, turbidity=2.5, cloud_cover=0.0, street_seed=1,
        ),
        SceneSpec(
            name="sample-overcast",
            description="Generated street, singapore-onenorth (left-hand traffic), overcast mid-morning: soft light, sun hidden.",
            location="singapore-onenorth", local_time="2018-07-24T10:30:00+08:00",
            origin_xy=(600.0, 900.0), heading_deg=30.0, turbidity=4.0, cloud_cover=0.9,
            sun_half_angle_deg=3.0, drive_on_left=True, street_seed=2,
        ),
        SceneSpec(
            name="sample-lowsun",
            description="Generated street, boston-seaport, clear morning ~1 h after sunrise (elevation ~11 deg) behind-right: long shadows.",
            location="boston-seaport", local_time="2018-08-30T07:12:00-04:00",
            origin_xy=(2000.0, 1000.0), heading_deg=173.0, turbidity=3.5, cloud_cover=0.0, street_seed=3,
        ),
    )
}


def choose_exposure(radiance: np.ndarray, label: np.ndarray) -> float:
    """Scale k (image units per physical radiance unit) of a camera's auto-exposure.

    Like an averaging meter: the geometric mean luminance of the whole image maps to ``KEY_VALUE``
    (linear), then k is clamped so that the median road pixel lands in ``ROAD_LDR_RANGE``.
    Inputs: radiance (H, W, 3) float, label (H, W) uint8 lidarseg labels.
    """
    lum = luminance(np.asarray(radiance, dtype=np.float64))
    k = KEY_VALUE / float(np.exp(np.mean(np.log(np.maximum(lum, 1e-9)))))
    road = label == LIDARSEG_DRIVEABLE
    if road.any():
        road_med = float(np.median(lum[road]))
        lo, hi = (v**GAMMA / max(road_med, 1e-12) for v in ROAD_LDR_RANGE)
        k = min(max(k, lo), hi)
    return float(np.float32(k))


def object_visibility(scene: StreetScene, rays: RayScene, cams: list[tuple[PinholeCamera, np.ndarray]]) -> np.ndarray:
    """Approximate visible fraction (n_objects,) of each object: over the cameras (camera, T_global_from_cam),
    the best fraction of its vertices inside the image that no other surface hides."""
    out = np.zeros(len(scene.objects))
    obj_of_vertex = np.full(len(scene.vertices_global), -1)
    obj_faces = scene.face_object >= 0
    obj_of_vertex[scene.faces[obj_faces].reshape(-1)] = np.repeat(scene.face_object[obj_faces], 3)
    vid = np.nonzero(obj_of_vertex >= 0)[0]
    for camera, T_global_from_cam in cams:
        K, W, H = camera.K, camera.width, camera.height
        p_cam = transform_points(np.linalg.inv(T_global_from_cam), scene.vertices_global[vid])
        z = p_cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (p_cam @ K.T)[:, :2] / z[:, None]
        inside = (z > 0.5) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        origin = T_global_from_cam[:3, 3]
        d = scene.vertices_global[vid] - origin
        dist = np.linalg.norm(d, axis=1)
        hits = rays.intersect(np.tile(origin, (len(vid), 1)), d / dist[:, None])
        own = scene.face_object[np.maximum(hits.face, 0)] == obj_of_vertex[vid]
        visible = inside & (~hits.hit | (hits.t >= dist - 0.05) | own)
        for o in range(len(scene.objects)):
            sel = obj_of_vertex[vid] == o
            n_in = inside[sel].sum()
            if n_in:
                out[o] = max(out[o], visible[sel].sum() / sel.sum())
    return out


@dataclass(frozen=True)
class RenderedCamera:
    """One rendered camera of a generated scene.

    Attributes:
        channel: e.g. ``CAM_FRONT``.
        camera: intrinsics and image size.
        T_global_from_cam: (4, 4) camera (OpenCV) -> global.
        file: the written image (relative to the dataroot); ``sample_data_token`` its row.
        meta: the camera's entry of ``lighting.json`` (sample_data token, sun and up directions in the camera).
    """

    channel: str
    camera: PinholeCamera
    T_global_from_cam: np.ndarray
    file: str
    sample_data_token: str
    meta: dict


@dataclass(frozen=True)
class RenderedCameras:
    """The cameras of a scene and the exposure k they share (set by CAM_FRONT, rendered first)."""

    cameras: list[RenderedCamera]
    k_exposure: float


def _register_scene(spec: SceneSpec, scene: StreetScene, tables: NuScenesTables) -> str:
    """Add the log, scene and sample rows and the map (road polygons, lanes); returns the sample token."""
    sample_token = content_token("sample", spec.name)
    log_token = tables.add_log(spec.name, spec.logfile, spec.location, spec.local_time[:10])
    scene_token = tables.add_scene(spec.name, spec.description, log_token, sample_token)
    tables.add_sample(sample_token, scene_token, spec.timestamp_us)
    for poly in scene.drivable_polygons_global:
        tables.add_map_polygon(spec.location, log_token, poly)
    for start_xy, end_xy, width_m in scene.lanes_global:
        tables.add_map_lane(spec.location, start_xy, end_xy, width_m)
    return sample_token


def _render_cameras(spec: SceneSpec, renderer: StreetRenderer, sun_direction_global: np.ndarray, out_dir: Path,
                    tables: NuScenesTables, sample_token: str, width: int, height: int, seed: int, spp: int,
                    sky_rays: int) -> RenderedCameras:
    """Render and write every camera of ``spec`` (CAM_FRONT first: it sets the exposure of all)."""
    T_global_from_ego = renderer.scene.T_global_from_ego
    channels = sorted(spec.cameras, key=lambda c: c != "CAM_FRONT")
    k_exposure = None
    cameras = []
    for ci, channel in enumerate(channels):
        rig = CAMERA_RIGS[channel]
        K = rig.K(width, height)
        T_ego_from_cam = rig.T_ego_from_cam()
        T_global_from_cam = T_global_from_ego @ T_ego_from_cam
        res = renderer.render(K, T_global_from_cam, width, height, spp=spp, sky_rays=sky_rays, seed=seed * 101 + ci)
        if k_exposure is None:
            k_exposure = choose_exposure(res.radiance, res.label)
        image = hdr_to_ldr_uint8(res.radiance * k_exposure)
        cam_ts = spec.timestamp_us + rig.time_offset_us
        filename = f"samples/{channel}/{spec.logfile}__{channel}__{cam_ts}.jpg"
        write_bytes_atomic(out_dir / filename, encode_image_rgb(image, ".jpg", JPEG_QUALITY))
        sd_tok = tables.add_sample_data(spec.name, channel, "camera", sample_token, cam_ts, filename, width, height,
                                        T_ego_from_cam, T_global_from_ego, K)
        T_cam_from_global = np.linalg.inv(T_global_from_cam)
        sun_cam = rotate_vectors(T_cam_from_global, sun_direction_global[None])[0]
        up_cam = rotate_vectors(T_cam_from_global, np.array([[0.0, 0.0, 1.0]]))[0]
        meta = {"sample_data_token": sd_tok, "sun_direction_camera": _unit(sun_cam).tolist(),
                "up_direction_camera": _unit(up_cam).tolist()}
        cameras.append(RenderedCamera(channel, PinholeCamera(K, width, height), T_global_from_cam, filename, sd_tok,
                                      meta))
    return RenderedCameras(cameras, k_exposure)


@dataclass(frozen=True)
class WrittenLidar:
    """The keyframe sweep as written: its files (relative to the dataroot) and its points in the global frame.

    Attributes:
        files: the ``.pcd.bin`` and the lidarseg label file.
        scan: the simulated sweep.
        points_global: (N, 3) float64 the stored float32 points, in the global frame.
    """

    files: list[str]
    scan: LidarScan
    points_global: np.ndarray


def _write_lidar(spec: SceneSpec, renderer: StreetRenderer, out_dir: Path, tables: NuScenesTables,
                 sample_token: str, seed: int) -> WrittenLidar:
    """Simulate, write and register LIDAR_TOP and its lidarseg labels."""
    T_global_from_ego = renderer.scene.T_global_from_ego
    T_global_from_lidar = T_global_from_ego @ T_ego_from_lidar()
    scan = simulate_lidar(renderer.scene, T_global_from_lidar, seed=seed, rays=renderer.rays)
    lidar_file = f"samples/LIDAR_TOP/{spec.logfile}__LIDAR_TOP__{spec.timestamp_us}.pcd.bin"
    write_bytes_atomic(out_dir / lidar_file, scan.to_pcd_bin())
    lidar_sd = tables.add_sample_data(spec.name, "LIDAR_TOP", "lidar", sample_token, spec.timestamp_us, lidar_file,
                                      0, 0, T_ego_from_lidar(), T_global_from_ego, None)
    seg_file = tables.add_lidarseg(lidar_sd)
    write_bytes_atomic(out_dir / seg_file, scan.labels.astype(np.uint8).tobytes())
    # points counted from the written float32 points
    points_sensor = np.frombuffer(scan.to_pcd_bin(), dtype=np.float32).reshape(-1, 5)[:, :3].astype(np.float64)
    return WrittenLidar([lidar_file, seg_file], scan, transform_points(T_global_from_lidar, points_sensor))


def _annotate(spec: SceneSpec, renderer: StreetRenderer, lidar: WrittenLidar, cameras: RenderedCameras,
              tables: NuScenesTables, sample_token: str) -> int:
    """Add a ``sample_annotation`` for every object the LiDAR hits (as nuScenes); returns their number."""
    scene = renderer.scene
    visibility = object_visibility(scene, renderer.rays, [(c.camera, c.T_global_from_cam) for c in cameras.cameras])
    n_ann = 0
    for i, box in enumerate(scene.objects):
        # count with the box exactly as stored (mm / 1e-10 rounding), as the devkit would
        stored = Box(np.round(box.center, 3), np.round(box.wlh, 3), np.round(box.rotation, 10), box.category)
        n_pts = int(points_in_box(stored, lidar.points_global).sum())
        if n_pts == 0 and not np.any(lidar.scan.object_index == i):
            continue  # annotate what the LiDAR sees (range noise can put a far object's few hits just outside)
        attr = scene.object_attributes[i]
        tables.add_annotation(spec.name, i, sample_token, box.category, box.center, box.wlh, box.rotation, attr,
                              n_pts, visibility_token(visibility[i]))
        n_ann += 1
    return n_ann


def _ground_truth(spec: SceneSpec, renderer: StreetRenderer, sun: SunPosition, cameras: RenderedCameras,
                  sample_token: str, n_annotations: int, render: dict) -> dict:
    """The scene's ``lighting.json`` document (every radiance on the images' scale, x k)."""
    sky, k_exposure = renderer.sky, cameras.k_exposure
    cam_meta = {c.channel: c.meta for c in cameras.cameras}
    sun_e = renderer.sun_e
    return {
        "schema": "streetaug.sample_lighting/1",
        "scene": spec.name,
        "location": spec.location,
        "timestamp_us": spec.timestamp_us,
        "local_time": spec.local_time,
        "sample_token": sample_token,
        "exposure_k": k_exposure,
        "radiometric_scale": "image: LDR = camera_response(k x physical radiance); every radiance here is already x k",
        "sun": {
            "direction_global": _unit(sun.direction_global).tolist(),
            "elevation_deg": round(sun.elevation_deg, 6),
            "azimuth_deg": round(sun.azimuth_deg, 6),
            "source": "ephemeris",
            "irradiance_rgb": (sun_e * k_exposure).tolist(),
            "irradiance_rgb_physical_w_m2": sun_e.tolist(),
            "visibility": sky.sun_visibility,
            "half_angle_deg": spec.sun_half_angle_deg,
            "direction_camera": {c: m["sun_direction_camera"] for c, m in cam_meta.items()},
        },
        "sky": {"model": "streetaug.augment.lighting.sky.sky_radiance", "turbidity": spec.turbidity,
                "cloud_cover": spec.cloud_cover, "ground_albedo": sky.ground_albedo},
        "cameras": cam_meta,
        "envmap_world": {"file": "envmap_world.exr", "height": ENVMAP_SIZE[0], "width": ENVMAP_SIZE[1],
                         "convention": "world z-up equirect: lon = atan2(dy, dx) (0 = east), lat = asin(dz); global frame",
                         "includes_sun": False},
        "files": {"envmap_world": "envmap_world.exr"},
        "n_annotations": n_annotations,
        "render": render,
    }


def _make_scene(spec: SceneSpec, out_dir: Path, tables: NuScenesTables, width: int, height: int, seed: int,
                spp: int, sky_rays: int) -> list[Path]:
    """Generate one scene: street -> camera images -> LiDAR -> annotations -> ground-truth lighting."""
    sun = sun_direction_global(spec.location, spec.timestamp_us)
    T_global_from_street = make_transform(yaw_to_quat(np.radians(spec.heading_deg)), [*spec.origin_xy, 0.0])
    scene = build_street(StreetParams(seed=seed * 7919 + spec.street_seed, drive_on_left=spec.drive_on_left),
                         T_global_from_street)
    sky = SkyParams(sun.direction_global, spec.turbidity, spec.cloud_cover, 0.15, float(np.radians(spec.sun_half_angle_deg)))
    renderer = StreetRenderer(scene, sky)
    sample_token = _register_scene(spec, scene, tables)
    cameras = _render_cameras(spec, renderer, sun.direction_global, out_dir, tables, sample_token, width, height,
                              seed, spp, sky_rays)
    lidar = _write_lidar(spec, renderer, out_dir, tables, sample_token, seed)
    n_ann = _annotate(spec, renderer, lidar, cameras, tables, sample_token)
    gt_dir = out_dir / "ground_truth" / spec.name
    write_exr(gt_dir / "envmap_world.exr", sky.envmap_world(*ENVMAP_SIZE) * np.float32(cameras.k_exposure))
    render = {"width": width, "height": height, "spp": spp, "sky_rays": sky_rays, "seed": seed}
    lighting = _ground_truth(spec, renderer, sun, cameras, sample_token, n_ann, render)
    write_bytes_atomic(gt_dir / "lighting.json", dumps(_round_floats(lighting)))
    return ([out_dir / c.file for c in cameras.cameras] + [out_dir / f for f in lidar.files]
            + [gt_dir / "envmap_world.exr", gt_dir / "lighting.json"])


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _round_floats(obj, nd: int = 9):
    if isinstance(obj, float):
        return float(np.format_float_positional(obj, precision=nd, unique=True, trim="-")) if np.isfinite(obj) else obj
    if isinstance(obj, (np.floating,)):
        return _round_floats(float(obj), nd)
    if isinstance(obj, dict):
        return {k: _round_floats(v, nd) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_round_floats(v, nd) for v in obj]
    return obj


def make_sample_scenes(out_dir: Path, names: list[str] | None = None, width: int = 1600, height: int = 900,
                       seed: int = 0, spp: int = 4, sky_rays: int = 2) -> list[Path]:
    """Generate the bundled sample scenes as a nuScenes dataroot (version ``v1.0-samples``) in ``out_dir``.

    Args:
        out_dir: dataroot to write (created; existing files of the same names are replaced).
        names: keys of ``SAMPLE_SCENES`` (default: all, in sorted order).
        width, height: image size (the nuScenes field of view is kept for any size).
        seed: seed of the street layouts and of the render sampling.
        spp, sky_rays: primary samples per pixel and sky rays per primary sample.

    Returns:
        The written files (sorted).
    """
    names = sorted(SAMPLE_SCENES) if names is None else list(names)
    unknown = [n for n in names if n not in SAMPLE_SCENES]
    if unknown:
        raise ValueError(f"unknown sample scene(s) {unknown}; known: {sorted(SAMPLE_SCENES)}")
    if width < 16 or height < 9:
        raise ValueError(f"image size must be at least 16 x 9, got {width} x {height}")
    out_dir = Path(out_dir)
    tables = NuScenesTables(VERSION)
    written: list[Path] = []
    for name in names:
        written += _make_scene(SAMPLE_SCENES[name], out_dir, tables, width, height, seed, spp, sky_rays)
    written += tables.write(out_dir)
    readme = out_dir / "README.md"
    write_bytes_atomic(readme, _readme(names, width, height, seed).encode())
    written.append(readme)
    return sorted(written)


def _readme(names: list[str], width: int, height: int, seed: int) -> str:
    """Deterministic description of a generated dataroot."""
    lines = [
        "# streetaug sample scenes (generated)",
        "",
        "Procedural streets rendered by streetaug's own ray tracer (`streetaug.augment.scenegen`), written as a",
        f"nuScenes dataset: `NuScenes(version='{VERSION}', dataroot=<this folder>)`; one keyframe per scene with",
        "CAM_FRONT / CAM_FRONT_LEFT / CAM_BACK (nuScenes-like calibration), LIDAR_TOP (32 beams; as in nuScenes",
        "every beam is stored, firing after firing, a beam without a return as a point at the sensor) with",
        "lidarseg labels, 3D boxes (`sample_annotation`) and a map expansion whose `drivable_area` is the road",
        "surface and whose `lane` records (with `arcline_path_3` centre lines) are the four travel lanes.",
        "`ground_truth/<scene>/lighting.json` + `envmap_world.exr` hold the exact light of each scene on the",
        "images' radiometric scale (sun direction/irradiance/visibility, sky parameters, exposure k).",
        "",
        f"Regenerate (byte-identical on the same machine): `python -m streetaug.augment.scenegen.make <dir> --size {width}x{height} --seed {seed}`",
        "",
        "| scene | location | local time | sun elevation / azimuth (deg) | sky |",
        "|---|---|---|---|---|",
    ]
    for name in names:
        spec = SAMPLE_SCENES[name]
        sun = sun_direction_global(spec.location, spec.timestamp_us)
        lines.append(
            f"| {name} | {spec.location} | {spec.local_time} | {sun.elevation_deg:.1f} / {sun.azimuth_deg:.1f} | "
            f"turbidity {spec.turbidity}, cloud cover {spec.cloud_cover} |"
        )
    lines += ["", "Generated data; no third-party content. Same license as the streetaug repository.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """``python -m streetaug.augment.scenegen.make OUT_DIR [--size WxH] [--seed N] [--names a,b]``."""
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--size", default="1600x900")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--names", default=None)
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    t0 = time.perf_counter()
    paths = make_sample_scenes(args.out_dir, args.names.split(",") if args.names else None, w, h, args.seed)
    size = sum(p.stat().st_size for p in paths)
    print(f"wrote {len(paths)} files, {size / 1e6:.2f} MB, in {time.perf_counter() - t0:.1f} s -> {args.out_dir}")


if __name__ == "__main__":
    main()
