"""Training of the learned sky (``streetaug.augment.training``): procedural skies, training views, the loops.

Smoke runs only (one or two steps); tests that need the real HDR panoramas (``../shared/data/hdri``) skip without
them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from conftest import HDRI, needs_hdri, unit
from streetaug.augment.lighting.skynet.inputs import view_rays
from streetaug.augment.lighting.skynet.model import LightNet
from streetaug.augment.lighting.skynet.weights import load_light_model, load_sky_model
from streetaug.augment.training import data as D
from streetaug.augment.training.synth import SynthSky, random_sky, random_waves
from streetaug.augment.training.train import (
    LightBatches,
    LightTrainConfig,
    SkyTrainConfig,
    light_losses,
    train_light,
    train_sky,
)
from streetaug.cli.main import main



class TestSynth:
    def test_clouds_hide_the_sun_and_stay_physical(self):
        sun = unit([0.3, 0.2, 0.6])
        clear = SynthSky(sun)
        rng = np.random.default_rng(3)
        cloudy = SynthSky(sun, coverage=1.0, thickness=10.0, waves=random_waves(rng, 3.0))
        assert clear.sun_visibility > 0.8
        assert cloudy.sun_visibility < 0.01 and cloudy.sun_transmittance < 0.01
        for sky in (clear, cloudy):
            dome = sky.dome(32, 128)
            assert np.all(np.isfinite(dome)) and dome.min() > 0
        below = SynthSky(unit([0.3, 0.2, -0.05]))
        assert below.sun_visibility == 0.0 and not np.any(below.sun_irradiance_rgb > 0)

    def test_random_skies_are_deterministic_and_varied(self):
        a = random_sky(np.random.default_rng([0, 7, 5])).dome(16, 64)
        b = random_sky(np.random.default_rng([0, 7, 5])).dome(16, 64)
        np.testing.assert_array_equal(a, b)
        vis = [random_sky(np.random.default_rng([1, i])).sun_visibility for i in range(40)]
        assert min(vis) == 0.0 and max(vis) > 0.8


@needs_hdri
def test_train_sky_one_step_smoke(tmp_path):
    cfg = SkyTrainConfig(steps=1, batch=2, n_synth=3, threads=1, ckpt_every=1, val_every=1,
                         out=str(tmp_path / "sky.pt"), cache_dir=str(tmp_path), hdri_dir=str(HDRI))
    report = train_sky(cfg, log=lambda s: None)
    assert np.isfinite(report["val"]["all"]["log_mse"])
    load_sky_model(tmp_path / "sky.pt")
    assert list(tmp_path.glob("ckpt_sky_*.pt"))  # a checkpoint to resume from


@needs_hdri
def test_train_light_two_steps_then_resume(tmp_path):
    """The image predictor trains through the shared loop, checkpoints, and a rerun resumes instead of redoing."""
    cfg = LightTrainConfig(steps=2, batch=2, n_streets=0, n_crops=4, mix=(0.0, 0.5, 0.5), threads=1, ckpt_every=1,
                           val_every=1, out=str(tmp_path / "light.pt"), cache_dir=str(tmp_path), hdri_dir=str(HDRI))
    lines: list[str] = []
    report = train_light(cfg, log=lines.append)
    assert [h["step"] for h in report["history"]] == [1, 2]
    assert all(np.isfinite(v) for h in report["history"] for v in h["train"].values())
    assert isinstance(load_light_model(tmp_path / "light.pt"), LightNet)
    lines.clear()
    again = train_light(cfg, log=lines.append)  # the checkpoint is at the last step: nothing to redo
    assert any("resuming from step 2" in line for line in lines)
    assert [h["step"] for h in again["history"]] == [1, 2]


@needs_hdri
def test_light_loss_smoke(models):
    panos = D.load_panoramas(HDRI, ("city",))
    rng = np.random.default_rng(0)
    crops = [D.panorama_view(panos["city"], 0.0, rng, (32, 128)), D.synthetic_sky_view(rng, (32, 128))]
    batch = LightBatches(([], crops[:1], crops[1:]), (0.0, 0.5, 0.5)).batch(3, rng)
    net = LightNet()
    losses = light_losses(net, models[0], {k: torch.from_numpy(v) for k, v in batch.items()})
    losses["total"].backward()
    assert all(torch.isfinite(v) for v in losses.values())
    assert all(p.grad is not None for p in net.parameters())


def test_mirrored_view_is_consistent():
    v = D.synthetic_sky_view(np.random.default_rng(4), (32, 128))
    f = D.flip_view(v)
    rays, rays_f = view_rays(v.K, v.R_heading_from_cam, 96, 160), view_rays(f.K, f.R_heading_from_cam, 96, 160)
    # pixel (i, j) of the mirror sees the mirror image (heading y -> -y) of what pixel (w-1-i, j) saw
    np.testing.assert_allclose(rays_f, rays[:, :, ::-1] * np.array([1.0, -1.0, 1.0])[:, None, None], atol=1e-6)
    np.testing.assert_array_equal(f.dome, v.dome[:, ::-1])
    np.testing.assert_allclose(D.flip_view(f).R_heading_from_cam, v.R_heading_from_cam, atol=1e-12)


def test_cli_train_sky_bad_hdri_dir(tmp_path):
    r = CliRunner().invoke(main, ["train-sky", "--steps", "1", "--n-synth", "2", "--cache", str(tmp_path),
                                  "--out", str(tmp_path / "w.pt"), "--hdri", str(tmp_path / "nope")])
    assert r.exit_code == 1
    assert "HDR panorama folder not found" in r.output


# ----------------------------------------------------------------------------- real street photos (issue 16)


def _fake_photo(rng: np.random.Generator, size=(180, 320)) -> D.View:
    """A "real photo" view: an image with only a known sun (no sky dome), as :func:`.real.photo_view` makes."""
    from streetaug.augment.core import intrinsics_from_fov
    from streetaug.augment.lighting.skynet.dome import heading_from_camera

    h, w = size
    img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    R = heading_from_camera(np.array([0.0, -1.0, 0.0]))
    return D.View(img, intrinsics_from_fov(w, h, 70.0), R, None, 0.1, unit([0.3, -0.5, 0.6]))


def test_real_photos_batch_with_their_sun_and_no_dome(models):
    """A photo's direction target is its ephemeris sun; its dome terms are masked out, its direction is not."""
    rng = np.random.default_rng(2)
    photo = _fake_photo(rng)
    synth = D.synthetic_sky_view(rng, (32, 128))
    b = D.views_batch([synth, photo])
    np.testing.assert_array_equal(b["has_dome"], [1.0, 0.0])
    np.testing.assert_allclose(b["dir"][1], photo.sun_dir_heading, atol=1e-6)
    assert b["log_hdr"].shape == (2, 3, 32, 128) and b["ldr"].shape == (2, 3, 96, 160)
    with pytest.raises(ValueError, match="dome_hw"):
        D.views_batch([photo])
    assert D.views_batch([photo], (32, 128))["log_hdr"].shape == (1, 3, 32, 128)
    torch.manual_seed(0)
    net = LightNet()
    t = {k: torch.from_numpy(v) for k, v in b.items()}
    base = light_losses(net, models[0], t)
    moved = dict(t, log_hdr=t["log_hdr"].clone(), log_int=t["log_int"].clone())
    moved["log_hdr"][1] += 5.0  # the photo's (absent) dome must not count ...
    moved["log_int"][1] += 5.0
    again = light_losses(net, models[0], moved)
    for k in ("hdr", "int", "total"):
        assert again[k].item() == pytest.approx(base[k].item(), rel=1e-6), k
    turned = dict(t, dir=t["dir"].clone())
    turned["dir"][1] = -turned["dir"][1]  # ... its sun must
    assert light_losses(net, models[0], turned)["dir"].item() > base["dir"].item() + 0.1


