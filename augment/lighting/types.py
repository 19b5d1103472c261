"""The lighting's typed results: levels, the parametric sky fit, one camera's estimate, a sample's shared lighting.

Frames: a :class:`LightingEstimate` is in its camera's frame (OpenCV) on its image's radiometric scale; a
:class:`SampleLighting` holds the volume frame (z up, see :mod:`.volume`) and each camera's exposure ratio.
Every JSON record (``params``) is made of plain Python numbers, lists and dicts (:func:`json_clean`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal, get_args

import numpy as np

from ..core import check_shape, invert_transform
from ...datasets.sample import CameraView
from .light import DistantLight, SunLight

if TYPE_CHECKING:  # only for the annotations here: the volume levels load the volume module
    from .volume import HybridLighting

Level = Literal["L0", "L1", "L2", "L3"]
LevelRequest = Literal["L0", "L1", "L2", "L3", "auto"]
SunSource = Literal["ephemeris", "image", "none"]
LEVEL_REQUESTS: tuple[str, ...] = get_args(LevelRequest)
ENVMAP_HEIGHT, ENVMAP_WIDTH = 128, 256


def check_level(level: str) -> str:
    """``level`` if it is one of :data:`LEVEL_REQUESTS`, else ValueError naming them."""
    if level not in LEVEL_REQUESTS:
        raise ValueError(f"level must be one of {', '.join(LEVEL_REQUESTS)}, got {level!r}")
    return level


def json_clean(obj):
    """JSON-friendly copy (numpy scalars -> Python numbers, arrays -> lists, dicts/lists recursively)."""
    if isinstance(obj, dict):
        return {k: json_clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_clean(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


@dataclass(frozen=True)
class ParametricFit:
    """The parametric sky of one camera (:mod:`.sky` fitted to its image, :mod:`.parametric`).

    Attributes:
        turbidity: Preetham turbidity.
        cloud_cover: 0 (clear) .. 1 (overcast).
        scale: image units per physical unit of the sky model.
        ground_albedo: the road albedo assumed.
        camera_height_m: camera height above the ground used for the ground evidence.
        up_cam: (3,) unit gravity up, camera frame.
        sky_sun_dir_cam: (3,) unit sun direction shaping the sky model (camera frame; the ephemeris sun, also
            below the horizon, or a nominal 45 deg sun for an overcast sky).
        sun_elevation_deg, sun_azimuth_deg: the ephemeris sun, or None without one.
        location: the log's location, or None.
        evidence: the image evidence used (JSON record).
    """

    turbidity: float
    cloud_cover: float
    scale: float
    ground_albedo: float
    camera_height_m: float
    up_cam: np.ndarray
    sky_sun_dir_cam: np.ndarray
    sun_elevation_deg: float | None = None
    sun_azimuth_deg: float | None = None
    location: str | None = None
    evidence: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The fit as the ``params`` record of ``lighting.json``."""
        out = {
            "turbidity": self.turbidity, "cloud_cover": self.cloud_cover, "scale": float(self.scale),
            "ground_albedo_assumed": self.ground_albedo, "camera_height_m": self.camera_height_m,
            "up_camera": np.asarray(self.up_cam).tolist(),
            "sky_sun_direction_camera": np.asarray(self.sky_sun_dir_cam).tolist(),
        }
        if self.sun_elevation_deg is not None:
            out.update(sun_elevation_deg=self.sun_elevation_deg, sun_azimuth_deg=self.sun_azimuth_deg,
                       location=self.location)
        out["evidence"] = self.evidence
        return json_clean(out)


