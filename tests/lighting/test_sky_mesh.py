"""The cameras' sky pixels in the seen-surface layer at (practically) infinity (augment/lighting/seen_surfaces.py:
``DepthView.sky``, ``SKY_MESH_RANGE_M``): sky seen at one centre is reproduced from another, sharp and without
parallax, wherever no nearer seen surface stands in the way."""

from __future__ import annotations

import numpy as np

from streetaug.augment.lighting import seen_surfaces as ss
from streetaug.augment.lighting.seen_surfaces import DepthView, SeenSurfaces, depth_mesh
from streetaug.augment.lighting.volume import HybridLighting, LogGrid, empty_params

from lighting_rig import CENTRE, F, H, K, R_VOL_FROM_CAM, T_VOL_FROM_CAM, W  # noqa: E402
WALL_M = 20.0  # a wall this far ahead fills the image's lower half; sky above it
GREY_DOME = 0.05


def sky_texture(d_vol: np.ndarray) -> np.ndarray:
    """Radiance (..., 3) of the sky along unit volume-frame directions (..., 3): waves over azimuth (period 20
    deg, ~21 px) and a gradient over elevation, so that a misplaced sky is far off."""
    az = np.arctan2(d_vol[..., 1], d_vol[..., 0])
    stripes = 0.5 + 0.45 * np.sin(18.0 * az)
    return np.stack([stripes, 0.6 + 0.3 * d_vol[..., 2], np.full_like(az, 0.9)], axis=-1).astype(np.float32)


