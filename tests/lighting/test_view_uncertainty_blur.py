"""A view from a new centre is the expected view: each pixel blurred by how uncertain the place of what it shows
is (augment/lighting/predicted_view.py uncertainty_blurred, seen_surfaces.trace_spread), with the seen surfaces'
depth uncertainty per pixel (observe.depth_uncertainty_map: small on LiDAR returns, the old constant where the
depth is extrapolated). On the real dev scene the six-view forward view (the paper's protocol) gains from it and
the self view is unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import SHARED_DATA
from streetaug.augment.lighting import observe as ob
from streetaug.augment.lighting import seen_surfaces as ss
from streetaug.augment.lighting.predicted_view import uncertainty_blurred
from streetaug.augment.lighting.seen_surfaces import DepthView, SeenSurfaces

from lighting_rig import CENTRE, H, K, T_VOL_FROM_CAM, W  # noqa: E402
SEQ = SHARED_DATA / "nuscenes-seq"


def wall(uncertainty: np.ndarray | None = None) -> SeenSurfaces:
    """A wall 10 m ahead of the camera, a checker texture, the given per-pixel depth uncertainty."""
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    tex = (((u // 4) + (v // 4)) % 2).astype(np.float32)[..., None] * np.ones(3, np.float32)
    return SeenSurfaces.from_views([DepthView("CAM_FRONT", np.full((H, W), 10.0, np.float32), tex, K,
                                              T_VOL_FROM_CAM, depth_uncertainty=uncertainty)])


def rays_to(origin: np.ndarray, n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    y, z = np.meshgrid(np.linspace(-2, 2, n), np.linspace(0.5, 2.5, 5))
    targets = np.stack([np.full(y.size, 10.0), y.ravel(), z.ravel()], axis=1)
    d = targets - origin
    return np.repeat(origin[None], len(d), axis=0), d / np.linalg.norm(d, axis=1, keepdims=True)


class TestTraceSpread:
    def test_zero_from_the_cameras_own_centre(self):
        hit, t, rgb, spread = wall().trace_spread(*rays_to(CENTRE))
        assert hit.all() and np.all(spread == 0.0)

    def test_grows_with_the_baseline_and_follows_the_pixel_uncertainty(self):
        o1 = CENTRE + np.array([0.0, 1.0, 0.0])
        o2 = CENTRE + np.array([0.0, 2.0, 0.0])
        _, t1, _, s1 = wall().trace_spread(*rays_to(o1))
        _, _, _, s2 = wall().trace_spread(*rays_to(o2))
        assert np.all(s1 > 0) and np.median(s2 / s1) == pytest.approx(2.0, rel=0.1)
        # the constant uncertainty: relative error x baseline across the ray / t
        assert np.median(s1 * t1) == pytest.approx(ss.DEPTH_UNCERTAINTY * 1.0, rel=0.15)
        _, _, _, sharp = wall(np.full((H, W), 0.01, np.float32)).trace_spread(*rays_to(o1))
        assert np.median(sharp / s1) == pytest.approx(0.01 / ss.DEPTH_UNCERTAINTY, rel=0.05)

    def test_trace_is_trace_spread_without_the_spread(self):
        a = wall().trace(*rays_to(CENTRE + np.array([0.5, 1.0, 0.3])))
        b = wall().trace_spread(*rays_to(CENTRE + np.array([0.5, 1.0, 0.3])))[:3]
        for x, y in zip(a, b):
            assert np.array_equal(x, y)

    def test_vertex_uncertainty_round_trip(self, tmp_path):
        layer = wall(np.linspace(0.01, 0.1, H * W, dtype=np.float32).reshape(H, W))
        layer.save(tmp_path / "s.npz")
        back = SeenSurfaces.load(tmp_path / "s.npz")
        assert np.allclose(back.vertex_uncertainty, layer.vertex_uncertainty, atol=1e-4)


class TestDepthUncertaintyMap:
    def test_small_on_returns_the_constant_away_and_where_extrapolated(self):
        measured = np.full((40, 60), 10.0, np.float32)
        measured[:10] = np.inf  # above the LiDAR: the mesh's depth there is extrapolated
        returns = np.array([[30.0, 20.0], [31.0, 20.0]])
        m = ob.depth_uncertainty_map(measured, returns)
        assert m[20, 30] == pytest.approx(ob.DEPTH_AT_RETURN)
        assert ob.DEPTH_AT_RETURN < m[20, 36] < ss.DEPTH_UNCERTAINTY  # 5 px from a return: in between
        assert m[20, 5] == pytest.approx(ss.DEPTH_UNCERTAINTY)
        assert np.all(m[:10] == ss.DEPTH_UNCERTAINTY)
        assert np.all(ob.depth_uncertainty_map(measured, None) == ss.DEPTH_UNCERTAINTY)


class TestUncertaintyBlurred:
    def test_identity_without_uncertainty(self):
        img = np.random.default_rng(0).random((30, 40, 3)).astype(np.float32)
        assert np.array_equal(uncertainty_blurred(img, np.zeros((30, 40))), img)

    def test_blurs_where_uncertain_and_reaches_across_a_silhouette(self):
        img = np.zeros((40, 80, 3), np.float32)
        img[:, 40:] = 1.0  # a sharp outline: a canopy (right) against the sky (left)
        sigma = np.zeros((40, 80), np.float32)
        sigma[:, 40:] = 4.0  # only the canopy's place is uncertain
        out = uncertainty_blurred(img, sigma, smooth_px=4.0)
        assert 0.02 < out[20, 38, 0] < 0.5 < out[20, 41, 0] < 0.98  # both sides of the outline soften
        assert out[20, 5, 0] == pytest.approx(0.0, abs=1e-6) and out[20, 75, 0] == pytest.approx(1.0, abs=1e-3)
        assert out.sum() == pytest.approx(img.sum(), rel=0.02)  # a blur keeps the energy


@pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file(), reason=f"real dev scene not found at {SEQ}")
def test_real_six_view_forward_gains_and_self_view_is_unchanged():
    """Scene-0916 keyframe 20 (held out when the constants were chosen): lighting from the 6 cameras at t,
    CAM_FRONT at t + 3 at the new centre. Before: 16.15 dB (the sharp guess); after ~16.7. An input camera's own
    view (the map at CAM_FRONT's own centre) is not blurred."""
    from streetaug.augment.evaluation.novel_view import real_view, view_scores
    from streetaug.augment.lighting import predicted_view as pv
    from streetaug.augment.lighting.api import estimate_views_lighting
    from streetaug.augment.lighting.predicted_view import auto_exposed, predicted_radiance
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens("scene-0916")
    src, tgt = reader.sample(tokens[20]), reader.sample(tokens[23])
    views = [src.cameras[c] for c in ("CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK",
                                      "CAM_BACK_LEFT", "CAM_BACK_RIGHT")]
    sl = estimate_views_lighting(views, src.location, "L2", lidar=src.lidar, boxes=src.boxes)
    target = tgt.cameras["CAM_FRONT"]
    pred = auto_exposed(sl, target, predicted_radiance(replace(sl, input_mean_ldr={}), target))
    assert view_scores(pred, real_view(target))["psnr"] > 16.45
    own = predicted_radiance(sl, src.cameras["CAM_FRONT"])
    scale = pv.SPREAD_SCALE
    try:
        pv.SPREAD_SCALE = 0.0
        sharp = predicted_radiance(sl, src.cameras["CAM_FRONT"])
    finally:
        pv.SPREAD_SCALE = scale
    assert np.array_equal(own, sharp)


def test_equirect_blur_wraps_across_the_seam_and_leaves_certain_pixels():
    from streetaug.augment.lighting.view_blur import uncertainty_blurred_equirect

    h, w = 32, 64
    env = np.zeros((h, w, 3), np.float32)
    env[:, 0] = 1.0  # a bright line at longitude 0, next to the seam
    assert uncertainty_blurred_equirect(env, np.zeros((h, w))) is env  # nothing uncertain: the map itself
    spread = np.full((h, w), 0.05, np.float32)
    out = uncertainty_blurred_equirect(env, spread)
    # blurred symmetrically across the seam: the last column gets as much as the second one
    assert out[h // 2, 1, 0] > 0.05
    assert out[h // 2, -1, 0] == pytest.approx(out[h // 2, 1, 0], rel=1e-3)
    assert out[h // 2, 0, 0] < 0.9
    assert out.sum() == pytest.approx(env.sum(), rel=0.02)  # energy kept
