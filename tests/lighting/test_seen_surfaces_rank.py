"""Ranked seen surfaces: an earlier keyframe's cameras (rank 1) fill only the rays the instant's own surfaces
(rank 0) leave open (augment/lighting/seen_surfaces.py); saved and loaded with their ranks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from streetaug.augment.lighting.seen_surfaces import SeenSurfaces
from test_seen_surfaces import CENTRE, H, W, fronto_view


def _layers() -> tuple[SeenSurfaces, SeenSurfaces]:
    """A far wall (10 m) over the left half of the instant's image, a near wall (5 m) over all of an earlier
    camera's image (same pose): ranked and unranked."""
    far = np.full((H, W), np.inf)
    far[:, : W // 2] = 10.0
    now = fronto_view(far)
    earlier = replace(fronto_view(np.full((H, W), 5.0), "CAM_FRONT@earlier"), rank=1)
    return SeenSurfaces.from_views([now, earlier]), SeenSurfaces.from_views([now, replace(earlier, rank=0)])


def _rays(y_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Rays from the camera's centre towards volume y = ``y_m`` (left +) at the camera's height, 20 m ahead."""
    d = np.array([[20.0, y_m, 0.0]])
    return CENTRE[None], d / np.linalg.norm(d, axis=1, keepdims=True)


def test_the_instant_surfaces_win_where_they_are_hit_even_behind_an_earlier_one():
    ranked, unranked = _layers()
    o, d = _rays(3.0)  # left: both walls
    _, t, _ = ranked.trace(o, d)
    assert abs(t[0] - 10.0 * np.linalg.norm(d[0]) / d[0, 0]) < 0.05  # the rank-0 wall at 10 m
    _, t_u, _ = unranked.trace(o, d)
    assert abs(t_u[0] - 5.0 / d[0, 0]) < 0.05  # unranked: the nearest (the earlier wall at 5 m)


def test_an_earlier_surface_fills_what_the_instant_left_open():
    ranked, _ = _layers()
    o, d = _rays(-3.0)  # right: only the earlier wall
    hit, t, _ = ranked.trace(o, d)
    assert hit[0] and abs(t[0] - 5.0 / d[0, 0]) < 0.05


def test_ranks_survive_save_and_load(tmp_path):
    ranked, _ = _layers()
    ranked.save(tmp_path / "seen.npz")
    back = SeenSurfaces.load(tmp_path / "seen.npz")
    assert back.rank.tolist() == [0, 1]
    o, d = _rays(3.0)
    assert np.allclose(back.trace(o, d)[1], ranked.trace(o, d)[1])


def test_an_earlier_keyframe_adds_rank_one_surfaces_that_leave_the_instant_views_unchanged():
    """The bundled sample given as its own previous keyframe: its cameras' surfaces come in again at rank 1
    (named ``@earlier``), and the input camera's predicted view, whose rays the rank-0 surfaces of the same
    poses already decide, does not change."""
    from streetaug.augment.lighting.api import earlier_keyframe, estimate_views_lighting
    from streetaug.augment.lighting.predicted_view import predicted_radiance
    from streetaug.datasets.bundled import bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(bundled_dataroot(), "v1.0-samples")
    s = reader.sample(reader.sample_tokens("sample-lowsun")[0])
    cams = ["CAM_FRONT", "CAM_BACK"]
    views = [s.cameras[c] for c in cams]
    alone = estimate_views_lighting(views, s.location, "L2", lidar=s.lidar, boxes=s.boxes)
    both = estimate_views_lighting(views, s.location, "L2", lidar=s.lidar, boxes=s.boxes,
                                   earlier=earlier_keyframe(s, cams))
    seen = both.hybrid.seen
    assert sorted(seen.channels) == sorted(cams + [f"{c}@earlier" for c in cams])
    assert [int(r) for r, c in zip(seen.rank, seen.channels) if c.endswith("@earlier")] == [1, 1]
    assert alone.hybrid.seen.rank.tolist() == [0, 0]
    a = predicted_radiance(alone, views[0], 96)
    b = predicted_radiance(both, views[0], 96)
    assert np.allclose(a, b, rtol=1e-4, atol=1e-6)


def test_an_earlier_surface_the_instant_saw_through_is_carved():
    """The instant's camera sees sky on its right half and a wall at 10 m on its left; an earlier camera (same
    pose) saw a surface at 5 m over its right half (moved away since, or sky taken for structure) and one at
    10 m / 20 m on its left (the same wall / behind it): only the right half is seen through, and carved."""
    from streetaug.augment.lighting.seen_surfaces import carved, seen_through

    now_depth = np.full((H, W), np.inf)
    now_depth[:, : W // 2] = 10.0
    now = fronto_view(now_depth)
    earlier_depth = np.full((H, W), 5.0)
    earlier_depth[: H // 2, : W // 2 - 3] = 10.0
    earlier_depth[H // 2 :, : W // 2 - 3] = 20.0
    earlier = fronto_view(earlier_depth, "CAM_FRONT@earlier")
    through = seen_through(earlier, [now])
    assert through[:, W // 2 + 3 :].all()  # in front of the instant's sky
    assert not through[:, : W // 2 - 3].any()  # the same wall, or hidden behind it
    cut = carved(earlier, [now])
    assert np.isinf(cut.depth_m[:, W // 2 + 3 :]).all() and np.isfinite(cut.depth_m[:, : W // 2 - 3]).all()
    # the ranked layer: a ray through the carved half finds nothing (the instant saw sky there)
    layer = SeenSurfaces.from_views([now, replace(cut, rank=1)])
    o, d = _rays(-3.0)
    assert not layer.trace(o, d)[0][0]
