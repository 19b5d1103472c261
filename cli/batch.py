"""``streetaug batch`` and ``streetaug merge``: augment a whole dataset (see :mod:`streetaug.augment.batch`)."""

from __future__ import annotations

from pathlib import Path

import click

# The batch machinery (placement, the dataset reader, scipy, shapely) is imported in the command bodies:
# `streetaug --help` and the other commands must not pay for it.
from .common import (LEVEL_HELP, LIGHT_LEVELS, YAW_SIGMA_RANGE, asset_options, exit_if_failed, limit_options,
                     render_options, runtime_errors)


def _dataroot(dataroot: Path | None, version: str | None) -> tuple[str, str]:
    """(absolute dataroot, version) of the options; the bundled sample scenes without ``--dataroot``."""
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot

    if dataroot is None:
        return str(bundled_dataroot().resolve()), version or BUNDLED_VERSION
    if version is None:
        raise click.UsageError("--version is required with --dataroot (e.g. --version v1.0-mini)")
    return str(dataroot.resolve()), version


@click.command("batch")
@click.option("--dataroot", type=click.Path(file_okay=False, path_type=Path),
              help="nuScenes dataroot (default: the bundled sample scenes).")
@click.option("--version", "version", default=None, help="Dataset version folder, e.g. v1.0-mini.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: becomes a nuScenes dataset (NuScenes(version, dataroot=OUT)).")
@click.option("--cameras", default="all", show_default=True,
              help="Comma-separated camera channels to augment, or 'all'. Objects are placed in each camera's "
                   "view and rendered into every selected camera that sees them.")
@click.option("--limit", type=click.IntRange(min=1), help="At most this many samples (the first, in scene order).")
@click.option("--n-objects", type=click.IntRange(1, 8), default=1, show_default=True,
              help="Objects placed in each camera's view.")
@click.option("--tracks", type=click.IntRange(0, 16), default=0, show_default=True,
              help="Insert N tracks per scene: instances through the scene's keyframes (parked by the kerb or moving "
                   "along a lane), rendered into every camera of every keyframe that sees them, with velocities and "
                   "prev/next-linked annotations. 0: objects per sample (--n-objects).")
@click.option("--sweeps", is_flag=True,
              help="With --tracks: also render the tracks into the camera (12 Hz) and LiDAR (20 Hz) sweeps between "
                   "keyframes, at poses interpolated at each sweep's time (skipped, with the reason, where the "
                   "dataset has no sweep files).")
@click.option("--yaw-sigma", type=YAW_SIGMA_RANGE, default=15.0, show_default=True,
              help="Yaw noise (deg, 0-180) around the ego heading: 15 augmentation (paper), 3 realistic.")
@asset_options
@render_options
@click.option("--level", type=click.Choice(LIGHT_LEVELS), default="auto", show_default=True, help=LEVEL_HELP)
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Local worker processes [default: all cores].")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run on a Dask cluster, e.g. tcp://HOST:8786 (workers need the same --dataroot and --out paths).")
@click.option("--dask-local", type=click.IntRange(min=1), default=None, metavar="N",
              help="Run on a Dask LocalCluster of N worker processes.")
@click.option("--shard", default=None, metavar="I/N",
              help="Process only shard I of N (0-based, e.g. $SLURM_ARRAY_TASK_ID/8); then 'streetaug merge --out'.")
@click.option("--dry-run", is_flag=True, help="Plan placements only (writes OUT/plan.jsonl), render nothing.")
@click.option("--contact-sheet", type=click.IntRange(min=0), default=12, show_default=True,
              help="Random augmented images in OUT/contact_sheet.png (0: none).")