@dataclass(frozen=True)
class LightingEstimate:
    """The lighting of one image, in its camera frame and on its radiometric scale.

    Attributes:
        light_cam: distant light: environment (camera-frame equirect, sun excluded) + sun, camera frame,
            image units. For L2/L3 this is the sky dome alone (what reaches a point with nothing around it).
        sun_dir_cam: (3,) unit vector towards the sun (camera frame), or None (night / unknown).
        sun_source: where the sun came from: the ephemeris, the image (learned model), or none.
        sun_visibility: 0..1 fraction of the sun getting through clouds (0 when there is no sun).
        level: the level of this estimate (for ``auto``: the level chosen).
        reason: why this level, which evidence was used, which fallbacks were taken.
        params: the JSON record written to ``lighting.json`` (fit, evidence numbers, build statistics).
        timing_s: seconds per step.
        hybrid: the sample's sky dome + sun + volume (volume frame, reference scale), L2/L3 only.
        T_vol_from_cam: (4, 4) this camera -> the volume frame (L2/L3 only).
        radiometric_scale: this image's units per unit of ``hybrid`` radiance (its exposure ratio).
        fit: the parametric sky fitted to this image (L1 with ephemeris or at night), else None (L0, the
            learned image model).
    """

    light_cam: DistantLight
    sun_dir_cam: np.ndarray | None
    sun_source: SunSource
    sun_visibility: float
    level: Level
    reason: str
    params: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    hybrid: HybridLighting | None = None
    T_vol_from_cam: np.ndarray | None = None
    radiometric_scale: float = 1.0
    fit: ParametricFit | None = None

    def light_at(self, point_cam: np.ndarray, height: int = ENVMAP_HEIGHT, width: int = ENVMAP_WIDTH) -> DistantLight:
        """The local distant light (camera frame, image scale) at a 3D point (3,) in the camera frame, metres.

        L0/L1: ``light_cam`` at every point. L2/L3: the local environment map of the volume + sky dome seen
        from the point (Eq. 1 over all directions, ``height`` x ``width``) and the sun attenuated by its
        transmittance through the volume from that point. A point inside solid voxels (e.g. on the ground) is
        first moved up to free space.
        """
        p = np.asarray(point_cam, dtype=np.float64)
        check_shape(p, (3,), "point_cam")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"point_cam must be finite, got {p.tolist()}")
        if self.hybrid is None or self.hybrid.params is None:
            return self.light_cam
        T = np.asarray(self.T_vol_from_cam)
        p_vol = self.hybrid.lift_out_of_solid(T[:3, :3] @ p + T[:3, 3])
        from .volume import world_to_frame_envmap  # only a volume level needs it

        env_world = self.hybrid.envmap_at_cached(p_vol, height, width)  # shared by the cameras seeing the point
        env = world_to_frame_envmap(env_world, T[:3, :3], height, width) * np.float32(self.radiometric_scale)
        sun = self.light_cam.sun
        if sun is not None:
            tau = self.hybrid.sun_transmittance(p_vol)
            sun = replace(sun, irradiance_rgb=np.asarray(sun.irradiance_rgb) * tau, visibility=sun.visibility * tau)
        return DistantLight(env.astype(np.float32), sun)


ViewKey = tuple[str, str, str]


def view_key(view: CameraView) -> ViewKey:
    """(channel, sample_data_token, image_path): what identifies an input view of a :class:`SampleLighting`."""
    return (view.channel, view.sample_data_token, view.image_path)


def join_reasons(a: str, b: str) -> str:
    """``a; b`` unless ``b`` is empty or already said in ``a`` (``b`` alone if it already says ``a``)."""
    if not b or b in a:
        return a
    return b if a and a in b else f"{a}; {b}"


