"""Camera samples follow what a pixel needs: a shading gradient the pixels resolve gets no extra samples (more
samples of a ramp average to its centre value), a step (shadow edge, reflected horizon) still does."""

import numpy as np

import streetaug.augment.render.foreground as foreground

W, H = 40, 30


def _traced(log_lum: np.ndarray) -> foreground.PixelSums:
    """One camera sample per pixel of a fully covered, one-material patch whose smooth radiance is exp(log_lum)."""
    P = W * H
    pixel = np.arange(P)
    rad = np.zeros((P, 6))
    rad[:, :3] = np.exp(log_lum.ravel())[:, None]
    sums = foreground.PixelSums.empty(P, np.array([0.0, 0.0, 1.0]))
    sums.add_first_hits(pixel, np.full(P, 10.0), np.tile([0.0, 0.0, -1.0], (P, 1)), pixel)
    sums.normal[:] = [0.0, 0.0, 1.0]
    sums.material[:] = 0
    sums.add_shading(pixel, rad, np.ones(P), residual=True)
    return sums


def test_a_resolved_shading_ramp_gets_no_inner_samples():
    ys, xs = np.mgrid[0:H, 0:W]
    ramp = -2.0 + 0.12 * xs + 0.05 * ys  # 12 % per pixel: the 3 x 3 range (0.24 + 0.10) exceeded the 15 % rule
    sil, inner = foreground._refine_masks(_traced(ramp), W, H, 1)
    assert not sil[2:-2, 2:-2].any()
    assert inner.sum() == 0  # old rule: every pixel of the patch


def test_a_shading_step_still_gets_inner_samples_on_both_sides():
    ys, xs = np.mgrid[0:H, 0:W]
    step = np.where(xs >= 20, -1.0, -2.0) + 0.01 * ys
    _, inner = foreground._refine_masks(_traced(step), W, H, 1)
    assert inner[:, 19].all() and inner[:, 20].all()
    assert inner.sum() == 2 * H  # nowhere else


def test_unresolved_shading_is_the_largest_second_difference():
    L = np.zeros((5, 5), np.float32)
    L[2, 2] = 1.0  # a spike: second difference 2 at it, 1 at its 8 neighbours
    u = foreground.unresolved_shading(L)
    assert u[2, 2] == 2.0 and np.all(u[1:4, 1:4][np.arange(9).reshape(3, 3) != 4] == 1.0)
    assert u[0, 0] == 0.0


def test_edge_samples_carry_the_residual_one_per_row_and_column():
    """A sub-pixel sample needs a share of the light samples: k of the k x k edge strata trace the residual."""
    for k in (2, 3, 4, 6):
        m = foreground.residual_strata(k).reshape(k, k)
        assert m.sum() == k and np.all(m.sum(axis=0) == 1) and np.all(m.sum(axis=1) == 1)


def test_silhouette_pixels_trace_k_residual_samples_not_k_squared():
    """Without a sun every shadow ray of the shading is a residual (environment / BRDF) sample: going from 2 x 2 to
    4 x 4 silhouette samples adds 12 camera samples per silhouette pixel but only 2 residual samples (old: 12)."""
    from render_fixtures import primitive_car, sunny_light
    from streetaug.augment.core import intrinsics_from_fov, pose_camera_to_transform
    from streetaug.augment.core.depth import ground_plane_depth
    from streetaug.augment.lighting.light import DistantLight
    from streetaug.augment.render import RenderSettings, render_insertion

    W_, H_ = 320, 180
    K = intrinsics_from_fov(W_, H_, 60.0)
    depth = ground_plane_depth(K, W_, H_, np.array([0.0, -1.0, 0.0]), 1.5)
    T = pose_camera_to_transform(0.0, 1.5, 12.0, 30.0)
    image = np.full((H_, W_, 3), 120, np.uint8)
    light = DistantLight(sunny_light().envmap, None)
    got = {}
    for k in (2, 4):
        ins = render_insertion(image, K, depth, light, primitive_car(), T, quality=RenderSettings(edge_grid=k, match_camera=False))
        got[k] = (ins.stats["foreground"]["edge_samples"], ins.stats["rays"].get("shade_visibility", 0))
    (e2, v2), (e4, v4) = got[2], got[4]
    assert e4 - e2 > 1000
    assert (v4 - v2) < 0.12 * (e4 - e2)  # old: ~ the share of edge samples that hit (0.3 - 0.5)
