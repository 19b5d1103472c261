"""The render chain's colour: it adds no cast of its own and keeps a saturated paint's chroma (issue #20).

A clear-coated sphere on a ground plane, the photo rendered from the same light, composited with the camera
match on (veil estimated from the photo, blur, noise, JPEG re-encoding): a neutral paint under a neutral light
stays neutral, a neutral paint under a tinted light takes exactly the light's tint, and the camera-look stages
keep a saturated paint's chroma.
"""

import numpy as np
import pytest

from render_fixtures import ground_scene, sphere_asset, two_level_sky
from streetaug.augment.assets.asset import Material
from streetaug.augment.core import hdr_to_ldr_uint8, intrinsics_from_fov
from streetaug.augment.evaluation.realism import srgb_to_lab
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render import QUALITY_PRESETS, render_insertion
from streetaug.augment.render.veil import Veil

W, H = 480, 270
K = intrinsics_from_fov(W, H, 60.0)
UP = np.array([0.0, -1.0, 0.0])  # camera frame: y down, level camera 1.5 m above the ground
JPEG_QUALITY = 80


def _pose(distance_m: float = 9.0) -> np.ndarray:
    """Object frame (z up) 1.5 m below a level camera, ``distance_m`` ahead."""
    T = np.eye(4)
    T[:3, :3] = np.column_stack([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = [0.0, 1.5, distance_m]
    return T


def _coat(rgb) -> Material:
    return Material("paint", np.asarray(rgb, float), metallic=0.0, roughness=0.35, specular=0.5, clearcoat=1.0)


def _light(sky_rgb, ground_rgb) -> DistantLight:
    """A sun-less light: uniform ``sky_rgb`` above the horizon, ``ground_rgb`` below."""
    env = two_level_sky(UP, 1.0, 0.0, 32, 64)
    env = np.where(env > 0, np.asarray(sky_rgb, np.float32), np.asarray(ground_rgb, np.float32))
    return DistantLight(env.astype(np.float32), None)


def _insert(light: DistantLight, paint, match_camera: bool = True, veil: Veil | None = None,
            jpeg_quality: int | None = JPEG_QUALITY):
    image, depth, ev = ground_scene(light, K=K, width=W, height=H)
    quality = QUALITY_PRESETS["default"]
    if not match_camera:
        quality = type(quality)(**{**quality.__dict__, "match_camera": False})
    ins = render_insertion(image, K, depth, light, sphere_asset(0.8, _coat(paint)), _pose(), quality=quality, ev=ev,
                           seed=3, jpeg_quality=jpeg_quality if match_camera else None, veil=veil)
    inner = ins.alpha > 0.999
    assert inner.sum() > 2000
    return ins, inner, ev


def _lab_mean(pixels: np.ndarray) -> np.ndarray:
    """Mean CIELAB (3,) over uint8 pixels (N, 3), per pixel as the realism benchmark measures."""
    return srgb_to_lab(pixels[None])[0].astype(np.float64).mean(axis=0)


def test_neutral_paint_under_a_neutral_light_composites_neutral():
    ins, inner, _ = _insert(_light((1.0, 1.0, 1.0), (0.3, 0.3, 0.3)), (0.2, 0.2, 0.2))
    px = ins.image[inner].astype(np.float64)
    mean = px.mean(axis=0)
    assert np.ptp(mean) < 0.6, mean  # the channels agree within half an 8-bit level
    lab = _lab_mean(ins.image[inner])
    assert abs(lab[1]) < 0.3 and abs(lab[2]) < 0.3, lab


@pytest.mark.parametrize("sky, ground", [((0.85, 0.95, 1.2), (0.32, 0.3, 0.26)), ((1.15, 1.0, 0.8), (0.3, 0.3, 0.3))])
def test_neutral_paint_takes_the_lights_tint_and_nothing_else(sky, ground):
    """The composite's colour (camera match on) is the rendered radiance's through the response (match off):
    the veil, blur and noise stages add no cast; and the tint is the light's (bluish sky: b* < 0).  (The JPEG
    stage is left out here: it quantises a uniform patch's chroma to its DC step, +-0.4 in a* / b* for one
    colour, without a bias over colours: ``test_camera_look.test_jpeg_round_trip_adds_no_colour_bias``.)"""
    light = _light(sky, ground)
    on, inner, ev = _insert(light, (0.2, 0.2, 0.2), jpeg_quality=None)
    off, inner_off, _ = _insert(light, (0.2, 0.2, 0.2), match_camera=False)
    both = inner & inner_off
    lab_on, lab_off = _lab_mean(on.image[both]), _lab_mean(off.image[both])
    assert np.all(np.abs(lab_on[1:] - lab_off[1:]) < 0.15), (lab_on, lab_off)
    rendered = _lab_mean(hdr_to_ldr_uint8(off.object_radiance[both], ev))
    assert np.all(np.abs(lab_off[1:] - rendered[1:]) < 0.2), (lab_off, rendered)
    assert np.sign(lab_on[2]) == np.sign(sky[1] - sky[2]) and abs(lab_on[2]) > 1.0, lab_on


def test_camera_look_keeps_a_saturated_paints_chroma():
    """Blur, noise and JPEG re-encoding (no veil) keep the chroma of a saturated blue paint within 3 %."""
    light = _light((1.0, 1.0, 1.0), (0.3, 0.3, 0.3))
    paint = (0.03, 0.08, 0.35)
    on, inner, _ = _insert(light, paint, veil=Veil.none())
    off, inner_off, _ = _insert(light, paint, match_camera=False)
    both = inner & inner_off
    lab_on, lab_off = _lab_mean(on.image[both]), _lab_mean(off.image[both])
    c_on, c_off = np.hypot(*lab_on[1:]), np.hypot(*lab_off[1:])
    assert c_off > 15.0
    assert c_on > 0.97 * c_off, (lab_on, lab_off)
    assert abs(lab_on[0] - lab_off[0]) < 1.0
