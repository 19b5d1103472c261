"""Car paint renders at the level its colour and the light predict (issue #20: inserted cars too dark)."""

from dataclasses import replace

import numpy as np
import pytest

from streetaug.augment.assets import car_body as cb
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core import hdr_to_ldr
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render import render_insertion
from streetaug.augment.render.settings import resolve_settings
from streetaug.augment.render.surface import prepare_asset

SKY = 0.5  # uniform environment radiance (every direction)
K = np.array([[1200.0, 0.0, 450.0], [0.0, 1200.0, 300.0], [0.0, 0.0, 1.0]])
SILVER = (0.462, 0.479, 0.497)  # linear "silver" B5B8BB


def _pose(yaw_deg: float, dist_m: float) -> np.ndarray:
    """Camera 1.6 m above the ground, the car ``dist_m`` ahead turned by ``yaw_deg`` (object x front, z up)."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:3, :3] = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    T[:3, 3] = [0.0, 1.6, dist_m]
    return T


def _paint_radiance(paint: tuple, yaw_deg: float = 60.0, dist_m: float = 9.0) -> dict[str, np.ndarray]:
    """Mean rendered radiance (3,) of the paint's fully covered pixels facing up ("top") and sideways ("side")."""
    asset = procedural_car(5, "sedan", paint=paint)
    T = _pose(yaw_deg, dist_m)
    light = DistantLight(np.full((64, 128, 3), SKY, np.float32), None)
    image = np.full((600, 900, 3), 128, np.uint8)
    settings = replace(resolve_settings("default"), match_camera=False)  # the radiance alone
    ins = render_insertion(image, K, np.full((600, 900), np.inf, np.float32), light, asset, T, quality=settings, seed=1)
    prep = prepare_asset(asset)
    ys, xs = np.nonzero(ins.coverage > 0.999)
    rays = np.stack([(xs + 0.5 - K[0, 2]) / K[0, 0], (ys + 0.5 - K[1, 2]) / K[1, 1], np.ones(len(xs))], 1)
    R, t = T[:3, :3], T[:3, 3]
    hits = prep.scene.intersect(np.tile(-R.T @ t, (len(xs), 1)), rays @ R)
    face = np.where(hits.hit, hits.face, 0)
    paint_px = hits.hit & np.isin(prep.face_material[face], [cb.PAINT])
    n_z = prep.face_normal[face][:, 2]
    rad = ins.object_radiance[ys, xs]
    out = {}
    for name, sel in (("top", paint_px & (n_z > 0.8)), ("side", paint_px & (np.abs(n_z) < 0.35))):
        assert sel.sum() > 300, name
        out[name] = rad[sel].mean(axis=0)
    return out


def test_white_car_under_a_uniform_sky_renders_at_its_albedo():
    # Under a uniform sky L an open surface of albedo a reflects a L whatever its lobes (energy conservation);
    # the clear coat adds its Fresnel reflection of the same sky and takes as much from the base.  The roof and
    # bonnet are open (a little of the cabin blocks the bonnet: the one bounce returns part of it).
    white = 0.80
    rad = _paint_radiance((white, white, white, 0.0))
    top = rad["top"].mean()
    assert 0.88 * white * SKY < top < 1.08 * (white + 0.04) * SKY, rad
    assert hdr_to_ldr(top) * 255 == pytest.approx(hdr_to_ldr(white * SKY) * 255, abs=12)
    # the sides see the car's own shadow and underbody below the horizon: darker, but not by much
    assert 0.65 * white * SKY < rad["side"].mean() < top, rad


def test_metallic_paint_is_as_bright_as_solid_paint_of_its_colour():
    # Silver's metallic look (flakes in the base coat) must not darken it: a bare-metal UE4 lobe returned only
    # ~60-75 % of the light at the oblique views of roofs and sides (single scattering, no energy compensation).
    solid = _paint_radiance(SILVER + (0.0,))
    metallic = _paint_radiance(SILVER + (0.7,))
    for name in ("top", "side"):
        ratio = metallic[name].mean() / solid[name].mean()
        assert 0.9 < ratio < 1.1, (name, ratio)
