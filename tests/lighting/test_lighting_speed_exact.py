"""The lighting's faster paths give the same numbers as the direct ones (issue #19): the height map's march,
its merged maps, the observation's radiance table, the box-shadow regions' windows, the seen mean colour; and
the work is done once (observe_view reuses the L1 fit's downscaled image; the volume and the dome share the
observations' LDR)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from streetaug.augment.core import clipped_to_lower_bound, ldr_uint8_to_hdr, make_transform
from streetaug.augment.lighting import evidence, fill, levels, multiview, observe
from streetaug.augment.lighting.evidence import _rasterise_ground, _rasterise_ground_window, prepare_image
from streetaug.augment.lighting.levels import HeightMap, _hemisphere_dirs
from streetaug.datasets.sample import CameraView


def _blocked_reference(hmap: HeightMap, pts: np.ndarray, d: np.ndarray, box_lo=None, box_hi=None,
                       max_dist_m: float = 300.0) -> np.ndarray:
    """The direct march: every point, direction and step of half a cell up to ``max_dist_m`` at once."""
    step = 0.5 * hmap.cell_m
    t = np.arange(1, int(max_dist_m / step) + 1) * step
    horiz = np.maximum(np.linalg.norm(d[:, :2], axis=1), 1e-6)
    pos = pts[:, None, None, :2] + (t[None, None, :, None] * (d[None, :, None, :2] / horiz[None, :, None, None]))
    z = pts[:, None, None, 2] + t[None, None, :] * (d[None, :, None, 2] / horiz[None, :, None])
    n = hmap.heights_m.shape[0]
    ij = np.floor((pos + hmap.half_extent_m) / hmap.cell_m).astype(np.int64)
    inside = ((ij >= 0) & (ij < n)).all(axis=-1)
    if box_lo is not None:
        inside &= ((pos >= box_lo[:2]) & (pos <= box_hi[:2])).all(axis=-1)
    ij = np.clip(ij, 0, n - 1)
    h = hmap.heights_m[ij[..., 0], ij[..., 1]]
    return (inside & (h > z) & (z < 200.0)).any(axis=-1)


@pytest.mark.parametrize("seed", range(6))
def test_height_map_march_equals_the_direct_march(seed):
    """Random structures (low, tall, a 250 m tower), points on and off the map, the auto judge's directions
    and random ones (also straight up and level): the shortened march and the direct one agree everywhere,
    for the whole map and within an L2 box."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(-140, 140, (2000, 3))
    src[:, 2] = rng.exponential(6.0 if seed % 2 else 25.0, len(src)) * (rng.random(len(src)) < 0.6)
    if seed == 3:
        src[0] = [20.0, 5.0, 250.0]
    hmap = HeightMap.from_points(src, half_extent_m=150.0)
    pts = rng.uniform(-100, 100, (int(rng.integers(5, 60)), 3))
    pts[:, 2] = rng.uniform(0.0, 3.0, len(pts))
    if seed % 3 == 0:
        pts[:2, :2] = [[-230.0, 10.0], [160.0, -170.0]]  # off the map: rays may enter it
    dirs = np.concatenate([_hemisphere_dirs()[0], rng.normal(size=(6, 3)), [[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]]])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    c = np.array([*rng.uniform(-50, 50, 2), 0.0])
    whole, within = hmap.blocked_whole_and_within(pts, dirs, c - 40.0, c + 40.0)
    ref_whole = _blocked_reference(hmap, pts, dirs)
    ref_within = _blocked_reference(hmap, pts, dirs, c - 40.0, c + 40.0)
    assert ref_whole.any() and not ref_whole.all()  # the case is not trivial
    np.testing.assert_array_equal(whole, ref_whole)
    np.testing.assert_array_equal(within, ref_within)
    np.testing.assert_array_equal(hmap.blocked(pts, dirs), ref_whole)
    np.testing.assert_array_equal(hmap.blocked(pts, dirs, c - 40.0, c + 40.0), ref_within)