@click.option("--fail-fast", is_flag=True, help="Stop at the first failing sample (with --debug: its traceback).")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@limit_options
@runtime_errors
def batch(dataroot, version, out, cameras, limit, n_objects, tracks, sweeps, yaw_sigma, asset, assets_dir, asset_front, asset_length,
          classes, class_weights, class_rules, class_sizes, quality, seed, ev, match_camera, level, workers, scheduler, dask_local, shard, dry_run, contact_sheet, fail_fast,
          no_progress, debug):
    """Augment every sample of a dataset into a new nuScenes-format dataset; rerunning resumes.

    \b
    Examples:
      streetaug batch --out out/dataset
      streetaug batch --dataroot ../shared/data/nuscenes-real --version v1.0-mini --out out/real-aug
      streetaug batch --dataroot /data/nuscenes --version v1.0-trainval --out /shared/aug \\
          --shard $SLURM_ARRAY_TASK_ID/64 --no-progress      # one job of an array, then:
      streetaug merge --out /shared/aug

    \b
    Exit codes: 0 every image done (ok or skipped); 3 the batch finished but some or
    all images failed ("N of M images failed; see OUT/augment_log.jsonl"); 1 bad input
    (nothing augmented: e.g. --out inside the source, a broken asset, another run
    writing into --out); 2 bad arguments.
    """
    from streetaug.augment.batch import BatchConfig, RunOptions, default_workers, format_summary, parse_shard, run_batch
    from streetaug.augment.batch.layout import LOG_FILE, PLAN_FILE, shard_dir

    if scheduler and dask_local:
        raise click.UsageError("give --scheduler ADDRESS or --dask-local N, not both")
    if dry_run and shard:
        raise click.UsageError("--dry-run plans the whole dataset; drop --shard")
    if asset is not None and (classes or class_weights):
        raise click.UsageError("--classes/--class-weights choose procedural objects or --assets files by class; "
                               "--asset FILE is one object: give one or the other")
    root, version = _dataroot(dataroot, version)
    names = tuple(dict.fromkeys(c.strip() for c in cameras.split(",") if c.strip()))  # duplicates once
    config = BatchConfig(
        dataroot=root, version=version, cameras=() if names in ((), ("all",)) else names, limit=limit, seed=seed,
        quality=quality, level=level, ev=ev, match_camera=match_camera, n_objects=n_objects, yaw_sigma_deg=yaw_sigma,
        asset=str(asset.resolve()) if asset else None, assets_dir=str(assets_dir.resolve()) if assets_dir else None,
        asset_front=asset_front, asset_length=asset_length, tracks=tracks, sweeps=sweeps, classes=classes,
        class_weights=class_weights, class_rules=str(class_rules.resolve()) if class_rules else None,
        class_sizes=str(class_sizes.resolve()) if class_sizes else None,
    )
    run = RunOptions(workers=workers or default_workers(), scheduler=scheduler, dask_local=dask_local,
                     shard=parse_shard(shard) if shard else None, fail_fast=fail_fast, dry_run=dry_run,
                     contact_sheet=contact_sheet, progress=not no_progress)
    summary = run_batch(config, out, run, echo=lambda msg: click.echo(msg, err=True))
    click.echo(format_summary(summary))
    if dry_run:
        rejected = ", ".join(f"{k} {v}" for k, v in summary["rejections"].items() if v)
        click.echo(f"  planned {summary['objects_planned']} objects; candidates rejected by rule: {rejected}\n"
                   f"  plan: {out}/plan.jsonl")
    elif run.shard:
        click.echo(f"  shard {shard} done; when every shard is: streetaug merge --out {out}")
    else:
        click.echo(f"  dataset: NuScenes(version='{version}', dataroot='{out}')"
                   + (f"; look: {out}/contact_sheet.png" if summary.get("outputs", {}).get("contact_sheet") else ""))
    log = out / PLAN_FILE if dry_run else (shard_dir(out, run.shard) if run.shard else out) / LOG_FILE
    exit_if_failed(summary, log)


@click.command("merge")
@click.option("--out", required=True, type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="The output folder the shards wrote into.")
@click.option("--allow-incomplete", is_flag=True,
              help="Merge even if some planned samples have no result (their images stay the source's).")
@click.option("--contact-sheet", type=click.IntRange(min=0), default=12, show_default=True,
              help="Random augmented images in OUT/contact_sheet.png (0: none).")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@runtime_errors
def merge(out, allow_incomplete, contact_sheet, debug):
    """Join the shards of 'streetaug batch --shard I/N' into one nuScenes dataset (log, tables, summary).

    Exit codes as batch: 0 nothing failed, 3 some images failed, 1 bad input.

    \b
    Example:
      streetaug merge --out /shared/aug
    """
    from streetaug.augment.batch import format_summary, merge as merge_shards
    from streetaug.augment.batch.layout import LOG_FILE

    summary = merge_shards(out, allow_incomplete, contact_sheet, echo=lambda msg: click.echo(msg, err=True))
    click.echo(format_summary(summary))
    exit_if_failed(summary, out / LOG_FILE)
