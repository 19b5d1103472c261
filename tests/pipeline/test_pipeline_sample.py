"""Multi-camera insertion: one placement in the global frame, rendered consistently into every camera."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import shapely

from streetaug.augment.assets.select import select_assets
from streetaug.augment.pipeline import InsertOptions, insert_into_sample, place_in_sample
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

OPTIONS = InsertOptions(quality="draft", seed=0, yaw_sigma_deg=15.0)


@pytest.fixture(scope="module")
def sample():
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    return reader.sample(reader.sample_tokens("sample-sunny")[0])


def cars(n: int, seed: int = 0):
    return select_assets(np.random.default_rng(seed), n)


@pytest.fixture(scope="module")
def twin_result(sample):
    """CAM_FRONT and an identical camera under another name; objects placed only in CAM_FRONT."""
    front = sample.cameras["CAM_FRONT"]
    twin = replace(front, channel="CAM_TWIN", sample_data_token="twin")
    return front, insert_into_sample(sample, [front, twin], {"CAM_FRONT": cars(1)}, OPTIONS)


def test_object_placed_for_one_camera_appears_in_every_camera_that_sees_it(twin_result):
    front, result = twin_result
    assert result.placed_for == ["CAM_FRONT"] and result.skipped_reason is None
    a, b = result.views["CAM_FRONT"].objects, result.views["CAM_TWIN"].objects
    assert [o["object_index"] for o in a] == [0] == [o["object_index"] for o in b]
    assert a[0]["box_global"] == b[0]["box_global"]
    assert a[0]["bbox_2d"] == b[0]["bbox_2d"]
    # Visible/coverage pixels are summed over both cameras (the nuScenes visibility of the object).
    assert result.coverage_px[0] > 100
    image_a, image_b = result.views["CAM_FRONT"].image, result.views["CAM_TWIN"].image
    changed = (image_a != front.image).any(axis=2)
    assert changed.sum() > 100
    # Same object, same light, same depth: only the Monte Carlo noise (seeded per camera) differs, so the
    # changed pixels agree on average and pixel by pixel (the source image there correlates at ~0.2).
    pa, pb = image_a[changed].astype(float), image_b[changed].astype(float)
    assert np.abs(pa.mean(axis=0) - pb.mean(axis=0)).max() < 1.5
    assert np.corrcoef(pa.ravel(), pb.ravel())[0, 1] > 0.9


def test_camera_that_sees_no_object_keeps_its_image(sample):
    front, back = sample.cameras["CAM_FRONT"], sample.cameras["CAM_BACK"]
    result = insert_into_sample(sample, [front, back], {"CAM_FRONT": cars(1)}, OPTIONS)
    assert len(result.placements) == 1
    r = result.views["CAM_BACK"]
    assert r.objects == [] and r.skipped_reason == "no inserted object or shadow in view"
    assert np.array_equal(r.image, back.image)
    assert not np.array_equal(result.views["CAM_FRONT"].image, front.image)


def test_objects_of_different_cameras_never_overlap(sample):
    views = [sample.cameras[c] for c in ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_BACK")]
    placed = place_in_sample(sample, views, {v.channel: cars(2, i) for i, v in enumerate(views)}, OPTIONS)
    assert len(placed.placements) >= 2
    footprints = [shapely.Polygon(p.box.corners()[[2, 3, 7, 6], :2]) for p in placed.placements]
    for i in range(len(footprints)):
        for j in range(i + 1, len(footprints)):
            assert footprints[i].distance(footprints[j]) > 0.5, (i, j)


def test_placement_in_a_view_does_not_depend_on_later_cameras(sample):
    """Per-camera seeds: CAM_FRONT's objects are the same whether or not other cameras are augmented after it."""
    front, back = sample.cameras["CAM_FRONT"], sample.cameras["CAM_BACK"]
    alone = place_in_sample(sample, [front], {"CAM_FRONT": cars(1)}, OPTIONS)
    both = place_in_sample(sample, [front, back], {"CAM_FRONT": cars(1), "CAM_BACK": cars(1, 1)}, OPTIONS)
    assert np.array_equal(alone.placements[0].T_global_from_object, both.placements[0].T_global_from_object)
