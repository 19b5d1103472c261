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
