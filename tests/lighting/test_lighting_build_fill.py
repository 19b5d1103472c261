"""The street prior for unobserved surfaces (augment/lighting/fill.py) and its use in build_volume."""

from __future__ import annotations

import numpy as np
import torch

from streetaug.augment.lighting.build import DistantSun, build_volume
from streetaug.augment.lighting.observe import ViewObservation, ego_forward_vol
from streetaug.augment.lighting.fill import lateral_offsets_m, street_axis_xy, street_extrusion
from streetaug.augment.lighting.volume import HybridLighting, LogGrid
from streetaug.augment.core import make_transform, yaw_to_quat

RED, BLUE = np.array([0.30, 0.02, 0.02]), np.array([0.02, 0.02, 0.30])
GRID = LogGrid(shape=(48, 48, 16), half_extent_xy_m=40.0, z_min_m=-4.0, z_max_m=20.0)


def test_street_extrusion_is_the_shrunk_cell_mean():
    lat = np.array([1.0, 1.1, 1.2, 5.0])
    z = np.array([2, 2, 2, 3])
    vals = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [10.0, 5.0]])
    fallback = np.array([[0.0, 4.0], [0.0, 4.0], [7.0, 7.0], [7.0, 7.0]])
    out = street_extrusion(lat, z, vals, np.array([1.1, 5.0, 1.1, 3.0]), np.array([2, 3, 3, 2]),
                           np.full(4, 0.3), fallback, 1.0, 4, bin_m=0.05)
    # cell (1.1 +- 0.3 m, 2): three values, sum 6, plus the fallback with weight 1: (6 + 0) / 4
    assert np.allclose(out[0], [6.0 / 4, 4.0 / 4])
    assert np.allclose(out[1], [10.0 / 2, 9.0 / 2])  # (5 m, 3): one value
    assert np.allclose(out[2:], 7.0)  # nothing observed at (1.1 m, 3) nor (3 m, 2): the fallback exactly
    # a narrow window sees only the nearest value, a wide one all three
    narrow = street_extrusion(lat, z, vals, np.array([1.0]), np.array([2]), np.array([0.02]), fallback[:1], 1.0, 4,
                              bin_m=0.01)
    wide = street_extrusion(lat, z, vals, np.array([3.0]), np.array([2]), np.array([2.5]), fallback[:1], 1.0, 4)
    assert np.allclose(narrow[0], [1.0 / 2, 4.0 / 2]) and np.allclose(wide[0], out[0])
    many = street_extrusion(np.zeros(1000), np.zeros(1000, int), np.full((1000, 1), 0.5), np.array([0.0]),
                            np.array([0]), np.array([0.5]), np.array([[9.0]]), 3.0, 1)
    assert abs(many[0, 0] - 0.5) < 0.03  # well-observed cells ignore the fallback


def test_street_axis_from_the_ego_heading():
    assert np.allclose(street_axis_xy(None), [1.0, 0.0])
    assert np.allclose(street_axis_xy(np.array([0.3, 0.4, 0.0])), [0.6, 0.8])
    assert np.allclose(street_axis_xy(np.array([0.01, 0.0, 1.0])), [1.0, 0.0])  # near vertical: no heading


def test_lateral_offsets_ignore_the_position_along_the_street():
    theta = np.radians(35.0)
    axis = np.array([np.cos(theta), np.sin(theta)])
    across = np.array([-axis[1], axis[0]])
    along = np.linspace(-30.0, 30.0, 7)
    for offset in (-6.0, 1.0, 15.0):
        assert np.allclose(lateral_offsets_m(along[:, None] * axis + offset * across, axis), offset)