def pixel_dirs() -> np.ndarray:
    """(H, W, 3) unit volume-frame rays of the test camera's pixel centres."""
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rays = np.stack([(u - K[0, 2]) / F, (v - K[1, 2]) / F, np.ones_like(u)], axis=-1) @ R_VOL_FROM_CAM.T
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def scene(with_sky: bool) -> DepthView:
    """The camera's view: a grey wall ``WALL_M`` ahead below the image's middle row, sky (inf depth) above."""
    sky = np.zeros((H, W), bool)
    sky[: H // 2 - 2] = True
    depth = np.where(sky, np.inf, WALL_M).astype(np.float32)
    rad = np.where(sky[..., None], sky_texture(pixel_dirs()), 0.2).astype(np.float32)
    return DepthView("CAM_FRONT", depth, rad, K, T_VOL_FROM_CAM, sky=sky if with_sky else None)


def moved_rays(forward_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays from ``forward_m`` ahead of the camera into the directions the camera saw as sky, away from the sky's
    edge (elevations 15..25 deg, azimuths -25..25 deg): (origins, dirs, the sky's radiance there)."""
    az, el = np.meshgrid(np.radians(np.linspace(-25, 25, 41)), np.radians(np.linspace(15, 25, 9)))
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1).reshape(-1, 3)
    o = np.repeat((CENTRE + np.array([forward_m, 0.0, 0.0]))[None], len(d), axis=0)
    return o, d, sky_texture(d)


def hybrid(view: DepthView) -> HybridLighting:
    grid = LogGrid(shape=(32, 32, 12), half_extent_xy_m=60.0, z_min_m=-2.0, z_max_m=30.0)
    dome = np.full((16, 32, 3), GREY_DOME, np.float32)
    return HybridLighting(dome, None, None, grid=grid, params=empty_params(grid, as_tensor=False),
                          seen=SeenSurfaces.from_views([view]))


def test_sky_seen_at_one_centre_is_reproduced_from_another():
    """8 m ahead of the camera (a later keyframe's centre), the sky it saw comes back within 0.03 of its
    pixels' radiance at the same directions: no parallax at infinity, no blur (the reprojection uncertainty
    of a surface 10 km away is nil). Without the sky mesh those rays fall through to the dome (0.05 grey)."""
    o, d, truth = moved_rays(8.0)
    new = np.asarray(hybrid(scene(with_sky=True)).radiance(o, d, include_sun=False))
    old = np.asarray(hybrid(scene(with_sky=False)).radiance(o, d, include_sun=False))
    assert np.abs(new - truth).max() < 0.03, np.abs(new - truth).max()
    assert np.abs(old - truth).max(axis=1).min() > 0.3  # the old behaviour: the dome's grey
    _, spread = hybrid(scene(with_sky=True)).radiance_spread(o, d, include_sun=False)
    assert spread.max() < 1e-4  # radians: no view blur on the sky


def test_nearer_seen_surfaces_still_cover_the_sky():
    """The wall in front of the sky is hit first, from the camera's centre and from a point ahead: a ray just
    below the sky's edge from the camera shows the wall's grey, not the sky behind it."""
    layer = SeenSurfaces.from_views([scene(with_sky=True)])
    d = pixel_dirs()[H // 2 + 4 : H - 4 : 5, 4 : W - 4 : 5].reshape(-1, 3)  # wall pixels, off the mesh's border
    for forward_m in (0.0, 5.0):
        o = np.repeat((CENTRE + np.array([forward_m, 0.0, 0.0]))[None], len(d), axis=0)
        hit, t, rgb = layer.trace(o, d)
        assert hit.all()
        assert t.max() < 2 * WALL_M  # the wall, not the sky sphere
        assert np.allclose(rgb, 0.2, atol=1e-3)


def test_sky_depth_is_the_sphere_and_skips_seen_surfaces():
    """The sky's camera-z depth puts every sky pixel at ``SKY_MESH_RANGE_M`` from the centre; a pixel with a
    finite depth is never sky, and a view without a sky mask has no sky mesh."""
    from streetaug.augment.lighting.seen_surfaces import sky_depth

    view = scene(with_sky=True)
    z = sky_depth(view)
    d_cam = pixel_dirs() @ R_VOL_FROM_CAM  # back into the camera frame
    rng = z / d_cam[..., 2]
    assert np.allclose(rng[view.sky], ss.SKY_MESH_RANGE_M, rtol=1e-6)
    assert np.isinf(z[~view.sky]).all()
    both = DepthView(view.channel, np.full((H, W), 15.0, np.float32), view.radiance, K, T_VOL_FROM_CAM, sky=view.sky)
    assert np.isinf(sky_depth(both)).all()
    v_sky, f_sky, _ = depth_mesh(view)
    v_old, f_old, _ = depth_mesh(scene(with_sky=False))
    assert len(f_sky) > len(f_old) > 0
    far = np.linalg.norm(v_sky - CENTRE, axis=1) > 0.99 * ss.SKY_MESH_RANGE_M
    assert far.sum() == len(v_sky) - len(v_old)


def test_the_sky_mesh_over_its_rows_equals_the_whole_image_grid():
    """Meshing only the rows that hold sky (from a multiple of the step) gives the whole image's grid mesh of
    the sky: the same vertices, faces, pixel coordinates."""
    from streetaug.augment.lighting.seen_surfaces import _grid_mesh, _sky_mesh, sky_depth

    view = scene(with_sky=True)
    sky = np.zeros((H, W), bool)
    sky[7:20, 10:60] = True  # starts off the step's grid
    view = DepthView(view.channel, np.where(sky, np.inf, WALL_M).astype(np.float32), view.radiance, K,
                     T_VOL_FROM_CAM, sky=sky)
    part = _sky_mesh(view, ss.GEOMETRY_STEP_PX)
    whole = _grid_mesh(view, sky_depth(view), ss.GEOMETRY_STEP_PX, None, max_depth_m=np.inf)
    assert len(part[1]) > 0
    for a, b in zip(part, whole):
        assert a.shape == b.shape and np.allclose(a, b)


def test_a_structure_only_the_volume_holds_stands_in_front_of_the_sky_seen_from_far_across():
    """12 m to the side of the camera (farther across the ray than ``SKY_PREEMPT_BASELINE_M``), a ray along a
    direction the camera saw as sky crosses an opaque block that only the volume holds (LiDAR / prior occupancy
    the camera did not see): it shows the block, not the sky pixel (the sky mesh was always in front before).
    From the camera's own centre the same direction shows the sky pixel exactly."""
    from streetaug.augment.lighting import volume as vol
    from streetaug.augment.lighting.volume import CH_ALPHA, CH_COLOR, CH_SIGMA

    h = hybrid(scene(with_sky=True))
    params = np.array(h.params)
    c = h.grid.voxel_centres()
    block = (c[..., 0] > 20) & (c[..., 0] < 45) & (c[..., 1] > 6) & (c[..., 1] < 18) & (c[..., 2] > 0) & (c[..., 2] < 25)
    params[block, CH_ALPHA] = 1.0
    params[block, CH_COLOR] = (1.0, 0.0, 0.0)
    params[block, CH_SIGMA] = 10.0  # a broad lobe: ~the colour from every side
    h = HybridLighting(h.sky_world, None, None, grid=h.grid, params=params, seen=h.seen)
    el = np.radians(20.0)
    d = np.array([[np.cos(el), 0.0, np.sin(el)]])
    side = np.array([CENTRE + np.array([0.0, 12.0, 0.0])])
    rgb = np.asarray(h.radiance(side, d, include_sun=False))[0]
    assert rgb[0] > 0.8 and rgb[1] < 0.1, rgb  # the block
    assert vol.SKY_PREEMPT_BASELINE_M < 12.0
    own = np.asarray(h.radiance(CENTRE[None], d, include_sun=False))[0]
    assert np.abs(own - sky_texture(d)[0]).max() < 0.03, own


def test_the_torch_backend_blends_the_sky_like_the_numpy_backend():
    """Tensors in (the differentiable backend): the same radiance as numpy's to float32 rounding, the sky pixel
    in front, behind and between (from the camera's centre, 12 m and 6 m to the side of it)."""
    import torch

    h = hybrid(scene(with_sky=True))
    params = np.array(h.params)
    params[..., 3:6] = (0.0, 0.0, 1.0)
    c = h.grid.voxel_centres()
    params[(c[..., 0] > 20) & (c[..., 0] < 45) & (c[..., 1] > 0) & (c[..., 2] > 0) & (c[..., 2] < 25), 7] = 0.5
    params[..., 0] = 0.7
    hn = HybridLighting(h.sky_world, None, None, grid=h.grid, params=params, seen=h.seen)
    ht = HybridLighting(torch.from_numpy(np.array(h.sky_world)), None, None, grid=h.grid,
                        params=torch.from_numpy(params), seen=h.seen)
    el = np.radians(np.linspace(10.0, 25.0, 7))
    d = np.stack([np.cos(el), np.zeros_like(el), np.sin(el)], axis=1)
    for side_m in (0.0, 6.0, 12.0):
        o = np.repeat((CENTRE + np.array([0.0, side_m, 0.0]))[None], len(d), axis=0)
        a = np.asarray(hn.radiance(o, d, include_sun=False))
        b = ht.radiance(torch.from_numpy(o), torch.from_numpy(d), include_sun=False).detach().numpy()
        assert np.allclose(a, b, atol=1e-4), (side_m, np.abs(a - b).max())
