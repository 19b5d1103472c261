"""render_objects keeps of each object only what the labels read, cut to the object's pixel box: none of
the renderer's full-frame layers of an object (~66 MB at 1600 x 900) outlives its compositing, neither
while the next object renders nor after render_objects returns."""

from __future__ import annotations

import gc
import sys
import weakref
from pathlib import Path

import numpy as np

from streetaug.augment.pipeline import InsertOptions
from streetaug.augment.pipeline import objects as objects_module
from streetaug.augment.pipeline.objects import render_objects
from streetaug.augment.render import render_insertion

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from render_fixtures import cars_on_ground_scene  # noqa: E402


def _scene():
    image, K, depth, lights, cars, poses, ev = cars_on_ground_scene(3)
    return image, K, depth, lights, cars, poses, InsertOptions(quality="draft", seed=0, ev=ev)


def test_no_full_frame_layer_of_a_composited_object_stays_referenced(monkeypatch):
    image, K, depth, lights, cars, poses, options = _scene()
    layers: list[weakref.ref] = []  # every full-frame layer but the composite image, of each render
    alive_at_next_render: list[int] = []
    calls: list[tuple[np.ndarray, np.ndarray, float, float]] = []  # each render's mask, coverage and pixel sums

    def spy(*args, **kwargs):
        gc.collect()
        alive_at_next_render.append(sum(r() is not None for r in layers))
        ins = render_insertion(*args, **kwargs)
        for name in ("mask", "coverage", "shadow_ratio", "object_depth_m", "shadow_ratio_rgb", "object_radiance",
                     "alpha"):
            if getattr(ins, name) is not None:
                layers.append(weakref.ref(getattr(ins, name)))
        calls.append((ins.mask.copy(), ins.coverage.copy(), ins.visible_px, ins.coverage_px))
        return ins

    monkeypatch.setattr(objects_module, "render_insertion", spy)
    out = render_objects(image, K, depth, lights, cars, poses, [T[:3, 2] for T in poses], options,
                         np.random.default_rng(0), {})
    gc.collect()
    assert len(calls) == 3 and len(layers) >= 15
    assert alive_at_next_render == [0, 0, 0]
    assert all(r() is None for r in layers)
    H, W = image.shape[:2]
    order = np.argsort([np.linalg.norm(T[:3, 3]) for T in poses], kind="stable")
    for (mask, coverage, visible_px, coverage_px), i in zip(calls, order):
        obj = out.objects[i]
        assert obj.mask_box.shape == obj.coverage_box.shape == (obj.box.height, obj.box.width)
        if coverage_px > 0:
            assert obj.mask_box.size < 0.25 * H * W  # the object's box, not the frame
        assert np.array_equal(obj.full_mask(), mask) and obj.full_mask().dtype == mask.dtype
        assert np.array_equal(obj.full_coverage(), coverage)
        assert (obj.visible_px, obj.coverage_px) == (visible_px, coverage_px)
        arrays = [v for v in vars(obj).values() if isinstance(v, np.ndarray)]
        assert all(a.size < H * W for a in arrays)
    assert sum(o.coverage_px > 0 for o in out.objects) >= 2


def _held_arrays(obj, seen=None) -> list[np.ndarray]:
    """Every numpy array an object holds, through its dataclass fields (recursively)."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return []
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return [obj]
    if not hasattr(obj, "__dataclass_fields__"):
        return []
    return [a for name in obj.__dataclass_fields__ for a in _held_arrays(getattr(obj, name), seen)]


def test_insertion_holds_no_full_frame_layer_but_its_image():
    image, K, depth, lights, cars, poses, options = _scene()
    ins = render_insertion(image, K, depth, lights[1], cars[1], poses[1], ground_normal_cam=poses[1][:3, 2],
                           quality="draft", ev=options.ev, seed=3)
    H, W = image.shape[:2]
    held = [a for a in _held_arrays(ins) if a is not ins.image]
    assert len(held) >= 10 and all(a.shape[0] * a.shape[1] < 0.5 * H * W for a in held)  # pixels, not values
    assert ins.layers.scene_depth_m is None
    mask, shadow, radiance = ins.mask, ins.shadow_ratio, ins.object_radiance
    assert mask.shape == shadow.shape == (H, W) and radiance.shape == (H, W, 3)
    assert mask.sum() > 100 and (shadow < 0.9).sum() > 100  # a visible car and its shadow
    outside = np.ones((H, W), bool)
    outside[ins.layers.box.slices] = False
    assert not mask[outside].any() and np.isinf(ins.object_depth_m[outside]).all()
    outside[:] = True
    outside[ins.composited.box.slices] = False
    assert (shadow[outside] == 1).all() and not radiance[outside].any()
    assert ins.visible_px == float(mask.sum()) and ins.coverage_px == float(ins.coverage.sum())


def test_render_objects_box_local_updates_are_the_dense_ones(monkeypatch):
    image, K, depth, lights, cars, poses, options = _scene()
    depth_before = depth.copy()
    seen: list[tuple] = []  # per render: the depth it got, its full mask, object depth and shadow ratio

    def spy(*args, **kwargs):
        ins = render_insertion(*args, **kwargs)
        seen.append((np.array(args[2], copy=True), ins.mask, ins.object_depth_m, ins.shadow_ratio))
        return ins

    monkeypatch.setattr(objects_module, "render_insertion", spy)
    out = render_objects(image, K, depth, lights, cars, poses, [T[:3, 2] for T in poses], options,
                         np.random.default_rng(0), {})
    assert np.array_equal(depth, depth_before)  # the caller's depth is not written to
    dense_depth, union, shadow = depth.copy(), np.zeros(depth.shape, np.float32), np.ones(depth.shape, np.float32)
    for got_depth, mask, obj_depth, ratio in seen:
        assert np.array_equal(got_depth, dense_depth)
        dense_depth = np.where(mask > 0.5, np.minimum(dense_depth, obj_depth), dense_depth)
        union, shadow = np.maximum(union, mask), shadow * ratio
    assert not np.array_equal(dense_depth, depth)  # an object in front of the ground
    assert np.array_equal(out.mask, union) and np.array_equal(out.shadow_ratio, shadow)