def test_ego_forward_in_the_volume_frame():
    class View:
        T_global_from_ego = make_transform(yaw_to_quat(np.radians(30.0)), [5.0, 2.0, 0.0])
        T_global_from_cam = T_global_from_ego @ make_transform(yaw_to_quat(np.radians(90.0)), [0.0, 1.0, 1.5])

    T_vol_from_cam = make_transform(yaw_to_quat(np.radians(90.0)), [0.0, 0.0, 1.5])  # volume = ego yawed
    f = ego_forward_vol(View(), T_vol_from_cam)
    assert np.allclose(f, [1.0, 0.0, 0.0], atol=1e-9)


def _wall_observation(axis_xy: np.ndarray, ego_forward) -> tuple[ViewObservation, np.ndarray]:
    """A wall 8 m left of a street along ``axis_xy``, red below 3 m and blue above, seen by a camera ahead
    (5..30 m along the street); LiDAR returns all along it."""
    across = np.array([-axis_xy[1], axis_xy[0]])
    s, z = np.meshgrid(np.arange(5.0, 30.0, 0.25), np.arange(0.5, 6.0, 0.25))
    seen = np.concatenate([s.reshape(-1, 1) * axis_xy + 8.0 * across, z.reshape(-1, 1)], axis=1)
    s2, z2 = np.meshgrid(np.arange(-30.0, 30.0, 0.5), np.arange(0.5, 6.0, 0.5))
    lidar = np.concatenate([s2.reshape(-1, 1) * axis_xy + 8.0 * across, z2.reshape(-1, 1)], axis=1)
    centre = np.array([0.0, 0.0, 1.5])
    vd = centre - seen
    vd /= np.linalg.norm(vd, axis=1, keepdims=True)
    obs = ViewObservation(
        "CAM_FRONT", seen, np.where(seen[:, 2:] < 3.0, RED, BLUE).astype(np.float32), vd,
        np.zeros(len(seen), bool), np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros(0, bool),
        np.zeros(0, bool), centre, ego_forward)
    return obs, lidar


def _wall_colour_behind(axis_deg: float, ego_forward_deg: float | None) -> np.ndarray:
    """The radiance (2, 3) of the (unobserved) wall 20 m behind the camera at 1.2 m and 4.5 m height, seen from
    the street. (4.5 m: inside the blue band the camera saw, 0.5-5.75 m; the wall's top voxel layer, 5-6 m,
    also holds its top edge, which the canyon prior no longer raises 25 % above what was seen.)"""
    axis = np.array([np.cos(np.radians(axis_deg)), np.sin(np.radians(axis_deg))])
    fwd = None if ego_forward_deg is None else np.array([np.cos(np.radians(ego_forward_deg)),
                                                         np.sin(np.radians(ego_forward_deg)), 0.0])
    obs, lidar = _wall_observation(axis, fwd)
    sky = np.full((16, 32, 3), 0.05, np.float32)
    light = DistantSun(np.array([0.0, 0.6, 0.8]), np.array([1.0, 1.0, 1.0]), np.array([0.2, 0.2, 0.2]))
    params, stats = build_volume(GRID, [obs], lidar, light, sky, unseen_keep=1.0)  # the street prior alone
    hy = HybridLighting(torch.from_numpy(sky), grid=GRID, params=params)
    across = np.array([-axis[1], axis[0]])
    p = np.array([np.r_[-20.0 * axis + 2.0 * across, h] for h in (1.2, 4.5)])
    with torch.no_grad():
        return hy.radiance(p, np.tile(np.r_[across, 0.0], (2, 1)), include_sun=False).numpy()


def test_unobserved_wall_behind_continues_the_wall_seen_ahead():
    for axis_deg in (0.0, 40.0):  # along the volume's x axis and a street at 40 deg to it
        low, high = _wall_colour_behind(axis_deg, axis_deg)
        assert low[0] > 3 * low[2] and high[2] > 3 * high[0]  # red below, blue above: as seen ahead
    # with a wrong street axis only the shading model (one fit to the whole wall) reaches it: no height bands
    low, high = _wall_colour_behind(40.0, 130.0)
    assert abs(np.log((low[0] / low[2]) / (high[0] / high[2]))) < np.log(2.0)
