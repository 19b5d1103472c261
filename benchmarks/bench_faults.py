"""Bad inputs and faults, run as a user would: exit code, message, peak memory and what was written, per case.

Usage: ``python benchmarks/bench_faults.py [--cases a,b] [--real-bombs] [--out benchmarks/results/faults.json]
[--label after]``

Every case (``tests/fault_cases.py``) is built from the bundled sample scenes or from assets made on the spot,
then ``python -m streetaug.cli ...`` runs in its own process under ``/usr/bin/time`` (peak RSS). Recorded: the
exit code, the last line on stderr, the wall time, the peak memory, files written or changed outside ``--out``,
the summary's counts and, for the collision case, how many images the ok rows point to. ``--real-bombs`` makes the
texture and image bombs real PNGs (13000^2 and 20000^2, written row by row) instead of header-only ones.
``--child-pythonpath DIR`` runs the commands on another checkout (e.g. a shim folder whose ``streetaug/``
links to an older tree): the "before" column.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import fault_cases as fc  # noqa: E402


def snapshot(folder: Path, skip: Path) -> dict[str, str]:
    files = {}
    for p in folder.rglob("*"):
        if p.is_file() and not p.is_relative_to(skip):
            files[str(p.relative_to(folder))] = hashlib.sha1(p.read_bytes()).hexdigest()
    return files


def run_one(case: fc.FaultCase, tmp: Path, env: dict[str, str], timeout_s: float = 600) -> dict:
    before = snapshot(tmp, case.out)
    cmd = ["/usr/bin/time", "-f", "PEAK_KB %M", sys.executable, "-m", "streetaug.cli", *case.argv]
    t0 = time.perf_counter()
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for _ in range(case.concurrent)]
    results = []
    for p in procs:
        try:
            out, err = p.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
        results.append((p.returncode, err))
    seconds = time.perf_counter() - t0
    rows = []
    for code, err in results:
        lines = [line for line in err.splitlines() if line.strip()]
        peak = [int(line.split()[1]) for line in lines if line.startswith("PEAK_KB")]
        lines = [line for line in lines if not line.startswith("PEAK_KB") and "Command exited" not in line]
        rows.append({"exit": code, "message": (lines[-1] if lines else "")[:300],
                     "peak_mb": round(peak[0] / 1024) if peak else None})
    after = snapshot(tmp, case.out)
    record = {"case": case.name, "what": case.what, "seconds": round(seconds, 1), "runs": rows,
              "written_outside_out": sorted(k for k in after if before.get(k) != after[k])[:10]}
    summary = case.out / "summary.json"
    if summary.is_file():
        record["counts"] = json.loads(summary.read_text()).get("counts")
    log = case.out / "augment_log.jsonl"
    if log.is_file():
        entries = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
        keys = [(e.get("sample_token"), e.get("camera")) for e in entries]
        record["log_rows"] = len(entries)
        record["duplicate_log_rows"] = len(keys) - len(set(keys))
        reasons = [e.get("reason") for e in entries if e.get("status") != "ok" and e.get("reason")]
        record["log_reasons"] = sorted(set(r[:200] for r in reasons))[:3]
    images = [p for p in (case.out / "samples").rglob("*.jpg")] if (case.out / "samples").is_dir() else []
    record["images_written"] = len(images)
    return record


def build_cases(tmp: Path, real_bombs: bool) -> list[tuple[fc.FaultCase, Path]]:
    cases = []

    def add(builder, *args, **kw):
        folder = Path(tempfile.mkdtemp(dir=tmp))
        cases.append((builder(folder, *args, **kw), folder))

    add(fc.case_basename_collision)
    add(fc.case_filename_escapes_batch)
    add(fc.case_filename_absolute_insert)
    for sub in (".", fc.VERSION, "samples/CAM_FRONT"):
        add(fc.case_insert_out_is_source, sub)
    add(fc.case_texture_bomb, 13000, real_bombs)
    add(fc.case_texture_bomb, 9000, real_bombs)
    add(fc.case_huge_image, 20000, real_bombs)
    add(fc.case_all_images_corrupt)
    add(fc.case_one_camera_corrupt)
    add(fc.case_broken_asset_in_folder)
    add(fc.case_duplicate_cameras)
    for name, args in {"ev-nan": ["--ev", "nan"], "ev-1e308": ["--ev", "1e308"],
                       "yaw-sigma-nan": ["--yaw-sigma", "nan"]}.items():
        add(fc.case_option, name, args)
    add(fc.case_concurrent_batches, 2)
    add(fc.case_lidar_nan)
    for name, (table, edit) in fc.table_cases().items():
        add(fc.case_table_field, name, table, edit)
    add(fc.case_data_uri, "bad-base64", "data:application/octet-stream;base64,@@@@")
    add(fc.case_data_uri, "not-base64", "data:application/octet-stream,abc")
    add(fc.case_deep_map)
    return cases


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="", help="comma-separated case names (default: all)")
    ap.add_argument("--real-bombs", action="store_true")
    ap.add_argument("--label", default="after")
    ap.add_argument("--child-pythonpath", default="", help="PYTHONPATH of the streetaug processes run")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "faults.json"))
    args = ap.parse_args()
    wanted = set(filter(None, args.cases.split(",")))
    with tempfile.TemporaryDirectory() as tmp_name:
        records = []
        for case, folder in build_cases(Path(tmp_name), args.real_bombs):
            if wanted and case.name not in wanted:
                continue
            env = dict(os.environ, PYTHONPATH=args.child_pythonpath) if args.child_pythonpath else dict(os.environ)
            record = run_one(case, folder, env)
            records.append(record)
            run = record["runs"][0]
            print(f"{case.name:40s} exit {run['exit']}  {run['peak_mb']} MB  {record['seconds']} s  "
                  f"{run['message'][:110]}  {record.get('counts', '')} {record.get('log_reasons', '')}"[:400], flush=True)
    path = Path(args.out)
    doc = json.loads(path.read_text()) if path.is_file() else {}
    doc[args.label] = {"child_pythonpath": args.child_pythonpath, "cases": records}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()
