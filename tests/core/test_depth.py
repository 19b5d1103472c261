"""Depth from LiDAR (z-buffer + morphological completion) and the ground-plane prior."""

import numpy as np
import pytest

from streetaug.augment.core import intrinsics_from_fov, unproject_depth
from streetaug.augment.core.depth import densify_lidar_depth, ground_plane_depth, sparse_depth

W, H = 1600, 900
K = intrinsics_from_fov(W, H, 70.0)


def test_ground_plane_depth_points_lie_on_plane():
    n = np.array([0.0, -0.995, 0.0998])
    n /= np.linalg.norm(n)
    d = 1.6
    depth = ground_plane_depth(K, W, H, n, d)
    assert depth.shape == (H, W) and depth.dtype == np.float32
    assert np.all(np.isinf(depth[: int(K[1, 2]) - 150]))  # above the horizon (plane tilted up ahead)
    ys, xs = np.nonzero(np.isfinite(depth))
    sel = np.random.default_rng(0).choice(len(ys), 2000, replace=False)
    uv = np.stack([xs[sel], ys[sel]], 1).astype(float)
    p = unproject_depth(K, uv, depth[ys[sel], xs[sel]])
    np.testing.assert_allclose(p @ n + d, 0.0, atol=1e-3 * np.abs(p).max())


def _synthetic_lidar(rng):
    """Ground 1.7 m below the camera plus a 2 m wide box 8 m ahead, 32 scan rings."""
    pts = []
    for elev in np.radians(np.linspace(-25, 10, 32)):
        az = np.radians(np.arange(-60, 60, 0.2))
        dirs = np.stack([np.sin(az) * np.cos(elev), -np.sin(elev) * np.ones_like(az), np.cos(az) * np.cos(elev)], 1)
        t = np.full(len(az), np.inf)
        down = dirs[:, 1] > 1e-6
        t[down] = 1.7 / dirs[down, 1]
        # the box: front face z = 8, |x| < 1, y in (-0.3, 1.7)
        tb = 8.0 / dirs[:, 2]
        pb = dirs * tb[:, None]
        inbox = (np.abs(pb[:, 0]) < 1.0) & (pb[:, 1] > -0.3) & (pb[:, 1] < 1.7) & (tb < t)
        t[inbox] = tb[inbox]
        ok = np.isfinite(t) & (t < 80)
        pts.append(dirs[ok] * t[ok, None])
    return np.concatenate(pts) + rng.normal(0, 0.01, (1, 3))


def test_densify_fills_between_scan_lines_and_keeps_sky_empty():
    rng = np.random.default_rng(0)
    pts = _synthetic_lidar(rng)
    sparse = sparse_depth(pts, K, W, H)
    assert 0.002 < (sparse > 0).mean() < 0.1  # ~1.1 deg between rings: ~25 px gaps, as with nuScenes' 32 beams
    dense = densify_lidar_depth(pts, K, W, H)  # its time: the depth stage of bench_insert_time / bench_batch --profile
    assert dense.shape == (H, W) and dense.dtype == np.float32
    # the box front face: depth 8 m at its centre pixel
    u = int(K[0, 2])
    v_box = int(K[1, 2] + K[1, 1] * 0.7 / 8.0)
    assert abs(dense[v_box, u] - 8.0) < 0.2
    # ground below the box, a few rows above the image bottom: true depth from the plane
    truth = ground_plane_depth(K, W, H, np.array([0, -1.0, 0]), 1.7)
    rows = slice(H - 120, H - 20)
    cols = slice(100, 400)
    err = np.abs(dense[rows, cols] - truth[rows, cols]) / truth[rows, cols]
    assert np.median(err) < 0.03
    # sky above the box and above the highest ring: unknown
    assert np.all(np.isinf(dense[:50]))
    # the nearer box wins at its edges (inverse-depth dilation): no ground depth leaks into it
    assert np.all(dense[v_box - 5 : v_box + 5, u - 20 : u + 20] < 8.3)


