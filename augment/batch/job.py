"""One sample's work in a worker: choose its assets, insert into its cameras, write its files, make its rows."""

from __future__ import annotations

import time
from pathlib import Path

from streetaug.datasets.nuscenes import NuScenesReader

from ..assets.select import select_assets
from ..pipeline import InsertOptions, insert_into_sample, item_seed, place_in_sample
from .config import BatchConfig
from .row import LogRow
from .write import plan_rows, write_camera, write_lidar


def insert_options(config: BatchConfig) -> InsertOptions:
    """The insertion options of a batch."""
    return InsertOptions(quality=config.quality, level=config.level, seed=config.seed,
                         yaw_sigma_deg=config.yaw_sigma_deg, ev=config.ev, match_camera=config.match_camera)


def augment_sample(reader: NuScenesReader, config: BatchConfig, out_dir: Path, token: str, cameras: list[str],
                   dry_run: bool = False) -> list[LogRow]:
    """Augment ``cameras`` of sample ``token`` (``reader`` holds its table rows) into ``out_dir``.

    Returns one row per camera (with ``dry_run``: the planned placements, nothing rendered or written).
    Raises whatever fails; the caller logs it.
    """
    t0 = time.perf_counter()
    sample = reader.sample(token)
    views = [sample.cameras[c] for c in cameras if c in sample.cameras]
    assets = {v.channel: select_assets(item_seed(config.seed, "asset", token, v.channel), config.n_objects,
                                       config.asset, config.assets_dir, config.asset_front, config.asset_length)
              for v in views}
    options = insert_options(config)
    load_s = time.perf_counter() - t0
    if dry_run:
        return plan_rows(token, cameras, place_in_sample(sample, views, assets, options))
    result = insert_into_sample(sample, views, assets, options)
    t_lidar = time.perf_counter()
    lidar = write_lidar(out_dir, reader, sample, result, config.version)
    shared_s = {"load": load_s, "lidar": time.perf_counter() - t_lidar}  # per sample: shared by its cameras
    per_camera = {k: v / max(len(views), 1) for k, v in shared_s.items()}
    return [write_camera(out_dir, sample, c, result, per_camera, lidar) for c in cameras]
