"""Start-up cost of the ``streetaug`` CLI: wall and CPU (user+sys of the child) seconds, medians of N runs.

Runs ``streetaug --help`` and the README's bundled ``insert`` example as fresh processes and writes
benchmarks/results/startup.json (or --out). Usage: python benchmarks/bench_startup.py [--runs 5] [--label before]
"""

from __future__ import annotations

import argparse
import json
import os
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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--label", default="before")
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
    existing = json.loads(args.out.read_text()) if args.out.exists() else {}
    existing[args.label] = {"runs": args.runs, "load_avg": os.getloadavg(), "commands": results}
    args.out.write_text(json.dumps(existing, indent=2) + "\n")


if __name__ == "__main__":
    main()