@dataclass(frozen=True)
class SampleLighting:
    """The lighting of one sample, shared by its cameras.

    Attributes:
        level: the level (for ``auto``: the level chosen).
        reason: why this level and which evidence/fallbacks were used.
        reference: channel of the reference camera (volume frame and radiometric scale).
        per_view: channel -> the L0/L1 estimate of each input camera (its own frame and scale).
        exposure_ratio: channel -> that camera's image units per reference unit.
        hybrid: sky dome + sun + volume in the volume frame (L2/L3), else None.
        T_global_from_vol: (4, 4) volume frame -> global.
        params: JSON record (cloud cover, grid, build statistics, auto's predicted errors).
        timing_s: seconds per step.
        view_keys: channel -> :func:`view_key` of the input views.
        sun_source: the reference camera's sun source (shared by the sample's volume).
        sun_visibility: the reference camera's sun visibility.
        T_global_from_ref_cam: (4, 4) the reference camera -> global.
        input_mean_ldr: channel -> the mean value in [0, 1] of each input image (what a camera's auto-exposure
            holds steady: :func:`.predicted_view.auto_exposure_target`).
    """

    level: Level
    reason: str
    reference: str
    per_view: dict[str, LightingEstimate]
    exposure_ratio: dict[str, float]
    hybrid: HybridLighting | None
    T_global_from_vol: np.ndarray
    params: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    view_keys: dict[str, ViewKey] = field(default_factory=dict)
    sun_source: SunSource = "none"
    sun_visibility: float = 0.0
    T_global_from_ref_cam: np.ndarray | None = None
    input_mean_ldr: dict[str, float] = field(default_factory=dict)

    def is_input(self, view: CameraView) -> bool:
        """Whether ``view`` is one of the views this lighting was estimated from."""
        key = self.view_keys.get(view.channel)
        return view.channel in self.per_view and key is not None and key == view_key(view)

    def for_view(self, view: CameraView) -> LightingEstimate:
        """A camera-frame estimate for ``view`` sharing this sample's sun, sky and volume.

        An input view at L0/L1 gets its own estimate; any other view gets the shared light (the volume's sky
        and sun at L2/L3, the reference camera's distant light at L0/L1) turned into its frame, at the
        reference camera's exposure.
        """
        same = self.is_input(view)
        if self.level in ("L0", "L1"):
            est = self.per_view[view.channel] if same else self._reference_rotated(view)
            return replace(est, level=self.level, reason=join_reasons(self.reason, est.reason))
        return self._from_hybrid(view, same)

    def _reference_rotated(self, view: CameraView) -> LightingEstimate:
        ref = self.per_view[self.reference]
        R_cam_from_ref = np.asarray(view.T_cam_from_global)[:3, :3] @ np.asarray(self.T_global_from_ref_cam)[:3, :3]
        sun_dir = None if ref.sun_dir_cam is None else R_cam_from_ref @ ref.sun_dir_cam
        note = f"{view.channel} was not an input view: the reference camera's light, reference exposure assumed"
        return replace(ref, light_cam=ref.light_cam.rotated(R_cam_from_ref), sun_dir_cam=sun_dir,
                       reason=join_reasons(ref.reason, note), fit=None)

    def _from_hybrid(self, view: CameraView, same: bool) -> LightingEstimate:
        from .volume import as_numpy, world_to_frame_envmap  # only a volume level needs them

        T_vol_from_cam = invert_transform(self.T_global_from_vol) @ np.asarray(view.T_global_from_cam)
        R_vol_from_cam = T_vol_from_cam[:3, :3]
        ratio = float(self.exposure_ratio.get(view.channel, 1.0)) if same else 1.0
        note = "" if same else f"; {view.channel} was not an input view: reference exposure assumed"
        hybrid = self.hybrid
        env = world_to_frame_envmap(hybrid.sky_world, R_vol_from_cam, ENVMAP_HEIGHT, ENVMAP_WIDTH) * np.float32(ratio)
        sun = sun_dir_cam = None
        if hybrid.sun_dir is not None:
            sun_dir_cam = R_vol_from_cam.T @ hybrid.sun_dir
            sun = SunLight(sun_dir_cam, as_numpy(hybrid.sun_irradiance).astype(np.float64) * ratio,
                           hybrid.sun_half_angle_rad, float(self.sun_visibility))
        params = dict(self.params)
        if same:
            params["l1"] = self.per_view[view.channel].params
        return LightingEstimate(
            light_cam=DistantLight(env, sun), sun_dir_cam=sun_dir_cam,
            sun_source=self.sun_source if sun is not None else "none",
            sun_visibility=float(self.sun_visibility) if sun is not None else 0.0,
            level=self.level, reason=self.reason + note, params=params, timing_s=dict(self.timing_s),
            hybrid=hybrid, T_vol_from_cam=T_vol_from_cam, radiometric_scale=ratio,
            fit=self.per_view[view.channel].fit if same else None,
        )
