"""Batch augmentation of a whole nuScenes dataset into a new nuScenes-format dataset.

``run_batch(config, out_dir, run)`` plans the samples, skips those an earlier run finished, sends the
rest to workers (inline, local processes or Dask; :mod:`.execute`), each of which augments one sample
in all its cameras (:mod:`.worker`), logs every image (:mod:`.log`) and at the end writes the tables,
``summary.json`` and a contact sheet (:mod:`.run`, :mod:`.report`). ``merge`` joins ``--shard`` runs.
"""

from .config import BatchConfig, RunOptions, default_workers, parse_shard
from .log import read_log
from .report import format_summary
from .run import merge, run_batch

__all__ = ["BatchConfig", "RunOptions", "default_workers", "format_summary", "merge", "parse_shard", "read_log",
           "run_batch"]
