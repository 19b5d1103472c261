"""``streetaug stability``: how much the outputs move under perturbed inputs (see :mod:`streetaug.augment.evaluation.stability`)."""

from __future__ import annotations

from pathlib import Path

import click

from .common import camera_view, dataset_options, open_dataset, resolve_sample, runtime_errors


@click.command("stability")
@dataset_options
@click.option("--families", default=None,
              help="Comma-separated perturbation families (default: all: exposure, noise, jpeg, focal, depth_bias, "
                   "depth_noise, lidar_dropout, calibration).")
@click.option("--failure-modes", is_flag=True,
              help="Instead: run the failure cases (night, sun at the horizon/zenith/behind, a wall, wet road, no "
                   "LiDAR, no map...) and write failure_modes.json and a contact sheet failure_modes.jpg.")
@click.option("--quality", type=click.Choice(["draft", "default", "high"]), default="draft", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@runtime_errors
def stability(dataroot, version, scene, sample_token, camera, families, failure_modes, quality, seed, out, debug):
    """Perturb one sample's inputs and measure how the sun, env map, placement and composite change.

    Writes stability.json (one row per family and strength) and stability.png (curves).

    \b
    Example:
      streetaug stability --scene sample-sunny --out out/stability
    """
    # Deferred: the insertion and the assets load scipy (torch only if the sky network runs); `--help` must not.
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.evaluation.failure_modes import write_failure_modes
    from streetaug.augment.evaluation.stability import write_stability_report
    from streetaug.augment.pipeline import InsertOptions, item_seed

    reader = open_dataset(dataroot, version)
    sample = reader.sample(resolve_sample(reader, scene, sample_token))
    view = camera_view(sample, camera)
    assets = select_assets(item_seed(seed, "asset", sample.token, camera), 1, location=sample.location)
    options = InsertOptions(quality=quality, seed=seed)
    if failure_modes:
        for row in write_failure_modes(sample, view, assets, options, out):
            click.echo(f"{row['case']:>20}: {row['outcome']:<8} {row['detail']}")
        return
    names = [f.strip() for f in families.split(",")] if families else None
    report = write_stability_report(sample, view, assets, options, out, names, seed=seed)
    click.echo(f"wrote {out}/stability.json and stability.png ({len(report['rows'])} perturbed runs)")
