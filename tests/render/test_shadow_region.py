"""The shadow's pixel box holds the whole ratio map: 1 on all four edges for any sun, long low-sun shadows included."""

import numpy as np
import pytest

from render_fixtures import plane_shadow, primitive_car, two_level_sky
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.lighting.light import DistantLight, SunLight
from streetaug.augment.render import RenderSettings
from streetaug.augment.render.footprint import fade_weight

W, H = 480, 270
K = intrinsics_from_fov(W, H, 70.0)
CAMERA = PinholeCamera(K, W, H)
UP = np.array([0.0, -1.0, 0.0])
CAR = primitive_car()
T = pose_camera_to_transform(1.0, 1.5, 12.0, 30.0)


def _light(elev_deg: float, az_deg: float) -> DistantLight:
    """Uniform sky (0.3 above the horizon, 0.1 below) and a sun at ``elev_deg`` above the horizon (camera frame)."""
    env = two_level_sky(UP, 0.3, 0.1)
    e, a = np.radians(elev_deg), np.radians(az_deg)
    s = np.array([np.cos(e) * np.sin(a), -np.sin(e), np.cos(e) * np.cos(a)])
    return DistantLight(env, SunLight(s, np.full(3, 3.0), np.radians(0.27)))


def _ratio(light: DistantLight, settings: RenderSettings | None = None):
    box, sh = plane_shadow(CAMERA, CAR, T, UP, light, ground_plane_depth(K, W, H, UP, 1.5), settings)
    return box, sh.ratio_rgb


@pytest.mark.parametrize("elev_deg,az_deg", [(2.0, 150.0), (5.0, 210.0), (10.0, 180.0), (40.0, 200.0)])
def test_ratio_is_one_on_every_edge_of_the_shadow_box(elev_deg, az_deg):
    box, ratio = _ratio(_light(elev_deg, az_deg))
    assert box.x0 > 0 and box.y0 > 0 and box.x1 < W and box.y1 < H  # the box's edges are not the image's
    for edge in (ratio[0], ratio[-1], ratio[:, 0], ratio[:, -1]):
        np.testing.assert_array_equal(edge, 1.0)
    r = ratio.mean(axis=2)
    assert r.min() < 0.3 and (r < 0.5).sum() > 400  # the sun shadow is inside


def test_low_sun_shadow_fades_out_smoothly():
    """At 2 deg the shadow (43 m uncut) is faded before the 30 m cap: the ratio rises through the fade in small steps."""
    light = DistantLight(np.zeros((32, 64, 3), np.float32), _light(2.0, 150.0).sun)  # sun only: no sky occlusion
    _, ratio = _ratio(light)
    r = ratio.mean(axis=2)
    assert r.min() < 0.05
    for edge in (r[0], r[-1], r[:, 0], r[:, -1]):  # the shadow ends inside the box
        np.testing.assert_array_equal(edge, 1.0)
    partial = (r > 0.05) & (r < 0.95)
    assert partial.sum() > 50  # a faded stretch, not a cut
    # Along every row, no jump from deep shadow to none between neighbouring pixels (a straight cut would).
    jumps = np.abs(np.diff(r, axis=1))
    assert np.percentile(jumps[jumps > 0], 99) < 0.9


def test_fade_weight_is_smooth_and_exactly_zero_at_the_end():
    d = np.linspace(0.0, 40.0, 401)
    w = fade_weight(d, 30.0, 0.6)
    assert np.all(w[d <= 18.0] == 1.0) and np.all(w[d >= 30.0] == 0.0)
    assert np.all(np.diff(w) <= 0) and np.abs(np.diff(w)).max() < 0.02
