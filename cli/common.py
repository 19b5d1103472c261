"""Options, parsing and error handling shared by the ``streetaug`` commands.

Exit codes: 0 success, 1 bad input or runtime errors (one line on stderr; the traceback only with
``--debug``), 2 bad arguments (click usage errors: also non-finite or absurd numbers), 3 a batch finished
but some images failed (``summary.json`` counts them; the log says why).
"""

from __future__ import annotations

import contextlib
import functools
import gc
import math
import os
import sys
from dataclasses import fields
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import click
import numpy as np

from streetaug.augment.core import InputError, intrinsics_from_fov
from streetaug.augment.core.limits import ResourceLimits

if TYPE_CHECKING:  # the dataset modules load shapely and scipy: imported where a command reads a dataset
    from streetaug.datasets.nuscenes import NuScenesReader
    from streetaug.datasets.sample import CameraView, Sample

CAMERA_DEFAULT = "CAM_FRONT"
# Lighting levels offered on the command line (see streetaug.augment.lighting.api).
LIGHT_LEVELS = ("L0", "L1", "L2", "L3", "auto")
LEVEL_HELP = ("Lighting level: L0 constant dome (the no-light baseline), L1 sun + parametric sky, "
              "L2 + scene volume near the placement, L3 full scene volume, auto the cheapest level whose "
              "predicted error is within 0.05 of the best (choice and reason in lighting.json).")


EXIT_SOME_FAILED = 3  # a batch finished but some images failed
MAX_POSITION_M = 1e4  # |X|, |Y|, |Z| of --at / --pose-camera
MAX_YAW_DEG = 720.0
MAX_PIXELS_PARAM = 1e6  # fx, fy, |cx|, |cy| of --intrinsics


