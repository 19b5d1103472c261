"""``streetaug train-sky`` and ``streetaug train-light``: train the learned sky model and image predictor.

Thin shells over :mod:`streetaug.augment.training`; the resolved configuration and the
training report are written beside the cached data (``--cache``).
"""

from __future__ import annotations

from pathlib import Path

import click

from .common import runtime_errors

_COMMON = [
    click.option("--seed", type=int, default=0, show_default=True, help="Seed of data, batches and initialisation."),
    click.option("--steps", type=click.IntRange(min=1), default=None, help="Optimiser steps (default: the config's)."),
    click.option("--batch", type=click.IntRange(min=1), default=None, help="Batch size."),
    click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
                 help="torch threads (more than the free cores makes OpenMP spin)."),
    click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
                 help="Weights file to write (default: the package's shipped weights)."),
    click.option("--cache", "cache_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
                 help="Folder for generated data and checkpoints (default ~/.cache/streetaug/skynet)."),
    click.option("--hdri", "hdri_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
                 help="Folder of the HDR panoramas (default $STREETAUG_HDRI or ../shared/data/hdri)."),
    click.option("--debug", is_flag=True, help="Show tracebacks."),
]


def _common(func):
    for option in reversed(_COMMON):
        func = option(func)
    return func


def _overrides(**kwargs) -> dict:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in kwargs.items() if v is not None}


@click.command("train-sky")
@_common
@click.option("--n-synth", type=click.IntRange(min=1), default=None, help="Number of synthetic skies generated.")
@runtime_errors
def train_sky(seed, steps, batch, threads, out, cache_dir, hdri_dir, debug, n_synth):
    """Train the sky model (LDR sky dome -> sky vector -> HDR dome) on synthetic + real skies.

    \b
    Example (the shipped weights; ~4 min training + ~1 min data on one core):
      streetaug train-sky --seed 0
    """
    from dataclasses import replace

    from streetaug.augment.training import SkyTrainConfig  # defers torch: only training needs it
    from streetaug.augment.training import train_sky as run

    cfg = replace(SkyTrainConfig(), **_overrides(seed=seed, steps=steps, batch=batch, threads=threads, out=out,
                                                 cache_dir=cache_dir, hdri_dir=hdri_dir, n_synth=n_synth))
    report = run(cfg, log=lambda s: click.echo(s))
    v = report["val"]["all"]
    click.echo(f"held-out panoramas: log-MSE {v['log_mse']:.4f}, peak error median {v['peak_err_deg_median']:.2f} deg")


@click.command("train-light")
@_common
@click.option("--n-streets", type=click.IntRange(min=1), default=None, help="Generated streets (2 views each).")
@click.option("--sky-weights", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Sky model weights (default: the package's).")
@click.option("--preset", type=click.Choice(["v2", "v3"]), default="v2", show_default=True,
              help="v2 (shipped): from scratch on synthetic streets and 4 panoramas; v3 (measured, not shipped: "
                   "see the model card): v2 fine-tuned with the real dev scene's training keyframes and 11 panoramas.")
@click.option("--init-weights", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
              help="Weights to fine-tune from (v3 needs v2's: git show e6b26cc:augment/lighting/skynet/weights/"
                   "light_model_v2.pt > v2.pt).")
@click.option("--real", "real_dataroot", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="nuScenes folder of the real dev scene (default ../shared/data/nuscenes-seq).")
@runtime_errors
def train_light(seed, steps, batch, threads, out, cache_dir, hdri_dir, debug, n_streets, sky_weights, preset,
                init_weights, real_dataroot):
    """Train the image -> sky-vector predictor (sun direction, visibility, sky latent) on top of the sky model.

    \b
    Examples (1 thread):
      streetaug train-light --seed 0                           # the shipped v2 (~30 min + 1200 street renders)
      streetaug train-light --preset v3 --init-weights v2.pt   # the v3 candidate of the model card (~32 min)
    """
    from dataclasses import replace

    from streetaug.augment.training import LightTrainConfig  # defers torch: only training needs it
    from streetaug.augment.training import train_light as run
    from streetaug.augment.training.train import LIGHT_V3

    base = LIGHT_V3 if preset == "v3" else LightTrainConfig()
    if preset == "v3" and init_weights is None:
        raise click.UsageError("--preset v3 fine-tunes v2: pass --init-weights (v2's file, see --help)")
    cfg = replace(base, **_overrides(seed=seed, steps=steps, batch=batch, threads=threads, out=out,
                                     cache_dir=cache_dir, hdri_dir=hdri_dir, n_streets=n_streets,
                                     sky_weights=sky_weights, init_weights=init_weights, real_dataroot=real_dataroot))
    report = run(cfg, log=lambda s: click.echo(s))
    click.echo(f"held-out panorama crops: sun direction median error {report['val']['sun_err_deg_median']:.1f} deg")

