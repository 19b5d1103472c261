"""``streetaug insert`` from files to files: its two forms, each reading its inputs and writing the contract's
outputs (:mod:`.outputs`) in one call."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from streetaug.datasets.sample import CameraView, Sample
from streetaug.placement.explain import draw_placement_bev

from ..assets.asset import Asset
from ..core import InputError, read_exr, read_image_rgb, write_image_rgb
from ..core.limits import ResourceLimits, check_image_pixels, image_size_from_header
from .image import insert_into_image
from .memory import check_insert_memory
from .options import InsertOptions
from .outputs import write_insert_outputs
from .results import InsertResult
from .sample import insert_into_view


def read_depth_map(path: Path) -> np.ndarray:
    """A metric depth map (H, W) float32 from ``.npy`` or ``.exr`` (first channel): camera-frame z, metres."""
    if path.suffix.lower() == ".npy":
        if not path.is_file():
            raise InputError(f"{path}: depth file not found")
        depth = np.load(path, allow_pickle=False)
    elif path.suffix.lower() == ".exr":
        depth = read_exr(path)
        depth = depth[..., 0]
    else:
        raise InputError(f"{path}: depth must be .exr or .npy (metres, camera-frame z)")
    if depth.ndim != 2:
        raise InputError(f"{path}: depth must be a single-channel (H, W) map, got shape {depth.shape}")
    return depth.astype(np.float32)


def insert_view_to_files(sample: Sample, view: CameraView, assets: Sequence[Asset], options: InsertOptions,
                         out_dir: Path, debug: bool = False, explain: bool = False) -> tuple[InsertResult, Path]:
    """The dataset form: insert into one camera of a sample; write ``image.*``, ``labels.json`` (with
    ``debug`` the mask and shadow maps, with ``explain`` ``placement_bev.png``). Returns the result and the
    image's path."""
    result = insert_into_view(sample, view, assets, options)
    if explain and result.placement is not None:
        write_image_rgb(out_dir / "placement_bev.png", draw_placement_bev(sample, view, result.placement))
    return result, write_insert_outputs(result, out_dir, Path(view.image_path).suffix, debug=debug)


def check_image_input(image_path: Path, options: InsertOptions) -> None:
    """Refuse, from its header alone, an input image above the size limit or whose insertion's memory estimate
    is above the memory limit (``InputError`` with the size and the limit); unreadable headers pass (the
    decoder names them)."""
    size = image_size_from_header(image_path) if Path(image_path).is_file() else None
    if size is not None:
        limits = ResourceLimits.from_env()
        check_image_pixels(size, str(image_path), limits)
        check_insert_memory([size], options.quality, f"insert --image {image_path}", limits)


def insert_image_to_files(image_path: Path, K: np.ndarray, depth_path: Path, envmap_path: Path, asset: Asset,
                          pose_camera: Sequence[float], options: InsertOptions, out_dir: Path,
                          debug: bool = False) -> tuple[InsertResult, Path]:
    """The image form: any image + metric depth + camera-frame env map + pose (:func:`insert_into_image`).

    ``K`` (3, 3) is the image's intrinsics. Returns the result and the written image's path.
    """
    check_image_input(image_path, options)
    image = read_image_rgb(image_path)
    result = insert_into_image(image, K, read_depth_map(depth_path), read_exr(envmap_path), asset, pose_camera, options)
    return result, write_insert_outputs(result, out_dir, image_path.suffix, debug=debug)