def test_densify_ground_fill_and_empty_input():
    empty = densify_lidar_depth(np.zeros((0, 3)), K, W, H)
    assert np.all(np.isinf(empty))
    filled = densify_lidar_depth(np.zeros((0, 3)), K, W, H, ground_fill=(np.array([0, -1.0, 0]), 1.5))
    np.testing.assert_allclose(filled, ground_plane_depth(K, W, H, np.array([0, -1.0, 0]), 1.5))


def test_sparse_depth_keeps_nearest():
    pts = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 5.0], [0.0, 0.0, 7.0]])
    d = sparse_depth(pts, K, W, H)
    assert d[int(round(K[1, 2])), int(round(K[0, 2]))] == pytest.approx(5.0)
    assert (d > 0).sum() == 1


def test_far_ground_between_scan_lines_does_not_hide_what_stands_on_it():
    """32-beam rings ~1.33 deg apart meet a flat road 1.7 m below the camera 30-50 m ahead tens of pixels apart.
    A virtual object standing at 45 m must see the road in front of it as farther than itself along every ray
    through its image (that road lies behind its foot): growing the nearer ring upwards made it 30 m away and
    hid the object's lower half."""
    K_ = np.array([[1266.0, 0, 800], [0, 1266.0, 450], [0, 0, 1]])
    W_, H_ = 1600, 900
    elev = np.radians(np.arange(-30.0, 10.0, 1.33))
    az = np.radians(np.linspace(-40, 40, 2400))
    e, a = np.meshgrid(elev, az, indexing="ij")
    dirs = np.stack([np.cos(e) * np.sin(a), -np.sin(e), np.cos(e) * np.cos(a)], -1).reshape(-1, 3)  # camera frame
    down = dirs[:, 1] > 1e-6
    t = 1.7 / dirs[down, 1]
    pts = (dirs[down] * t[:, None])[t < 120]
    dense = densify_lidar_depth(pts, K_, W_, H_, ground_fill=(np.array([0.0, -1.0, 0.0]), 1.7))
    # the object's image: 45 m ahead, bottom on the road (y = 1.7), 1.5 m tall
    v_foot, v_top = 450 + 1266 * 1.7 / 45, 450 + 1266 * 0.2 / 45
    rows = np.arange(int(np.ceil(v_top)), int(np.floor(v_foot)))
    assert len(rows) >= 30
    assert np.all(dense[rows, 790:811] >= 45.0 * 0.98), dense[rows, 800].min()
    # and the road itself stays right where LiDAR saw it (1/z of a plane is affine in the row)
    truth = ground_plane_depth(K_, W_, H_, np.array([0.0, -1.0, 0.0]), 1.7)
    band = slice(int(v_foot) + 2, H_ - 5)
    err = np.abs(dense[band, 700:900] - truth[band, 700:900]) / truth[band, 700:900]
    assert np.median(err) < 0.01


def test_ground_seen_past_an_obstacle_does_not_punch_through_it():
    """The LiDAR sits above the camera: it sees road behind a car that projects between the car's own scan lines
    in the image. The ground is only joined between scan lines with no obstacle between them."""
    K_ = np.array([[1266.0, 0, 800], [0, 1266.0, 450], [0, 0, 1]])
    W_, H_ = 1600, 900
    u = np.linspace(-1.0, 1.0, 200)
    car = np.stack(np.meshgrid(u, np.arange(0.2, 1.7, 0.2)), -1).reshape(-1, 2)  # a car's back, rows 20 cm apart
    car = np.c_[car[:, 0], 1.7 - car[:, 1], np.full(len(car), 10.0)]  # camera frame: y down, 10 m ahead
    t = np.linspace(15.0, 30.0, 12)  # road behind it, projecting between the car's scan lines
    road = np.stack(np.meshgrid(u * 1.5, t), -1).reshape(-1, 2)
    road = np.c_[road[:, 0] * road[:, 1] / 10, np.full(len(road), 1.7), road[:, 1]]
    dense = densify_lidar_depth(np.concatenate([car, road]), K_, W_, H_,
                                ground_fill=(np.array([0.0, -1.0, 0.0]), 1.7))
    rows = slice(int(450 + 1266 * 0.2 / 10) + 3, int(450 + 1266 * 1.5 / 10) - 3)
    cols = slice(800 - 80, 800 + 80)
    assert np.all(dense[rows, cols] < 10.5), np.max(dense[rows, cols])
