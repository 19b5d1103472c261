"""Options, parsing and error handling shared by the ``streetaug`` commands.

Exit codes: 0 success, 2 bad arguments (click usage errors), 1 runtime errors (one line on stderr;
the traceback only with ``--debug``).
"""

from __future__ import annotations

import functools
import sys
import traceback
from pathlib import Path
from typing import Callable

import click
import numpy as np

from streetaug.augment.core import intrinsics_from_fov
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.sample import CameraView, Sample

CAMERA_DEFAULT = "CAM_FRONT"
# Lighting levels offered on the command line (see streetaug.augment.lighting.api).
LIGHT_LEVELS = ("L0", "L1", "L2", "L3", "auto")
LEVEL_HELP = ("Lighting level: L0 constant dome (the no-light baseline), L1 sun + parametric sky, "
              "L2 + scene volume near the placement, L3 full scene volume, auto the cheapest level whose "
              "predicted error is within 0.05 of the best (choice and reason in lighting.json).")


def parse_floats(value: str | None, n: int, name: str) -> list[float] | None:
    if value is None:
        return None
    try:
        parts = [float(x) for x in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected {n} comma-separated numbers, got {value!r}", param_hint=name) from None
    if len(parts) != n or not all(np.isfinite(parts)):
        raise click.BadParameter(f"expected {n} finite comma-separated numbers, got {value!r}", param_hint=name)
    return parts


def runtime_errors(func: Callable) -> Callable:
    """Turn library errors into one line on stderr and exit code 1 (traceback with --debug)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except click.ClickException:
            raise
        except (Exception, KeyboardInterrupt) as e:  # noqa: BLE001 - the CLI boundary
            if kwargs.get("debug"):
                traceback.print_exc()
            click.echo(f"error: {e}", err=True)
            sys.exit(1)

    return wrapper


# ----------------------------------------------------------------------------- shared options


def dataset_options(func: Callable) -> Callable:
    options = [
        click.option("--dataroot", type=click.Path(file_okay=False, path_type=Path),
                     help="nuScenes dataroot (default: the bundled sample scenes)."),
        click.option("--version", "version", default=None,
                     help="Dataset version folder, e.g. v1.0-mini (default for the bundled scenes: v1.0-samples)."),
        click.option("--scene", default=None, help="Scene name (e.g. scene-0061) or scene token."),
        click.option("--sample", "sample_token", default=None, help="Sample token (default: the scene's first sample)."),
        click.option("--camera", default=CAMERA_DEFAULT, show_default=True, help="Camera channel."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def open_dataset(dataroot: Path | None, version: str | None) -> NuScenesReader:
    """The reader of ``--dataroot``/``--version`` (the bundled sample scenes without ``--dataroot``)."""
    if dataroot is None:
        return NuScenesReader(bundled_dataroot(), version or BUNDLED_VERSION)
    if version is None:
        raise click.UsageError("--version is required with --dataroot (e.g. --version v1.0-mini)")
    return NuScenesReader(dataroot, version)


def resolve_sample(reader: NuScenesReader, scene: str | None, sample_token: str | None) -> str:
    """``--sample`` or else the first sample of ``--scene``."""
    if sample_token:
        return sample_token
    if scene is None:
        raise click.UsageError("give --scene NAME_OR_TOKEN or --sample TOKEN")
    tokens = reader.sample_tokens(scene)
    if not tokens:
        raise click.UsageError(f"scene {scene!r} has no samples")
    return tokens[0]


def camera_view(sample: Sample, camera: str) -> CameraView:
    """The sample's ``--camera``, or a usage error naming the cameras it has."""
    if camera not in sample.cameras:
        raise click.UsageError(
            f"camera {camera!r} not in sample {sample.token}; available: {', '.join(sorted(sample.cameras))}"
        )
    return sample.cameras[camera]


def parse_intrinsics(intrinsics: str) -> np.ndarray:
    """``--intrinsics fx,fy,cx,cy`` -> K (3, 3) (pixel centres at integers)."""
    fx, fy, cx, cy = parse_floats(intrinsics, 4, "--intrinsics")
    if fx <= 0 or fy <= 0:
        raise click.BadParameter("focal lengths must be positive", param_hint="--intrinsics")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def intrinsics_option(intrinsics: str | None, fov_deg: float | None, width: int, height: int) -> np.ndarray:
    """K (3, 3) from ``--intrinsics`` or else ``--fov-deg`` (horizontal, principal point at the image centre)."""
    if intrinsics is not None:
        return parse_intrinsics(intrinsics)
    return intrinsics_from_fov(width, height, fov_deg)


def asset_options(func: Callable) -> Callable:
    options = [
        click.option("--asset", type=click.Path(dir_okay=False, path_type=Path),
                     help="glTF/GLB/OBJ/PLY asset (metres, +Y up, front +Z). Default: a procedural car."),
        click.option("--assets", "assets_dir", type=click.Path(file_okay=False, path_type=Path),
                     help="Folder of assets to sample from."),
        click.option("--asset-front", default="+z", show_default=True,
                     type=click.Choice(["+x", "-x", "+y", "-y", "+z", "-z"]),
                     help="Axis the asset's front points along (the Kenney cars: -z)."),
        click.option("--asset-length", type=float, help="Rescale the asset to this length in metres."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def render_options(func: Callable) -> Callable:
    options = [
        click.option("--quality", type=click.Choice(["draft", "default", "high"]), default="default",
                     show_default=True, help="Render preset."),
        click.option("--seed", type=int, default=0, show_default=True, help="Random seed (placement, asset, sampling)."),
        click.option("--ev", type=float, default=0.0, show_default=True, help="Exposure of the camera response."),
        click.option("--match-camera", is_flag=True,
                     help="Blur the car and add noise like the photo around it (estimated there; +20-60 ms)."),
    ]
    for option in reversed(options):
        func = option(func)
    return func
