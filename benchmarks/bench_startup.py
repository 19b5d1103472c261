"""Start-up cost of the ``streetaug`` CLI: wall and CPU (user+sys of the child) seconds, medians of N runs.

Runs ``streetaug --help`` and the README's bundled ``insert`` example as fresh processes and writes
benchmarks/results/startup.json (or --out). Usage: python benchmarks/bench_startup.py [--runs 5] [--label before]

``insert_stages`` splits the insert process (medians of ``--stage-runs`` runs under ``-X importtime``, which
itself adds some time): ``import_s`` (every module's own import time, summed, and per top-level package),
``work_s`` (``labels.json`` ``timing_s``: lighting, placement, render ... as the pipeline measures them),
``read_sample_s`` (opening the bundled dataset and building the sample, timed in a separate process after
its imports) and ``rest_s`` = wall - import - work (interpreter start, reading the dataset, image decoding
and encoding, writing the outputs).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXE = str(Path(sys.executable).with_name("streetaug"))
COMMANDS = {
    "help": [EXE, "--help"],
    "predict_light_help": [EXE, "predict-light", "--help"],
    "insert_sample_sunny": [EXE, "insert", "--scene", "sample-sunny", "--out", "{out}"],
}


def time_process(argv: list[str]) -> tuple[float, float]:
    """Run argv once; return (wall_s, cpu_s) where cpu_s is the child's user+sys time."""
    before = os.times()
    start = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall_s = time.perf_counter() - start
    after = os.times()
    cpu_s = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return wall_s, cpu_s


_IMPORT_LINE = re.compile(r"import time:\s+(\d+) \|\s+\d+ \| *(\S+)")
_READ_SAMPLE = """
import time
from streetaug.datasets import BUNDLED_VERSION, NuScenesReader, bundled_dataroot
start = time.perf_counter()
reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
sample = reader.sample(reader.sample_tokens("sample-sunny")[0])
print(time.perf_counter() - start)
"""


def import_seconds(importtime_stderr: str) -> dict[str, float]:
    """Package -> summed own import time (s) from ``-X importtime`` output; ``streetaug.*`` by subpackage."""
    by_package: collections.Counter = collections.Counter()
    for match in _IMPORT_LINE.finditer(importtime_stderr):
        parts = match.group(2).split(".")
        key = ".".join(parts[:3]) if parts[0] == "streetaug" else parts[0]
        by_package[key] += int(match.group(1)) * 1e-6
    return dict(by_package)


def insert_stages(tmp: str, runs: int) -> dict:
    """Medians of the insert process's import / work / rest split (see the module docstring)."""
    argv = [sys.executable, "-X", "importtime", "-m", "streetaug.cli", "insert", "--scene", "sample-sunny"]
    rows, packages = [], collections.defaultdict(list)
    for run in range(runs):
        out = Path(tmp) / f"stages_{run}"
        start = time.perf_counter()
        done = subprocess.run(argv + ["--out", str(out)], check=True, capture_output=True, text=True)
        wall_s = time.perf_counter() - start
        imports = import_seconds(done.stderr)
        timing = json.loads((out / "labels.json").read_text())["timing_s"]
        read_s = float(subprocess.run([sys.executable, "-c", _READ_SAMPLE], check=True, capture_output=True,
                                      text=True).stdout)
        rows.append({"wall_s": wall_s, "import_s": sum(imports.values()), "work_s": timing["total"],
                     "read_sample_s": read_s, "rest_s": wall_s - sum(imports.values()) - timing["total"],
                     **{f"work.{k}": v for k, v in timing.items() if k != "total" and "." not in k}})
        for name, seconds in imports.items():
            packages[name].append(seconds)
    medians = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    top = sorted(packages, key=lambda n: -statistics.median(packages[n]))[:15]
    medians["import_by_package_s"] = {n: statistics.median(packages[n]) for n in top}
    return medians


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--label", default="before")
    parser.add_argument("--stage-runs", type=int, default=3, help="Runs of the insert stage split (0: none).")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "startup.json")
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, template in COMMANDS.items():
            walls, cpus = [], []
            for run in range(args.runs):
                argv = [a.replace("{out}", f"{tmp}/{name}_{run}") for a in template]
                wall_s, cpu_s = time_process(argv)
                walls.append(wall_s)
                cpus.append(cpu_s)
            results[name] = {"median_wall_s": statistics.median(walls), "median_cpu_s": statistics.median(cpus),
                             "wall_s": walls, "cpu_s": cpus}
            print(f"{name}: wall {results[name]['median_wall_s']:.2f} s, cpu {results[name]['median_cpu_s']:.2f} s")
        stages = insert_stages(tmp, args.stage_runs) if args.stage_runs else None
        if stages:
            print("insert stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in stages.items() if not isinstance(v, dict)))
            print("  imports: " + ", ".join(f"{k} {v:.2f}" for k, v in stages["import_by_package_s"].items()))
    existing = json.loads(args.out.read_text()) if args.out.exists() else {}
    existing[args.label] = {"runs": args.runs, "load_avg": os.getloadavg(), "commands": results,
                            **({"insert_stages": stages} if stages else {})}
    args.out.write_text(json.dumps(existing, indent=2) + "\n")


if __name__ == "__main__":
    main()
