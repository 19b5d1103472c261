"""Issue #20 (realism): inserted cars' paint mix taken from the sample's own cars; white paint's albedo bounded."""

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from streetaug.augment.assets.car_paint import MAX_PAINT_ALBEDO, paint_family, paint_palette
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.scene_paint import (band_ratio, image_reference_level, paint_band_rgb,
                                                  predicted_band_ratio, sample_car_ratios, scene_paint_mix,
                                                  scene_paint_weights)
from streetaug.augment.assets.select import select_assets
from streetaug.augment.core import ldr_uint8_to_hdr, make_transform
from streetaug.augment.evaluation.realism import srgb_to_lab

REGION = "asia_pacific"
K = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]])
W, H = 1280, 720


def family_shares(weights, region=REGION):
    out = {}
    for (name, *_), w in zip(paint_palette(region), weights):
        out[paint_family(name)] = out.get(paint_family(name), 0.0) + float(w)
    return out


def shade_rgb(name, region=REGION):
    return next(rgb for n, rgb, *_ in paint_palette(region) if n == name)


# ----------------------------------------------------------------------------- the mix follows the cars


def test_no_cars_keep_the_regions_table():
    prior = np.array([p[3] for p in paint_palette(REGION)])
    np.testing.assert_allclose(scene_paint_weights([], REGION), prior / prior.sum())


@pytest.mark.parametrize("shade,family", [("silver", "silver"), ("mid grey", "grey"), ("jet black", "black"),
                                          ("pure white", "white")])
def test_mix_follows_the_colour_of_the_given_cars(shade, family):
    prior = family_shares(scene_paint_weights([], REGION))
    ratios = [predicted_band_ratio(shade_rgb(shade)) * f for f in np.linspace(0.85, 1.15, 20)]
    mix = family_shares(scene_paint_weights(ratios, REGION))
    assert mix[family] == max(mix.values()), mix  # silver and white are ~x1.6 apart in a band: neighbours
    assert mix[family] > prior[family] + 0.2
    assert abs(sum(mix.values()) - 1.0) < 1e-9


def test_scene_of_silver_cars_draws_fewer_white_cars_than_the_table():
    # scene-0916's case: mostly silver and grey cars under an overcast sky, where Asia's table draws 48 % white.
    ratios = ([predicted_band_ratio(shade_rgb("silver"))] * 8 + [predicted_band_ratio(shade_rgb("mid grey"))] * 8
              + [predicted_band_ratio(shade_rgb("pure white"))] * 2)
    mix = family_shares(scene_paint_weights(ratios, REGION))
    assert mix["white"] < 0.3 and mix["silver"] + mix["grey"] > 0.6, mix


def test_chromatic_cars_pull_their_hue_family():
    ratios = [predicted_band_ratio(shade_rgb("bright red"))] * 10
    mix = family_shares(scene_paint_weights(ratios, REGION))
    assert mix["red"] > 0.5, mix
    ratios = [predicted_band_ratio(shade_rgb("royal blue"))] * 10
    assert family_shares(scene_paint_weights(ratios, REGION))["blue"] > 0.5


# ----------------------------------------------------------------------------- measuring the band in an image


def _box_pose(x_m: float = 0.5, z_m: float = 15.0, yaw_deg: float = 20.0) -> np.ndarray:
    """Camera <- box: the box's x (front) turned ``yaw_deg`` from the camera's right, ``z_m`` ahead, its centre
    0.6 m below the camera. Camera frame: x right, y down, z forward; box frame: x front, y left, z up."""
    yaw = np.radians(yaw_deg)
    R_world_from_box = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    R_cam_from_world = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # world: x right, y fwd, z up
    return make_transform(R_cam_from_world @ R_world_from_box, [x_m, 0.6, z_m])


WLH = np.array([1.8, 4.4, 1.5])


