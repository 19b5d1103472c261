"""Memory of the composite (issue #19): the object's layers are held only inside its and its shadow's pixel box,
the veil and the composite work on the object's pixels only, and none of it changes a byte of the result."""

import tracemalloc

import numpy as np
import pytest

from streetaug.augment.core import PinholeCamera
from streetaug.augment.render import composite as composite_mod
from streetaug.augment.render.composite import LAYER_FILL, composite, composite_layers, depth_visibility, object_layers
from streetaug.augment.render.footprint import PixelBox
from streetaug.augment.render.foreground import Foreground
from streetaug.augment.render.shadow import ShadowMap
from streetaug.augment.render.veil import Veil

W, H = 1600, 900
K = np.array([[1266.0, 0.0, 800.0], [0.0, 1266.0, 450.0], [0.0, 0.0, 1.0]])
FG_BOX = PixelBox(700, 380, 820, 470)
SH_BOX = PixelBox(660, 440, 900, 520)


def layers_inputs(seed: int = 0):
    """A foreground and a shadow in small boxes of a 1600 x 900 image, and the scene's depth (partly in front)."""
    rng = np.random.default_rng(seed)
    h, w = FG_BOX.height, FG_BOX.width
    alpha = np.clip(rng.uniform(-0.3, 1.3, (h, w)), 0.0, 1.0).astype(np.float32)
    radiance = (rng.uniform(0.0, 2.0, (h, w, 3)) * alpha[..., None]).astype(np.float32)
    depth = np.where(alpha > 0, rng.uniform(14.0, 16.0, (h, w)), np.inf).astype(np.float32)
    solid = np.maximum(alpha, (rng.random((h, w)) < 0.1).astype(np.float32))
    fg = Foreground(FG_BOX, radiance, alpha, depth, {}, solid)
    ratio = np.clip(rng.uniform(0.3, 1.4, (SH_BOX.height, SH_BOX.width, 3)), 0.0, 1.0).astype(np.float32)
    sh = ShadowMap(SH_BOX, ratio, {})
    scene = np.full((H, W), 40.0, np.float32)
    scene[400:430, 720:760] = 10.0  # something in front of part of the object
    scene[:100] = np.inf
    return fg, sh, scene


def dense_layers(fg: Foreground, sh: ShadowMap, scene: np.ndarray) -> dict[str, np.ndarray]:
    """The layers over the whole image as they were built before (one full-frame array each)."""
    full = {name: np.full((H, W, 3) if name in ("radiance_premult", "ratio_rgb") else (H, W), fill, np.float32)
            for name, fill in LAYER_FILL.items()}
    sl = fg.box.slices
    vis = depth_visibility(fg.depth_m, scene[sl])
    solid = np.maximum(fg.solid, fg.alpha)
    full["coverage"][sl], full["mask"][sl], full["visibility"][sl] = fg.alpha, fg.alpha * vis, vis
    full["solid_coverage"][sl], full["solid_mask"][sl] = solid, solid * vis
    full["depth_m"][sl], full["radiance_premult"][sl] = fg.depth_m, fg.radiance_premult
    full["ratio_rgb"][sh.box.slices] = sh.ratio_rgb
    return full


class TestObjectLayers:
    def test_hold_only_the_union_box(self):
        fg, sh, scene = layers_inputs()
        layers = object_layers(fg, sh, scene)
        assert layers.box == FG_BOX.union(SH_BOX)
        size = (layers.box.height, layers.box.width)
        for name in ("coverage_box", "visibility_box", "mask_box", "depth_box", "solid_coverage_box",
                     "solid_mask_box"):
            assert getattr(layers, name).shape == size, name
        assert layers.radiance_box.shape == size + (3,) and layers.ratio_box.shape == size + (3,)

    def test_full_frame_views_match_the_dense_layers(self):
        fg, sh, scene = layers_inputs()
        layers = object_layers(fg, sh, scene)
        for name, dense in dense_layers(fg, sh, scene).items():
            np.testing.assert_array_equal(getattr(layers, name), dense, err_msg=name)
            assert layers.crop(name, PixelBox(600, 300, 1000, 600)).tobytes() == dense[300:600, 600:1000].tobytes()
            inside = layers.crop(name, PixelBox(700, 450, 850, 500))  # inside the box: a view, no copy
            assert inside.tobytes() == dense[450:500, 700:850].tobytes() and inside.base is not None

    def test_crop_outside_the_box_is_the_fill(self):
        fg, sh, scene = layers_inputs()
        layers = object_layers(fg, sh, scene)
        np.testing.assert_array_equal(layers.crop("depth_m", PixelBox(0, 0, 50, 40)), np.inf)
        np.testing.assert_array_equal(layers.crop("ratio_rgb", PixelBox(1500, 800, 1600, 900)), 1.0)
        empty = object_layers(None, None, scene)
        assert empty.box is None
        np.testing.assert_array_equal(empty.mask, 0.0)
        np.testing.assert_array_equal(empty.ratio_rgb, 1.0)

    def test_does_not_allocate_full_frame_layers(self):
        """A car 30 m away fills ~1 % of the frame: its layers took 69 MB of full-frame arrays (1600 x 900)."""
        fg, sh, scene = layers_inputs()
        tracemalloc.start()
        try:
            layers = object_layers(fg, sh, scene)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        box_bytes = layers.box.height * layers.box.width * 4 * (6 + 2 * 3)
        assert peak < 2 * box_bytes + 2**20, (peak, box_bytes)  # one full-frame float layer is 5.8 MB


