"""The renderer's stages and public API: footprint, the prepared asset cached on the asset, surface at hits."""

import pickle

import numpy as np
import pytest

from render_fixtures import ground_scene, primitive_car, sunny_light
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.render import QUALITY_PRESETS, footprint, prepare_asset, render_insertion
from streetaug.augment.render.surface import SurfaceHits, surface_at_hits

W, H = 320, 180
K = intrinsics_from_fov(W, H, 60.0)
CAMERA = PinholeCamera(K, W, H)


@pytest.fixture(scope="module")
def car():
    return primitive_car()


def test_footprint_is_the_renderers_boxes_and_nothing_outside_changes(car):
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light, K, W, H)
    T = pose_camera_to_transform(1.0, 1.5, 14.0, 30.0)
    ins = render_insertion(image, K, depth, light, car, T, quality="draft", ev=ev, seed=1)
    where = footprint(CAMERA, car, T, light, QUALITY_PRESETS["draft"])
    assert ins.footprint == where and where.reaches_image
    assert where.object_box.as_list() == ins.stats["foreground"]["box"]
    assert where.shadow_box.as_list() == ins.stats["shadow"]["box"]
    outside = np.ones((H, W), bool)
    outside[where.box.slices] = False
    assert outside.any()
    np.testing.assert_array_equal(ins.image[outside], image[outside])
    assert ins.visible_px == pytest.approx(float(ins.mask.sum())) and ins.coverage_px >= ins.visible_px > 0


def test_footprint_of_an_object_behind_the_camera_is_empty(car):
    light = sunny_light()
    where = footprint(CAMERA, car, pose_camera_to_transform(0.0, 1.5, -20.0, 0.0), light, QUALITY_PRESETS["default"])
    assert where.object_box is None and where.shadow_box is None and not where.reaches_image and where.box is None


def test_prepared_asset_is_kept_on_the_asset_and_not_pickled(car):
    prep = prepare_asset(car)
    assert prepare_asset(car) is prep
    copy = pickle.loads(pickle.dumps(car))
    np.testing.assert_array_equal(copy.vertices, car.vertices)
    again = prepare_asset(copy)
    assert again is not prep and len(again.faces) == len(prep.faces)


def test_surface_at_hits_faces_the_ray_and_reads_the_material(car):
    prep = prepare_asset(car)
    o = np.array([[10.0, 0.0, 0.6], [0.0, 0.0, 0.6]])  # outside in front of the car / inside its body
    d = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    hits = prep.scene.intersect(o, d)
    assert hits.hit.all()
    surf = surface_at_hits(prep, hits.face, hits.bary, d)
    assert isinstance(surf, SurfaceHits)
    assert surf.normal.shape == surf.geometric_normal.shape == (2, 3) and surf.emission.shape == (2, 3)
    assert np.all(np.einsum("ij,ij->i", surf.geometric_normal, d) < 0)  # turned towards the ray's origin
    np.testing.assert_array_equal(surf.front, [True, False])  # the body's outside, then its inside
    np.testing.assert_array_equal(surf.material, prep.face_material[hits.face])
    np.testing.assert_allclose(surf.params.base_color, prep.base_color[surf.material])
