"""Start-up of ``streetaug insert --scene sample-sunny`` for two revisions, interleaved (both see the same load).

Usage: ``python benchmarks/bench_startup_old_new.py --old OLD_SHIM --new NEW_SHIM [--runs 7] [--out FILE]``

Each ``*_SHIM`` is a directory holding a ``streetaug`` package of that revision (an empty ``__init__.py`` and
symlinks ``augment``, ``cli``, ``placement``, ``datasets`` into a ``git worktree``). Run ``i`` times the insert
and ``--help`` of both revisions, in the order old-new, new-old, ... (:func:`bench_startup.time_process`: wall
and the child's CPU seconds), then :func:`bench_startup.insert_stages` per revision (imports / work / rest).
Prints medians and the 1-minute load average seen during the runs; writes the raw numbers to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_startup import EXE, insert_stages, time_process  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", type=Path, required=True)
    ap.add_argument("--new", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--stage-runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "startup_old_new.json")
    args = ap.parse_args()
    revs = {"old": str(args.old), "new": str(args.new)}
    res = {r: {"insert": [], "help": []} for r in revs}
    loads = []
    env0 = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.runs):
            for r in list(revs) if i % 2 == 0 else list(revs)[::-1]:
                os.environ["PYTHONPATH"] = revs[r]
                res[r]["insert"].append(time_process([EXE, "insert", "--scene", "sample-sunny", "--out",
                                                      f"{tmp}/{r}_{i}"]))
                res[r]["help"].append(time_process([EXE, "--help"]))
                loads.append(os.getloadavg()[0])
        stages = {}
        for r in revs:
            os.environ["PYTHONPATH"] = revs[r]
            stages[r] = insert_stages(tmp, args.stage_runs) if args.stage_runs else {}
    os.environ.clear()
    os.environ.update(env0)
    for r in revs:
        for cmd in ("insert", "help"):
            wall, cpu = ([x[j] for x in res[r][cmd]] for j in (0, 1))
            print(f"{r} {cmd}: median wall {statistics.median(wall):.2f} s, cpu {statistics.median(cpu):.2f} s "
                  f"(walls {', '.join(f'{x:.2f}' for x in wall)})")
        if stages[r]:
            print(f"{r} stages: " + ", ".join(f"{k} {v:.2f}" for k, v in stages[r].items() if not isinstance(v, dict)))
            print("   imports: " + ", ".join(f"{k} {v:.3f}" for k, v in stages[r]["import_by_package_s"].items()))
    print(f"load average (1 min) during the runs: median {statistics.median(loads):.1f}, "
          f"range {min(loads):.1f}-{max(loads):.1f} (2 cores)")
    args.out.write_text(json.dumps({"revisions": revs, "runs": res, "stages": stages, "load_1min": loads},
                                   indent=1) + "\n")


if __name__ == "__main__":
    main()
