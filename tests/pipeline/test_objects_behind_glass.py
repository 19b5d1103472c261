"""Inserted objects occlude each other in the labels as in the image: rendered nearest first, a car behind a
nearer inserted car is hidden by it (the nearer car's see-through glass counts as the car), whatever the
order the objects are given in."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.pipeline import InsertOptions
from streetaug.augment.pipeline import objects as objects_module
from streetaug.augment.pipeline.objects import render_objects
from streetaug.augment.render import render_insertion

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from render_fixtures import ground_scene, sunny_light  # noqa: E402


def test_a_car_behind_a_nearer_inserted_car_is_hidden_in_its_labels(monkeypatch):
    W, H = 320, 180
    K = intrinsics_from_fov(W, H, 60.0)
    light = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58))
    image, depth, ev = ground_scene(light, K, W, H)
    near, far = procedural_car(4), procedural_car(11)
    T_near = pose_camera_to_transform(1.5, 1.5, 9.0, 120.0)
    T_far = pose_camera_to_transform(1.5 * 16.0 / 9.0, 1.5, 16.0, 120.0)  # right behind it
    options = InsertOptions(quality="default", seed=0, ev=ev)
    # the far car first in the list: it must still be drawn after (behind) the near one
    alphas = []  # the renderer's composited alpha of each object, in render order (not kept by render_objects)

    def spy(*args, **kwargs):
        ins = render_insertion(*args, **kwargs)
        alphas.append(ins.alpha)
        return ins

    monkeypatch.setattr(objects_module, "render_insertion", spy)
    out = render_objects(image, K, depth, [light, light], [far, near], [T_far, T_near], [T_far[:3, 2], T_near[:3, 2]],
                         options, np.random.default_rng(0), {})
    b, a = out.objects  # given order kept: far, near
    assert out.objects[0].asset is far
    assert b.visible_px / b.coverage_px < 0.5  # mostly hidden by the near car: its label says so
    assert a.visible_px / a.coverage_px > 0.95
    seen_through = (a.full_mask() > 0.95) & (alphas[0] < 0.8)  # the near car's windows let the background through
    assert seen_through.sum() > 20
    assert b.full_mask()[seen_through].mean() < 0.02  # ... but not the car behind them
    # the same objects in the other order give the same picture and labels
    again = render_objects(image, K, depth, [light, light], [near, far], [T_near, T_far], [T_near[:3, 2], T_far[:3, 2]],
                           options, np.random.default_rng(0), {})
    assert abs(again.objects[1].visible_px - b.visible_px) < 0.02 * b.coverage_px