def test_merged_height_maps_equal_the_map_of_all_points():
    rng = np.random.default_rng(1)
    a, b = rng.uniform(-160, 160, (3000, 3)), rng.uniform(-160, 160, (500, 3))
    a[:, 2], b[:, 2] = rng.uniform(-1, 30, 3000), rng.uniform(-1, 30, 500)
    both = HeightMap.from_points(np.concatenate([a, b]))
    merged = HeightMap.from_points(a).merged(HeightMap.from_points(b))
    np.testing.assert_array_equal(merged.heights_m, both.heights_m)
    with pytest.raises(ValueError, match="cells differ"):
        HeightMap.from_points(a).merged(HeightMap.from_points(b, cell_m=2.0))


@pytest.mark.parametrize("ratio", [1.0, 0.37, 2.9])
def test_clipped_radiance_table_equals_the_formula(ratio):
    rng = np.random.default_rng(2)
    small = rng.integers(0, 256, (40, 60, 3)).astype(np.uint8)
    small[:5] = 255
    small[5:8, :, 1] = 247
    level_max = small.max(axis=-1)
    direct = (clipped_to_lower_bound(ldr_uint8_to_hdr(small), small / 255.0) / ratio).astype(np.float32)
    np.testing.assert_array_equal(observe.clipped_radiance(small, level_max, ratio), direct)
    assert observe.first_level_at(0.97) == int(np.argmax(np.arange(256) / 255.0 >= 0.97))
    assert observe.first_level_at(1.5) == 256


def test_ground_window_mask_equals_the_whole_image_mask():
    """Shadows and rings (with holes; several parts; partly outside the image; behind the camera) rasterised in
    their window are the whole image's masks."""
    K = np.array([[200.0, 0.0, 240.0], [0.0, 200.0, 135.0], [0.0, 0.0, 1.0]])
    T_cam_from_global = np.eye(4)
    T_cam_from_global[:3, :3] = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]  # global x forward, z up
    T_cam_from_global[:3, 3] = [0.0, 1.5, 0.0]  # camera 1.5 m above z = 0
    shape = (270, 480)
    rng = np.random.default_rng(3)
    n_nonempty = 0
    for i in range(40):
        centre = rng.uniform([2.0, -25.0], [40.0, 25.0])
        shadow = shapely.Point(*centre).buffer(rng.uniform(0.5, 4.0)).convex_hull
        region = shadow.buffer(2.5).difference(shadow.buffer(0.7))  # a ring: a hole
        if i % 4 == 0:
            region = region.union(shapely.Point(*(centre + [6.0, 3.0])).buffer(1.0))
        if i % 7 == 0:
            region = shapely.Point(-1.0 + 2.0 * (i % 2), 0.0).buffer(3.0)  # near / behind the camera
        for poly in (shadow, region):
            whole = _rasterise_ground(poly, 0.0, T_cam_from_global, K, shape)
            mask, win = _rasterise_ground_window(poly, 0.0, T_cam_from_global, K, shape)
            out = np.zeros(shape, bool)
            out[win] = mask
            np.testing.assert_array_equal(out, whole)
            n_nonempty += int(whole.any())
    assert n_nonempty > 40


def test_mean_colour_of_ldr_parts_equals_the_mean_colour_of_all():
    rng = np.random.default_rng(4)
    parts = [rng.uniform(0.0, 3.0, (n, 3)).astype(np.float32) for n in (10, 0, 333, 7)]
    direct = fill.mean_colour_radiance(np.concatenate(parts))
    np.testing.assert_array_equal(fill.mean_colour_of_ldr([fill.clipped_ldr(p) for p in parts]), direct)
    np.testing.assert_array_equal(fill.mean_colour_of_ldr([]), np.zeros(3))


