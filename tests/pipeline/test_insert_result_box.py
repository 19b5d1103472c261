"""InsertResult holds its mask and shadow ratio only inside the box of the pixels they change."""

import numpy as np

from streetaug.augment.pipeline import InsertResult
from streetaug.augment.pipeline.results import changed_pixel_box
from streetaug.augment.render import PixelBox

H, W = 90, 160


def _layers():
    mask = np.zeros((H, W), np.float32)
    mask[30:50, 40:70] = 0.8
    shadow = np.ones((H, W), np.float32)
    shadow[45:60, 35:90] = 0.6  # the shadow reaches past the object
    return mask, shadow


def test_the_box_holds_object_and_shadow_and_the_full_layers_round_trip():
    mask, shadow = _layers()
    image = np.zeros((H, W, 3), np.uint8)
    result = InsertResult.of(image, [], mask, shadow, {"total": 0.0})
    assert result.changed_box == PixelBox(35, 30, 90, 60)
    assert result.mask_box.shape == (30, 55) and result.shadow_ratio_box.shape == (30, 55)
    np.testing.assert_array_equal(result.mask, mask)
    np.testing.assert_array_equal(result.shadow_ratio, shadow)
    assert result.mask.dtype == np.float32 and result.shadow_ratio.dtype == np.float32
    mask[:] = 1.0  # a copy: the caller's full-frame arrays are not referenced
    assert result.mask[0, 0] == 0.0


def test_nothing_inserted_holds_nothing_and_reads_as_unchanged():
    image = np.zeros((H, W, 3), np.uint8)
    for result in (InsertResult.of(image, [], None, None, {}),
                   InsertResult.of(image, [], np.zeros((H, W), np.float32), np.ones((H, W), np.float32), {})):
        assert result.mask_box.size == 0 and result.changed_box == PixelBox(0, 0, 0, 0)
        assert result.mask.shape == (H, W) and not result.mask.any()
        assert (result.shadow_ratio == 1).all()


def test_changed_pixel_box_is_the_tightest_box():
    changed = np.zeros((H, W), bool)
    changed[5, 7] = changed[20, 3] = True
    assert changed_pixel_box(changed) == PixelBox(3, 5, 8, 21)