def test_jittered_photo_keeps_every_pixel_on_its_ray():
    from streetaug.augment.lighting.skynet.inputs import VIEW_SIZE
    from streetaug.augment.training.real import jitter_photo

    rng = np.random.default_rng(5)
    photo = _fake_photo(rng)
    for seed in range(3):
        j = jitter_photo(photo, np.random.default_rng(seed), VIEW_SIZE)
        h, w = VIEW_SIZE
        assert j.ldr.shape == (h, w, 3) and j.ldr.dtype == np.uint8
        np.testing.assert_array_equal(j.sun_dir_heading, photo.sun_dir_heading)
        # the jittered corners, back-projected and re-projected into the original, fall inside the original
        # image, and the crop is at least 70 % of each side
        corners = np.array([[-0.5, -0.5, 1.0], [w - 0.5, h - 0.5, 1.0]])
        orig = (photo.K @ np.linalg.inv(j.K) @ corners.T).T
        orig = orig[:, :2] / orig[:, 2:]
        H0, W0 = photo.ldr.shape[:2]
        assert np.all(orig >= -0.5 - 1e-6) and np.all(orig <= np.array([W0, H0]) - 0.5 + 1e-6)
        span = orig[1] - orig[0]
        assert 0.7 * W0 - 1 <= span[0] <= W0 + 1e-6 and 0.7 * H0 - 1 <= span[1] <= H0 + 1e-6