def _street_view() -> tuple[CameraView, np.ndarray]:
    W, H = 960, 540
    K = np.array([[500.0, 0.0, (W - 1) / 2], [0.0, 500.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    T_ego_from_cam = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [1.0, 0.0, 1.5])
    rng = np.random.default_rng(5)
    image = rng.integers(0, 256, (H, W, 3)).astype(np.uint8)
    image[:120] = 255  # a clipped sky
    view = CameraView("CAM_FRONT", "tok", "synthetic.png", K, W, H, T_ego_from_cam, np.eye(4), 0).with_image(image)
    x, y = np.meshgrid(np.linspace(3, 40, 60), np.linspace(-8, 8, 30))
    ground_ego = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    wall_ego = np.stack([np.full(400, 25.0), rng.uniform(-6, 6, 400), rng.uniform(0, 8, 400)], 1)
    pts_ego = np.concatenate([ground_ego, wall_ego])
    pts_cam = (pts_ego - T_ego_from_cam[:3, 3]) @ T_ego_from_cam[:3, :3]
    return view, pts_cam


def _count(monkeypatch, module, name: str) -> list:
    calls: list = []
    real = getattr(module, name)

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def test_observe_view_reuses_the_fits_downscaled_image(monkeypatch):
    """With the L1 fit's prepared image, observe_view downscales nothing again and densifies the LiDAR once;
    what it observes is the same as without the prepared image (which it then makes itself)."""
    view, pts_cam = _street_view()
    T_vol_from_cam = np.asarray(view.T_ego_from_cam)
    n_cam = T_vol_from_cam[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    ground = (n_cam, float(-n_cam @ (-T_vol_from_cam[:3, :3].T @ T_vol_from_cam[:3, 3])))
    up_cam = T_vol_from_cam[2, :3]
    work = prepare_image(np.asarray(view.image), view.K, up_cam, pts_cam)
    assert work.rgb_uint8 is not None and work.rgb_uint8.shape == work.ldr.shape
    alone = observe.observe_view(view, T_vol_from_cam, 1.3, pts_cam, ground)
    downscales = _count(monkeypatch, observe, "downscale_image")
    densified = _count(monkeypatch, observe, "densify_lidar_depth")
    reused = observe.observe_view(view, T_vol_from_cam, 1.3, pts_cam, ground, work=work)
    assert len(downscales) == 0, "the fit's downscaled image was made again"
    assert len(densified) == 1
    for field in ("points", "radiance", "view_dirs", "capped", "far_dirs", "far_radiance", "far_is_sky",
                  "far_saturated"):
        np.testing.assert_array_equal(getattr(reused, field), getattr(alone, field), err_msg=field)
    np.testing.assert_array_equal(reused.depth_view.radiance, alone.depth_view.radiance)
    assert alone.far_saturated.any() and (alone.radiance.max() > 0)


def test_an_estimate_downscales_and_densifies_each_camera_once(monkeypatch):
    """A two-camera L2 estimate (ephemeris sun, LiDAR): each image is downscaled once (by the L1 fit; the
    volume's observation reuses it) and each camera's LiDAR densified once. Main downscaled each image twice."""
    import datetime as dt

    from streetaug.augment.lighting.api import estimate_views_lighting
    from streetaug.datasets.sample import LidarSweep

    view, pts_cam = _street_view()
    noon = int(dt.datetime(2018, 7, 24, 4, 0, tzinfo=dt.timezone.utc).timestamp() * 1e6)
    T_global_from_ego = make_transform(np.eye(3), [300.0, 500.0, 0.0])
    T_ego_from_cam = np.asarray(view.T_ego_from_cam)
    views = []
    for channel, yaw in (("CAM_FRONT", 0.0), ("CAM_FRONT_LEFT", 55.0)):
        c, s = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
        R_yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        T = make_transform(R_yaw @ T_ego_from_cam[:3, :3], T_ego_from_cam[:3, 3])
        views.append(CameraView(channel, "tok", "synthetic.png", view.K, view.width, view.height, T,
                                T_global_from_ego, noon).with_image(np.asarray(view.image)))
    pts_ego = pts_cam @ T_ego_from_cam[:3, :3].T + T_ego_from_cam[:3, 3]
    lidar = LidarSweep(pts_ego, np.zeros(len(pts_ego), np.float32), np.eye(4), T_global_from_ego, noon)
    calls = {"fit": _count(monkeypatch, evidence, "downscale_image"),
             "observe": _count(monkeypatch, observe, "downscale_image"),
             "densify": _count(monkeypatch, observe, "densify_lidar_depth")}
    sl = estimate_views_lighting(views, "singapore-onenorth", "L2", lidar=lidar)
    assert sl.hybrid is not None and sl.level == "L2"
    assert len(calls["observe"]) == 0, "the volume's observation downscaled an image again"
    assert len(calls["fit"]) == len(views)
    assert len(calls["densify"]) == len(views)
