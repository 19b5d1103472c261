"""render_objects measures the camera's neutral axis once per image, on the image as captured (as the veil), and
every object's pixels get that one axis: not one measurement per object, each on the image with the objects
drawn before it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.pipeline import InsertOptions
from streetaug.augment.pipeline import objects as objects_module
from streetaug.augment.pipeline.objects import render_objects
from streetaug.augment.render import camera_look, render_insertion
from streetaug.augment.render import insert as insert_module

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from render_fixtures import cars_on_ground_scene, ground_scene, sunny_light  # noqa: E402


def _scene():
    image, K, depth, lights, cars, poses, ev = cars_on_ground_scene(2)
    image = image.copy()
    image[..., 1] = np.clip(image[..., 1].astype(int) + 3, 0, 255).astype(np.uint8)  # a green cast to measure
    return image, K, depth, lights, cars, poses, InsertOptions(quality="draft", seed=0, ev=ev)


def test_the_neutral_axis_is_measured_once_per_image_on_the_image_as_captured(monkeypatch):
    image, K, depth, lights, cars, poses, options = _scene()
    original = image.copy()
    measured: list[np.ndarray] = []  # the images the axis was measured on
    applied: list[camera_look.NeutralAxis] = []

    def measure(img, *a, **k):
        measured.append(np.array(img, copy=True))
        return camera_look.neutral_axis(img, *a, **k)

    def apply(img, alpha, axis):
        applied.append(axis)
        return camera_look.apply_neutral_axis(img, alpha, axis)

    monkeypatch.setattr(insert_module, "neutral_axis", measure)
    monkeypatch.setattr(objects_module, "neutral_axis", measure, raising=False)
    monkeypatch.setattr(insert_module, "apply_neutral_axis", apply)
    out = render_objects(image, K, depth, lights, cars, poses, [T[:3, 2] for T in poses], options,
                         np.random.default_rng(0), {})
    assert sum(o.coverage_px > 0 for o in out.objects) == 2 and len(applied) == 2  # both drawn, both get the axis
    assert len(measured) == 1
    assert np.array_equal(measured[0], original)  # before any object was drawn
    assert applied[0] is applied[1]
    assert np.abs(applied[0].offsets_dn).max() > 0.5  # the cast was found (the test measures something)
    assert np.array_equal(image, original)  # the caller's image is not written to


def test_a_given_neutral_axis_renders_the_same_bytes_as_one_measured_on_the_image():
    image, K, depth, lights, cars, poses, options = _scene()
    kw = dict(quality="draft", ev=options.ev, seed=5)
    measured_here = render_insertion(image, K, depth, lights[0], cars[0], poses[0], **kw)
    given = render_insertion(image, K, depth, lights[0], cars[0], poses[0], neutral=camera_look.neutral_axis(image), **kw)
    assert np.array_equal(measured_here.image, given.image)
    none = camera_look.NeutralAxis(np.array([128.0]), np.zeros((1, 3)), np.zeros(8, np.int64))
    without = render_insertion(image, K, depth, lights[0], cars[0], poses[0], neutral=none, **kw)
    assert not np.array_equal(without.image, given.image)  # the axis is used


def test_a_shadow_alone_is_composited_without_measuring_the_camera_look(monkeypatch):
    """An object off the image whose shadow reaches it has no pixel to blur, noise or tint: its blur, noise and
    neutral axis are not measured, and the composite has the bytes it had with them measured."""
    from streetaug.augment.render import composite as composite_module

    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    light = sunny_light(sun_dir_cam=(0.95, -0.3, 0.0))  # a low sun on the right: long shadows to the left
    image, depth, ev = ground_scene(light, K, W, H)
    car = procedural_car(7)
    T = pose_camera_to_transform(7.0, 1.5, 6.0, 90.0)  # off the image's right edge, its shadow in it
    kw = dict(quality="draft", ev=ev, seed=5, jpeg_quality=90)
    calls: list[str] = []

    def effects(img):
        calls.append("effects")
        return composite_module.estimate_camera_effects.__wrapped__(img)

    def measure(img, *a, **k):
        calls.append("neutral")
        return camera_look.neutral_axis(img, *a, **k)

    effects.__wrapped__ = composite_module.estimate_camera_effects
    monkeypatch.setattr(composite_module, "estimate_camera_effects", effects)
    monkeypatch.setattr(insert_module, "neutral_axis", measure)
    alone = render_insertion(image, K, depth, light, car, T, **kw)
    assert alone.coverage_px == 0 and alone.composited.box is not None
    assert (alone.shadow_ratio < 0.97).sum() > 1000  # its shadow is in the image
    assert calls == []
    assert not np.array_equal(alone.image, image)
    monkeypatch.setattr(composite_module, "object_drawn", lambda layers: True)  # measured as an object's would be
    measured = render_insertion(image, K, depth, light, car, T, **kw)
    assert calls == ["effects"]
    assert np.array_equal(alone.image, measured.image)
    assert np.array_equal(alone.shadow_ratio, measured.shadow_ratio)


def test_an_image_whose_objects_draw_no_pixel_is_not_measured(monkeypatch):
    """render_objects measures the neutral axis only once an object has a pixel to tint: a shadow alone (the
    object off the image) leaves it unmeasured, with the bytes it had when it was measured up front."""
    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    light = sunny_light(sun_dir_cam=(0.95, -0.3, 0.0))  # a low sun on the right: long shadows to the left
    image, depth, ev = ground_scene(light, K, W, H)
    T = pose_camera_to_transform(7.0, 1.5, 6.0, 90.0)  # off the image's right edge, its shadow in it
    options = InsertOptions(quality="draft", seed=0, ev=ev)
    calls: list[int] = []

    def measure(img, *a, **k):
        calls.append(1)
        return camera_look.neutral_axis(img, *a, **k)

    monkeypatch.setattr(objects_module, "neutral_axis", measure, raising=False)
    monkeypatch.setattr(insert_module, "neutral_axis", measure)
    out = render_objects(image, K, depth, [light], [procedural_car(7)], [T], [T[:3, 2]], options,
                         np.random.default_rng(0), {})
    assert out.objects[0].coverage_px == 0 and (out.shadow_ratio < 0.97).sum() > 1000  # a shadow alone
    assert calls == []
    given = render_insertion(image, K, depth, light, procedural_car(7), T, quality="draft", ev=ev,
                             seed=int(np.random.default_rng(0).integers(2**31)), neutral=camera_look.neutral_axis(image))
    assert np.array_equal(out.image, given.image)


def test_the_axis_measured_on_first_use_has_the_values_of_one_measured_up_front():
    image, *_ = _scene()
    lazy = objects_module._NeutralAxisOnFirstUse(image)
    assert not lazy.measured
    now = camera_look.neutral_axis(image)
    assert np.array_equal(lazy.offset_at(np.arange(256.0)), now.offset_at(np.arange(256.0)))
    assert lazy.measured and np.array_equal(lazy.levels, now.levels) and np.array_equal(lazy.n_px, now.n_px)
