"""``streetaug batch``: augment a whole dataset (see :mod:`streetaug.augment.batch`)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from .main import CAMERA_DEFAULT, LEVEL_HELP, LIGHT_LEVELS, _asset_options, _open_dataset, _render_options, _runtime_errors


@click.command("batch")
@click.option("--dataroot", type=click.Path(file_okay=False, path_type=Path),
              help="nuScenes dataroot (default: the bundled sample scenes).")
@click.option("--version", "version", default=None, help="Dataset version folder, e.g. v1.0-mini.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--cameras", default=CAMERA_DEFAULT, show_default=True, help="Comma-separated camera channels.")
@click.option("--limit", type=click.IntRange(min=1), help="At most this many samples.")
@_asset_options
@_render_options
@click.option("--level", type=click.Choice(LIGHT_LEVELS), default="L1", show_default=True, help=LEVEL_HELP)
@click.option("--fail-fast", is_flag=True, help="Stop at the first failing image.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@_runtime_errors
def batch(dataroot, version, out, cameras, limit, asset, assets_dir, asset_front, asset_length, quality, seed, ev,
          level, fail_fast, debug):
    """Augment every sample of a dataset (first version: images + labels; resumes when re-run).

    \b
    Examples:
      streetaug batch --out out/dataset
      streetaug batch --dataroot ../shared/data/nuscenes-real --version v1.0-mini \\
          --cameras CAM_FRONT,CAM_FRONT_LEFT --out out/real-aug
    """
    from streetaug.augment.batch import BatchConfig, run_batch

    reader = _open_dataset(dataroot, version)
    config = BatchConfig(
        cameras=tuple(c.strip() for c in cameras.split(",") if c.strip()), limit=limit, seed=seed,
        quality=quality, level=level, ev=ev, asset=asset, assets_dir=assets_dir, asset_front=asset_front,
        asset_length=asset_length, fail_fast=fail_fast,
    )
    t = time.perf_counter()
    summary = run_batch(reader, out, config)
    click.echo(f"done in {time.perf_counter() - t:.1f} s: " +
               ", ".join(f"{k} {v}" for k, v in sorted(summary["counts"].items())) + f"; outputs in {out}")
