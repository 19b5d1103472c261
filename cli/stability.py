"""``streetaug stability``: how much the outputs move under perturbed inputs (see :mod:`streetaug.augment.stability`)."""

from __future__ import annotations

from pathlib import Path

import click

from .main import _dataset_options, _open_dataset, _resolve_sample, _runtime_errors, _view


@click.command("stability")
@_dataset_options
@click.option("--families", default=None,
              help="Comma-separated perturbation families (default: all: exposure, noise, jpeg, focal, depth_bias, "
                   "depth_noise, lidar_dropout, calibration).")
@click.option("--quality", type=click.Choice(["draft", "default", "high"]), default="draft", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@_runtime_errors
def stability(dataroot, version, scene, sample_token, camera, families, quality, seed, out, debug):
    """Perturb one sample's inputs and measure how the sun, env map, placement and composite change.

    Writes stability.json (one row per family and strength) and stability.png (curves).

    \b
    Example:
      streetaug stability --scene sample-sunny --out out/stability
    """
    from streetaug.augment.assets.select import select_assets
    from streetaug.augment.io import write_json_atomic
    from streetaug.augment.pipeline import InsertOptions, item_seed
    from streetaug.augment.stability import plot_report, stability_report

    reader = _open_dataset(dataroot, version)
    sample = reader.sample(_resolve_sample(reader, scene, sample_token))
    view = _view(sample, camera)
    assets = select_assets(item_seed(seed, "asset", sample.token, camera), 1)
    names = [f.strip() for f in families.split(",")] if families else None
    report = stability_report(sample, view, assets, InsertOptions(quality=quality, seed=seed), names, seed=seed)
    write_json_atomic(out / "stability.json", report)
    plot_report(report, out / "stability.png")
    click.echo(f"wrote {out}/stability.json and stability.png ({len(report['rows'])} perturbed runs)")
