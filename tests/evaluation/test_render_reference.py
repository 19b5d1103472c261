"""The renderer against a Mitsuba 3 reference (optional: skipped when mitsuba is not importable).

The conventions of the reference scene (camera, pixel centres, principal point, environment-map
orientation) are checked with a single bright direction, then a small insertion is compared.
"""

import dataclasses

import cv2
import numpy as np
import pytest

from render_fixtures import primitive_car, sunny_light
from streetaug.augment.assets.asset import Material
from streetaug.augment.core import (hdr_to_ldr_uint8, intrinsics_from_fov, lonlat_to_camera_dir, luminance,
                                   pose_camera_to_transform, project_points)
from streetaug.augment.core.depth import ground_plane_depth
from streetaug.augment.evaluation import reference as ref
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.render import render_insertion

OK, WHY = ref.mitsuba_available()
pytestmark = pytest.mark.skipif(not OK, reason=f"Mitsuba reference unavailable: {WHY}")


def _spot_env(spots, height=256, width=512):
    """A black map with 2 x 2-pixel spots; returns the map and each spot's exact camera-frame direction."""
    env = np.zeros((height, width, 3), np.float32)
    dirs = []
    for lon_deg, lat_deg, ch in spots:
        u = int((lon_deg / 360 + 0.5) * width)
        v = int((0.5 - lat_deg / 180) * height)
        env[v - 1 : v + 1, u - 1 : u + 1, ch] = 1000.0
        # the 2 x 2 block is centred on the pixel corner (u, v)
        dirs.append(lonlat_to_camera_dir(np.array((u / width - 0.5) * 2 * np.pi), np.array((0.5 - v / height) * np.pi)))
    return env, np.array(dirs)


@pytest.mark.parametrize("principal", ["centred", "off-centre"])
def test_camera_and_envmap_conventions_single_bright_direction(principal):
    """A bright direction of the camera-frame map lands where our projection puts it (to 0.15 px)."""
    W, H = 160, 90
    cx, cy = ((W - 1) / 2, (H - 1) / 2) if principal == "centred" else (100.0, 55.0)
    K = np.array([[100.0, 0, cx], [0, 100.0, cy], [0, 0, 1]])
    env, dirs = _spot_env([(20, 10, 0), (-15, 5, 1), (-30, 15, 2)])
    scene = ref.ReferenceScene(K, W, H, env, np.array([0, -1.0, 0]), 1.5, np.zeros(3))
    img, _ = ref.render(ref.build_scene(scene, spp=16), 16, seed=0)
    ys, xs = np.mgrid[0:H, 0:W]
    for ch, d in enumerate(dirs):
        w = img[..., ch]
        assert w.max() > 0, f"spot {ch} not in view"
        centroid = np.array([(xs * w).sum() / w.sum(), (ys * w).sum() / w.sum()])
        expected, _ = project_points(K, d[None])
        np.testing.assert_allclose(centroid, expected[0], atol=0.15)


def test_material_mapping():
    lam = ref.mitsuba_bsdf(Material("m", np.array([0.5, 0.4, 0.3]), metallic=0.0, specular=0.0))
    assert lam["type"] == "diffuse"
    metal = ref.mitsuba_bsdf(Material("m", np.array([0.9, 0.6, 0.1]), metallic=1.0, roughness=0.7))
    assert metal["type"] == "principled" and metal["metallic"] == 1.0 and metal["roughness"] == 0.7
    glass = ref.mitsuba_bsdf(Material("g", np.ones(3) * 0.1, roughness=0.05, opacity=0.3))
    assert glass["type"] == "mask" and glass["opacity"] == 0.3


def _exact_car():
    """The primitive car with materials whose Mitsuba mapping is exact: rough metals and Lambertians."""
    car = primitive_car()
    mats = (Material("paint", np.array([0.7, 0.15, 0.1]), metallic=1.0, roughness=1.0),
            Material("cabin", np.array([0.3, 0.3, 0.32]), metallic=0.0, specular=0.0),
            Material("tyre", np.array([0.05, 0.05, 0.05]), metallic=0.0, specular=0.0))
    return dataclasses.replace(car, materials=mats)


def test_insertion_matches_mitsuba():
    """A small sunny scene: our default composite against Mitsuba's with-car image (same LDR space)."""
    W, H = 200, 112
    K = intrinsics_from_fov(W, H, 55.0)
    up, albedo = np.array([0.0, -1.0, 0.0]), np.array([0.2, 0.2, 0.2])
    env = sunny_light(sun_dir_cam=(-0.55, -0.6, 0.3), sun_irradiance=6.0).to_envmap(128, 256)
    env = ref.with_ground_below_horizon(env, up, albedo)
    ev = float(np.log2(0.45**2.2 / luminance(ref.ground_radiance(env, up, albedo))))
    car = _exact_car()
    T = pose_camera_to_transform(0.3, 1.5, 9.0, 60.0)
    scene = ref.ReferenceScene(K, W, H, env, up, 1.5, albedo, car, T)
    crop = (20, 45, 190, 112)
    without, _ = ref.render(ref.build_scene(scene.without_object(), crop=crop), 48, seed=1)
    with_car, _ = ref.render(ref.build_scene(scene, crop=crop), 48, seed=1)
    x0, y0, x1, y1 = crop
    bg = np.full((H, W, 3), 0.0, np.float32)
    bg[:] = np.median(without.reshape(-1, 3), axis=0)  # outside the crop: anything
    bg[y0:y1, x0:x1] = without
    full_ref = bg.copy()
    full_ref[y0:y1, x0:x1] = with_car
    image = hdr_to_ldr_uint8(bg, ev)
    reference = hdr_to_ldr_uint8(full_ref, ev).astype(np.float64)
    depth = ground_plane_depth(K, W, H, up, 1.5)
    res = render_insertion(image, K, depth, DistantLight.from_envmap(env), car, T, ev=ev, seed=0)
    changed = cv2.GaussianBlur(np.abs(reference - image).max(axis=2).astype(np.float32), (0, 0), 1.5) > 1.0
    region = cv2.dilate((changed | (res.coverage > 0)).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert region.sum() > 1500
    mse = ((res.image.astype(np.float64) - reference) ** 2).mean(axis=2)
    psnr_region = 10 * np.log10(255**2 / mse[region].mean())
    # The car's shadow falls to the right (sun on the left): the reference and we agree on where.
    shadow_ref = (reference.mean(axis=2) < 0.6 * image.mean(axis=2)) & (res.coverage == 0)
    shadow_ours = (res.image.mean(axis=2) < 0.6 * image.mean(axis=2)) & (res.coverage == 0)
    overlap = (shadow_ref & shadow_ours).sum() / max((shadow_ref | shadow_ours).sum(), 1)
    assert overlap > 0.7, overlap
    print(f"PSNR region {psnr_region:.2f} dB, shadow overlap {overlap:.2f}")
    assert psnr_region > 30.0, psnr_region