@pytest.mark.parametrize("match_camera", [False, True])
def test_composite_layers_match_the_dense_composite(match_camera, monkeypatch):
    """Compositing the box-held layers (chunked per pixel) is byte-identical to compositing full-frame layers."""
    fg, sh, scene = layers_inputs(1)
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    camera = PinholeCamera(K, W, H)
    veil = Veil(np.array([5.0, 20.0, 60.0]), np.array([0.0, 0.01, 0.03]), np.array([0.8, 0.85, 0.9]))
    layers = object_layers(fg, sh, scene)
    a = composite_layers(image, layers, camera, match_camera, 0.0, np.random.default_rng(7), veil=veil)
    monkeypatch.setattr(composite_mod, "COMPOSITE_CHUNK_PX", 997)
    b = composite_layers(image, layers, camera, match_camera, 0.0, np.random.default_rng(7), veil=veil)
    assert a.image.tobytes() == b.image.tobytes()
    np.testing.assert_array_equal(a.object_radiance, b.object_radiance)
    np.testing.assert_array_equal(a.shadow_ratio, b.shadow_ratio)
    if not match_camera:  # the plain composite against the dense formula over the whole image
        d = dense_layers(fg, sh, scene)
        dense = composite(image, d["radiance_premult"], d["mask"], d["visibility"], d["ratio_rgb"], 0.0)
        assert a.image.tobytes() == dense.tobytes()
    assert (a.image != image).any()


class TestVeilOnPixels:
    VEIL = Veil(np.array([2.5, 12.5, 40.0]), np.array([0.001, 0.01, 0.04]), np.array([0.7, 0.8, 0.95]))

    def object_in_frame(self):
        rng = np.random.default_rng(5)
        cov = np.zeros((H, W), np.float32)
        cov[400:480, 700:820] = np.clip(rng.uniform(-0.2, 1.2, (80, 120)), 0, 1)
        rad = (rng.uniform(0, 3, (H, W, 3)) * cov[..., None]).astype(np.float32)
        depth = np.where(cov > 0, rng.uniform(5, 50, (H, W)), np.inf).astype(np.float32)
        return rad, cov, depth

    def test_apply_is_the_dense_formula(self):
        rad, cov, depth = self.object_in_frame()
        haze = self.VEIL.haze_at(depth)[..., None]
        dense = (rad * (1.0 - haze) + self.VEIL.airlight_rgb * haze * cov.astype(np.float64)[..., None]).astype(np.float32)
        assert self.VEIL.apply(rad, cov, depth).tobytes() == dense.tobytes()

    def test_apply_does_not_allocate_float64_frames(self):
        """A near object's box can be the whole frame: its float64 temporaries were ~130 MB."""
        rad, cov, depth = self.object_in_frame()
        tracemalloc.start()
        try:
            self.VEIL.apply(rad, cov, depth)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 2 * H * W * 3 * 4, peak  # its float32 result and masks; one float64 RGB frame is 35 MB

    def test_shadow_ratio_is_the_dense_formula(self):
        rng = np.random.default_rng(6)
        S = np.ones((H, W, 3), np.float32)
        S[300:500, 600:900] = rng.uniform(0.2, 1.0, (200, 300, 3))
        image = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
        depth = rng.uniform(3, 60, (H, W)).astype(np.float32)
        from streetaug.augment.core import ldr_uint8_to_hdr

        V = self.VEIL.haze_at(depth)[..., None] * self.VEIL.airlight_rgb
        I = ldr_uint8_to_hdr(image, 0.0).astype(np.float64)
        share = np.clip(V / np.maximum(I, 1e-9), 0.0, 1.0)
        S64 = S.astype(np.float64)
        dense = (S64 + (1.0 - S64) * share).astype(np.float32)
        got = self.VEIL.shadow_ratio(S, image, depth, 0.0)
        assert got.tobytes() == dense.tobytes()
        assert S[0, 0, 0] == 1.0 and got is not S
