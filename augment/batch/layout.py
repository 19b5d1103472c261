"""The output folder of a batch: where the log, the summary, the plan and the changed lidarseg labels go.

See :mod:`.run` for the whole tree (images, labels, tables, shards).
"""

from __future__ import annotations

from pathlib import Path

LOG_FILE = "augment_log.jsonl"
SUMMARY_FILE = "summary.json"
PLAN_FILE = "plan.jsonl"
# Output folder of lidarseg labels that inserted objects changed (``lidarseg/`` links to the source's).
LIDARSEG_FOLDER = "lidarseg_augmented"


def shard_dir(out_dir: Path, shard: tuple[int, int]) -> Path:
    """The folder of shard ``(i, n)``'s log and summary."""
    return out_dir / "shards" / f"{shard[0]}-of-{shard[1]}"