def _draw_box(image: np.ndarray, T: np.ndarray, paint_ldr: int) -> np.ndarray:
    """Fill the box's projected hull with ``paint_ldr``; returns its pixel rectangle (x0, y0, x1, y1)."""
    w, l, h = WLH
    corners = np.array([[sx * l / 2, sy * w / 2, sz * h / 2] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    cam = corners @ T[:3, :3].T + T[:3, 3]
    uv = cam[:, :2] / cam[:, 2:3] * K[0, 0] + K[:2, 2]
    cv2.fillConvexPoly(image, cv2.convexHull(uv.astype(np.float32)).astype(np.int32), (paint_ldr,) * 3)
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


def _scene(paint_ldr: int, ground_ldr: int = 90):
    """An image of one box car (its hull filled with ``paint_ldr``) on a grey ground: (image, pose, wlh, rect)."""
    image = np.full((H, W, 3), ground_ldr, np.uint8)
    T = _box_pose()
    return image, T, WLH, _draw_box(image, T, paint_ldr)


def test_band_reads_the_paint_of_the_box():
    image, T, wlh, rect = _scene(200)
    band = paint_band_rgb(image, K, T, wlh)
    assert len(band) >= 30
    np.testing.assert_allclose(np.median(band, axis=0), ldr_uint8_to_hdr(np.full((1, 1, 3), 200, np.uint8))[0, 0],
                               rtol=1e-6)
    # a nearer object covering the car: nothing to measure
    assert len(paint_band_rgb(image, K, T, wlh, [rect + np.array([-5, -5, 5, 5])])) == 0
    # behind the camera: nothing either
    T_back = T.copy()
    T_back[2, 3] = -15.0
    assert len(paint_band_rgb(image, K, T_back, wlh)) == 0


def test_band_ratio_orders_light_and_dark_cars():
    ratios = []
    for paint in (40, 120, 220):
        image, T, wlh, _ = _scene(paint)
        ratios.append(band_ratio(paint_band_rgb(image, K, T, wlh), image_reference_level(image)))
    lum = [float(r @ [0.2126, 0.7152, 0.0722]) for r in ratios]
    assert lum[0] < lum[1] < lum[2]
    assert band_ratio(np.zeros((3, 3)), 1.0) is None  # too few pixels


def _fake_sample(paints, location="singapore-queenstown", readable=True):
    """A duck-typed sample: one camera, one box car per paint (side by side, 15 m ahead)."""
    image = np.full((H, W, 3), 90, np.uint8)
    boxes = []
    for i, paint in enumerate(paints):
        T = _box_pose(x_m=-6.0 + 6.0 * i)
        _draw_box(image, T, paint)
        boxes.append(SimpleNamespace(T_global_from_box=T, wlh=WLH, category="vehicle.car", token=f"car{i}"))

    class View:
        K = globals()["K"]
        T_cam_from_global = np.eye(4)

        @property
        def image(self):
            if not readable:
                raise OSError("cannot read the image")
            return image

    return SimpleNamespace(cameras={"CAM_FRONT": View()}, boxes=tuple(boxes), location=location)


def test_sample_mix_follows_its_cars_and_falls_back_without():
    dark = _fake_sample([35, 35, 35])
    light = _fake_sample([215, 215, 215])
    r_dark, r_light = sample_car_ratios(dark), sample_car_ratios(light)
    assert len(r_dark) == 3 and len(r_light) == 3
    m_dark, m_light = family_shares(scene_paint_mix(dark)), family_shares(scene_paint_mix(light))
    assert m_dark["black"] + m_dark["grey"] > m_light["black"] + m_light["grey"] + 0.3
    assert m_light["white"] + m_light["silver"] > m_dark["white"] + m_dark["silver"] + 0.3
    assert scene_paint_mix(_fake_sample([200], readable=False)) is None  # unreadable image: the region's table
    no_cars = SimpleNamespace(cameras=dark.cameras, boxes=(), location="singapore-queenstown")
    assert scene_paint_mix(no_cars) is None


# ----------------------------------------------------------------------------- paint weights in the generator


def test_paint_weights_choose_the_paint_and_keep_the_body():
    names = [p[0] for p in paint_palette(REGION)]
    only_black = tuple(1.0 if n == "jet black" else 0.0 for n in names)
    for seed in range(6):
        a = procedural_car(seed, paint_region=REGION)
        b = procedural_car(seed, paint_region=REGION, paint_weights=only_black)
        assert b.name.endswith("jet_black")
        np.testing.assert_array_equal(a.vertices, b.vertices)  # one paint draw either way: same body
    cars = select_assets(np.random.default_rng(0), 4, location="singapore-queenstown", paint_weights=only_black)
    assert all(c.name.endswith("jet_black") for c in cars)
    with pytest.raises(ValueError, match="paint_weights"):
        procedural_car(0, paint_region=REGION, paint_weights=(1.0, 2.0))
    with pytest.raises(ValueError, match="paint_weights"):
        procedural_car(0, paint_region=REGION, paint_weights=tuple(-x for x in only_black))


def test_white_cars_albedo_is_bounded():
    names = [p[0] for p in paint_palette(REGION)]
    only_white = tuple(1.0 if paint_family(n) == "white" else 0.0 for n in names)
    top = []
    for seed in range(40):
        car = procedural_car(seed, paint_region=REGION, paint_weights=only_white)
        rgb = car.materials[0].base_color
        assert rgb.max() <= MAX_PAINT_ALBEDO + 1e-12
        top.append(rgb)
    lin = np.array(top)
    s = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    lab = srgb_to_lab((np.clip(s, 0, 1) * 255).round().astype(np.uint8)[None])[0]
    assert lab[:, 0].max() <= 93.5 and lab[:, 0].min() > 85.0, lab[:, 0]
    # the brightest channel is capped, the hue kept: a capped paint stays neutral
    assert np.all(np.abs(lab[:, 1]) < 1.0) and np.all(np.abs(lab[:, 2]) < 2.0)


def test_mix_reproduces_the_composition_of_the_cars():
    # 12 mid-grey, 6 black and 6 white cars (their predicted bands, +-10 %): the MAP mix draws about those shares,
    # pulled a little towards the region's table (4 cars' worth), not spread over every neighbour.
    ratios = ([predicted_band_ratio(shade_rgb("mid grey")) * f for f in np.linspace(0.9, 1.1, 12)]
              + [predicted_band_ratio(shade_rgb("jet black")) * f for f in np.linspace(0.9, 1.1, 6)]
              + [predicted_band_ratio(shade_rgb("pure white")) * f for f in np.linspace(0.9, 1.1, 6)])
    mix = family_shares(scene_paint_weights(ratios, REGION))
    prior = family_shares(scene_paint_weights([], REGION))
    for family, share in (("grey", 0.5), ("black", 0.25), ("white", 0.25)):
        expected = (24 * share + 4 * prior[family]) / 28
        assert abs(mix[family] - expected) < 0.12, (family, mix)
