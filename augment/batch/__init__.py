"""Batch augmentation of a whole nuScenes dataset into a new nuScenes-format dataset.

``run_batch(config, out_dir, run)`` plans the samples, skips those an earlier run finished, sends the
rest to workers (inline, local processes or Dask; :mod:`.execute`), each of which augments one sample
in all its cameras (:mod:`.worker` runs the task, :mod:`.job` does the work, :mod:`.write` writes its
files), logs every image as one typed :class:`LogRow` (:mod:`.row`, :mod:`.log`) and at the end writes
the tables, ``summary.json`` and a contact sheet (:mod:`.run`, :mod:`.report`; the folder's layout:
:mod:`.layout`). ``merge`` joins ``--shard`` runs.
"""

from .config import BatchConfig, RunOptions, default_workers, parse_shard
from .log import read_log
from .report import format_summary
from .row import LidarEntry, LoggedLighting, LoggedObject, LogRow
from .run import merge, run_batch

__all__ = ["BatchConfig", "LidarEntry", "LogRow", "LoggedLighting", "LoggedObject", "RunOptions", "default_workers",
           "format_summary", "merge", "parse_shard", "read_log", "run_batch"]
