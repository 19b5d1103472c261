"""The foreground traces its camera rays in chunks: the same render as one unchunked pass, in bounded memory."""

import tracemalloc

import numpy as np
import pytest

import streetaug.augment.render.foreground as foreground
import streetaug.augment.render.shade as shade
from render_fixtures import primitive_car, sunny_light
from streetaug.augment.core import PinholeCamera, intrinsics_from_fov, pose_camera_to_transform
from streetaug.augment.render import RenderSettings, footprint, prepare_asset
from streetaug.augment.render.bounce import BounceLight
from streetaug.augment.render.shade import ShadingContext

W, H = 480, 270
CAMERA = PinholeCamera(intrinsics_from_fov(W, H, 60.0), W, H)
UP = np.array([0.0, -1.0, 0.0])


def _render(distance_m: float = 6.0, seed: int = 3) -> foreground.Foreground:
    """The glass-cabin primitive car ``distance_m`` ahead (its box ~ a third of the frame at 6 m)."""
    light, car = sunny_light(), primitive_car()
    T = pose_camera_to_transform(0.3, 1.5, distance_m, 35.0)
    settings = RenderSettings()
    prep = prepare_asset(car)
    bounce = BounceLight.build(light, prep, T, UP)
    ctx = ShadingContext.for_object(prep, light, bounce.env, T, settings, np.random.default_rng(seed),
                                    np.full(3, 0.05), np.full(3, 0.02), bounce)
    return foreground.render_foreground(CAMERA, footprint(CAMERA, car, T, light, settings).object_box, ctx, T)


def _fields(fg: foreground.Foreground) -> dict[str, np.ndarray]:
    return {"radiance": fg.radiance_premult, "alpha": fg.alpha, "depth": fg.depth_m, "solid": fg.solid}


@pytest.mark.parametrize("chunk", [997, 1500])
def test_chunked_render_is_the_unchunked_render(monkeypatch, chunk):
    monkeypatch.setattr(foreground, "TRACE_CHUNK_RAYS", 10**9)
    whole = _render()
    assert whole.stats["pixels"] > 20 * chunk  # many chunks, glass (depth > 1) in several of them
    assert whole.stats["rays"]["glass"] > 1000
    monkeypatch.setattr(foreground, "TRACE_CHUNK_RAYS", chunk)
    chunked = _render()
    assert chunked.box == whole.box
    assert chunked.stats["rays"] == whole.stats["rays"]
    for name, a in _fields(whole).items():
        b = _fields(chunked)[name]
        # the same random numbers in the same order: the same image but for float rounding of per-pixel sums
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-7, err_msg=name)
    assert np.isfinite(whole.depth_m).sum() > 0.5 * whole.depth_m.size


def test_chunks_that_split_the_shading_batches_change_nothing(monkeypatch):
    """Chunks of camera rays do not line up with the shading batches: the queue keeps the batches."""
    monkeypatch.setattr(shade, "SHADE_CHUNK_RAYS", 40_000)  # 10k points per shading batch, chunks of 3001 rays
    monkeypatch.setattr(foreground, "TRACE_CHUNK_RAYS", 10**9)
    whole = _render()
    monkeypatch.setattr(foreground, "TRACE_CHUNK_RAYS", 3001)
    chunked = _render()
    np.testing.assert_allclose(chunked.radiance_premult, whole.radiance_premult, rtol=1e-6, atol=1e-7)
    other_seed = _render(seed=4)  # a different random stream does differ (the comparison can fail)
    assert np.abs(other_seed.radiance_premult - whole.radiance_premult).max() > 1e-3


def _peak_mb(monkeypatch, chunk: int) -> float:
    monkeypatch.setattr(foreground, "TRACE_CHUNK_RAYS", chunk)
    _render(distance_m=4.5)  # warm caches (prepared asset, tables) outside the measurement
    tracemalloc.start()
    try:
        _render(distance_m=4.5)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def test_chunks_bound_the_foreground_memory(monkeypatch):
    monkeypatch.setattr(shade, "SHADE_CHUNK_RAYS", 20_000)  # the shading batch small: what is left is the trace's
    unchunked, chunked = _peak_mb(monkeypatch, 10**9), _peak_mb(monkeypatch, 2048)
    assert chunked < 0.6 * unchunked, (chunked, unchunked)


def test_shadow_sky_batches_change_nothing(monkeypatch):
    """The shadow's sky test is batched by ``shadow.SHADOW_CHUNK_RAYS`` (memory, issue #19): each ground point's
    directions are drawn in order, so any batch size gives the same shadow and composite, byte for byte."""
    import streetaug.augment.render.shadow as shadow
    from render_fixtures import ground_scene
    from streetaug.augment.render import render_insertion

    light, car = sunny_light(sun_dir_cam=(0.6, -0.55, 0.58)), primitive_car()
    image, depth, ev = ground_scene(light, CAMERA.K, W, H)
    T = pose_camera_to_transform(0.3, 1.5, 9.0, 35.0)
    a = render_insertion(image, CAMERA.K, depth, light, car, T, ev=ev, seed=2, quality="draft")
    monkeypatch.setattr(shadow, "SHADOW_CHUNK_RAYS", 3001)
    b = render_insertion(image, CAMERA.K, depth, light, car, T, ev=ev, seed=2, quality="draft")
    assert (a.shadow_ratio_rgb < 0.9).sum() > 100  # a real shadow, many batches of 3001 rays
    assert a.stats["rays"]["shadow_sky"] > 10 * 3001
    assert a.shadow_ratio_rgb.tobytes() == b.shadow_ratio_rgb.tobytes()
    assert a.image.tobytes() == b.image.tobytes()