def parse_floats(value: str | None, n: int, name: str,
                 bounds: list[float] | None = None) -> list[float] | None:
    """``"a,b,c"`` -> n finite floats, each ``|x| <= bounds[i]`` when given (a usage error naming ``name``)."""
    if value is None:
        return None
    try:
        parts = [float(x) for x in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected {n} comma-separated numbers, got {value!r}", param_hint=name) from None
    if len(parts) != n or not all(np.isfinite(parts)):
        raise click.BadParameter(f"expected {n} finite comma-separated numbers, got {value!r}", param_hint=name)
    for i, (x, bound) in enumerate(zip(parts, bounds or ())):
        if abs(x) > bound:
            raise click.BadParameter(f"value {i + 1} ({x:g}) is out of range: expected |x| <= {bound:g}",
                                     param_hint=name)
    return parts


def float_list(n: int, bounds: list[float]) -> Callable:
    """A click callback checking a comma-separated option at parse time (:func:`parse_floats`); the value
    stays the text, parsed again where it is used."""

    def check(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
        parse_floats(value, n, param.opts[0], bounds)
        return value

    return check


POSITION_CHECK = float_list(3, [MAX_POSITION_M] * 3)
POSE_CHECK = float_list(4, [MAX_POSITION_M] * 3 + [MAX_YAW_DEG])
INTRINSICS_CHECK = float_list(4, [MAX_PIXELS_PARAM] * 4)


class FiniteFloat(click.FloatRange):
    """A float option within a range, refusing NaN (which ``click.FloatRange`` lets through) and infinities."""

    name = "float"

    def convert(self, value, param, ctx):
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


EV_RANGE = FiniteFloat(-20.0, 20.0)
YAW_SIGMA_RANGE = FiniteFloat(0.0, 180.0)
ASSET_LENGTH_RANGE = FiniteFloat(0.0, 100.0, min_open=True)
FOV_RANGE = FiniteFloat(0.0, 180.0, min_open=True, max_open=True)


def exit_if_failed(summary: dict, log: Path) -> None:
    """Exit 3 with ``N of M images failed; see LOG`` when any image of the batch failed."""
    failed = int(summary.get("counts", {}).get("failed", 0))
    if failed:
        click.echo(f"{failed} of {summary.get('images', failed)} images failed; see {log}", err=True)
        sys.exit(EXIT_SOME_FAILED)


_imports_frozen = False


@contextlib.contextmanager
def library_imports():
    """Import a command's library modules (torch, scipy, the pipeline) with the cyclic GC paused, then freeze them.

    The imports allocate ~1M objects that live as long as the process: with the GC on, each collection on the
    way re-walks them, and so does the collection at exit (together ~0.5 CPU-s of a ~3.5 s ``insert``).
    Frozen, later collections skip them; garbage made afterwards is collected as usual. Once per process:
    a process running many commands (tests) freezes only what existed at the first.
    """
    global _imports_frozen
    if _imports_frozen:
        yield
        return
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        _imports_frozen = True
        gc.freeze()
        if was_enabled:
            gc.enable()


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
    from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
    from streetaug.datasets.nuscenes import NuScenesReader

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
    fx, fy, cx, cy = parse_floats(intrinsics, 4, "--intrinsics", [MAX_PIXELS_PARAM] * 4)
    if fx <= 0 or fy <= 0:
        raise click.BadParameter("focal lengths must be positive", param_hint="--intrinsics")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def intrinsics_option(intrinsics: str | None, fov_deg: float | None, width: int, height: int) -> np.ndarray:
    """K (3, 3) from ``--intrinsics`` or else ``--fov-deg`` (horizontal, principal point at the image centre)."""
    if intrinsics is not None:
        return parse_intrinsics(intrinsics)
    return intrinsics_from_fov(width, height, fov_deg)


def _check_classes(ctx, param, value):
    """--classes: comma-separated detection classes, checked as the class mix checks them (exit 2 when bad)."""
    if value is None:
        return None
    from streetaug.augment.assets.classes import ClassMix  # deferred: the procedural generators

    try:
        return ",".join(ClassMix.parse(value).classes)
    except InputError as e:
        raise click.BadParameter(str(e), ctx, param) from None


def asset_options(func: Callable) -> Callable:
    options = [
        click.option("--asset", type=click.Path(dir_okay=False, path_type=Path),
                     help="glTF/GLB/OBJ/PLY asset (metres, +Y up, front +Z). Default: a procedural car."),
        click.option("--assets", "assets_dir", type=click.Path(file_okay=False, path_type=Path),
                     help="Folder of assets to sample from."),
        click.option("--asset-front", default="+z", show_default=True,
                     type=click.Choice(["+x", "-x", "+y", "-y", "+z", "-z"]),
                     help="Axis the asset's front points along (the Kenney cars: -z)."),
        click.option("--asset-length", type=ASSET_LENGTH_RANGE,
                     help="Rescale the asset to this length in metres (0 < L <= 100)."),
        click.option("--classes", default=None, callback=_check_classes, metavar="A,B,...",
                     help="Detection classes to insert (car, truck, bus, trailer, construction_vehicle, pedestrian, "
                          "motorcycle, bicycle, traffic_cone, barrier); procedural, or the --assets files of those "
                          "classes. Default: cars."),
        click.option("--class-weights", default=None, metavar="W,W,... | NAME=W,...",
                     help="Weights of --classes (same order, or name=weight; unlisted 1), e.g. "
                          "construction_vehicle=4 to oversample. Alone: every class."),
        click.option("--class-rules", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
                     help="JSON file overriding the per-class placement rules (schema streetaug.class_rules/1; "
                          "see placement/class_rules.json)."),
        click.option("--class-sizes", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
                     help="Box-size table procedural objects are built to (from 'streetaug class-sizes' on your "
                          "own dataset; default: the shipped nuScenes statistics)."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def render_options(func: Callable) -> Callable:
    options = [
        click.option("--quality", type=click.Choice(["draft", "default", "high"]), default="default",
                     show_default=True, help="Render preset."),
        click.option("--seed", type=int, default=0, show_default=True, help="Random seed (placement, asset, sampling)."),
        click.option("--ev", type=EV_RANGE, default=0.0, show_default=True,
                     help="Exposure of the camera response (stops, -20 to 20)."),
        click.option("--match-camera/--no-match-camera", default=True, show_default=True,
                     help="Give the object the photo's look: its blur, motion blur, noise and JPEG quality "
                          "(estimated around the object)."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


# ----------------------------------------------------------------------------- resource limits

LIMIT_HELP = {
    "max_image_pixels": "Largest input image, depth or env map (width x height pixels); larger ones are refused.",
    "max_texture_side": "Textures larger than this (pixels, either side) are downscaled while decoding.",
    "max_texture_pixels": "Largest texture (pixels, before downscaling); larger ones are refused.",
    "max_triangles": "Most triangles of one asset; more are refused.",
    "max_memory_mb": "Largest estimated peak memory of a stage (MiB); larger inputs are refused before it runs.",
}


def _set_limit(ctx: click.Context, param: click.Parameter, value: int | None) -> None:
    """Put a ``--max-*`` option into the environment (``STREETAUG_MAX_*``), read by every process and worker."""
    if value is not None and ctx.get_parameter_source(param.name) == click.core.ParameterSource.COMMANDLINE:
        os.environ[param.envvar] = str(value)


def limit_options(func: Callable) -> Callable:
    """``--max-image-pixels``, ``--max-texture-side``, ``--max-texture-pixels``, ``--max-triangles``,
    ``--max-memory-mb`` (defaults: :class:`ResourceLimits`; each also read from ``STREETAUG_MAX_*``)."""
    defaults = ResourceLimits()
    for f in reversed(fields(ResourceLimits)):
        func = click.option(
            "--" + f.name.replace("_", "-"), f.name, type=click.IntRange(min=1), envvar="STREETAUG_" + f.name.upper(),
            show_envvar=True, expose_value=False, callback=_set_limit, metavar="N",
            help=f"{LIMIT_HELP.get(f.name, f.name)} [default: {getattr(defaults, f.name)}]")(func)
    return func