def test_shadow_contrast_to_visibility():
    from streetaug.augment.training.real import visibility_from_contrast

    vals = [visibility_from_contrast(c) for c in (None, 0.8, 1.0, 1.6, 2.5, 4.0, 9.0)]
    assert vals[0] == 0.0 and vals[1] == 0.0 and vals[2] == 0.0
    assert 0.0 < vals[3] < vals[4] < vals[5] == 1.0 == vals[6]


@needs_hdri
def test_train_light_fine_tunes_with_real_photos(tmp_path, monkeypatch):
    """The v3 recipe's path on tiny inputs: fine-tune from a weights file with a pool of real photos."""
    from dataclasses import replace

    import streetaug.augment.training.train as T

    rng = np.random.default_rng(7)
    photos = [_fake_photo(rng) for _ in range(3)]
    seen = {}

    def fake_pool(dataroot, keyframes, cache_dir, log=print):
        seen["args"] = (dataroot, keyframes)
        return photos

    monkeypatch.setattr(T, "real_photo_pool", fake_pool)
    init = tmp_path / "init.pt"
    from streetaug.augment.lighting.skynet.weights import save_weights

    torch.manual_seed(1)
    net0 = LightNet()
    save_weights(init, net0, "light", 2, net0.cfg.to_dict(), {})
    cfg = replace(T.LIGHT_V3, steps=2, batch=3, n_streets=0, n_crops=4, mix=(0.0, 0.3, 0.2, 0.5), threads=1,
                  ckpt_every=1, val_every=1, init_weights=str(init), real_dataroot="somewhere", real_keyframes=(0, 1),
                  train_panoramas=("city",), val_panoramas=("sky",), out=str(tmp_path / "light.pt"),
                  cache_dir=str(tmp_path), hdri_dir=str(HDRI))
    report = T.train_light(cfg, log=lambda s: None)
    assert seen["args"] == ("somewhere", (0, 1))
    assert report["real_photos"] == 3 and report["train_panoramas"] == ["city"]
    net = load_light_model(tmp_path / "light.pt")
    # fine-tuned: started from init (close to it after 2 small steps), but moved
    p0, p1 = dict(net0.named_parameters()), dict(net.named_parameters())
    diffs = [float((p1[k] - p0[k]).detach().abs().max()) for k in p0]
    assert max(diffs) > 0 and max(diffs) < 0.05
    from streetaug.augment.lighting.skynet.weights import read_weights

    assert read_weights(tmp_path / "light.pt", "light")["version"] == 3


def test_learning_rate_is_a_python_float():
    """Past the warm-up too: a numpy scalar in the optimiser state breaks resuming (weights_only checkpoints)."""
    from streetaug.augment.training.train import _lr

    for step in (0, 29, 30, 500, 999):
        assert type(_lr(1e-3, step, 1000)) is float
    assert _lr(1e-3, 30, 1000) > _lr(1e-3, 999, 1000) > 0


def test_cli_train_light_v3_needs_the_weights_it_fine_tunes(tmp_path):
    r = CliRunner().invoke(main, ["train-light", "--preset", "v3", "--steps", "1", "--cache", str(tmp_path),
                                  "--out", str(tmp_path / "w.pt")])
    assert r.exit_code == 2
    assert "--init-weights" in r.output
