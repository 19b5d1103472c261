"""Reading one sample of a trainval-sized dataset: indexed tables (cold, warm) against parsing them whole.

Writes a synthetic nuScenes table set under ``--root`` (default /tmp/streetaug_bench_tables; reused when
the same ``--scale`` was written before) with the trainval row counts times ``--scale``: 34,149 samples in
scenes of 40, 77 ``sample_data`` rows per sample (6 cameras x 6, LIDAR_TOP x 11, 5 radars x 6; keyframe
and sweeps, ``prev`` / ``next`` chains per channel), one ``ego_pose`` per ``sample_data``, 34 annotations
per sample (68 instances per scene). Rows have the bundled examples' fields, written as they are
(``json.dumps(row, indent=1, sort_keys=True)``: checked), random tokens; the big tables' rows are in random
order. No image or LiDAR files: ``sample()`` does not read them.

Then times, in fresh processes, ``NuScenesReader(root, version, with_map=False).sample(token)`` of one
sample in the middle: ``cold`` (no index cached: the scans are part of it), ``warm`` (the indexes cached by
the cold run) and ``full_parse`` (``index_min_bytes=None``: every table parsed whole, as before), interleaved,
``--runs`` each. Per run: wall s (parent clock, whole process), CPU s and peak RSS (``os.wait4`` rusage of
the child: ``ru_maxrss``), and the child's own seconds for open + sample. Medians go to ``--out``
(benchmarks/results/table_reading_s14.json). Usage::

    python benchmarks/bench_table_reading.py [--scale 1.0] [--runs 3] [--modes cold,warm,full_parse]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / "examples" / "nuscenes-samples" / "v1.0-samples"
VERSION = "v1.0-trainval-synthetic"
GENERATOR = 1  # bump when the generated tables change

TRAINVAL_SAMPLES = 34149
SAMPLES_PER_SCENE = 40
ANNOTATIONS_PER_SAMPLE = 34
CAMERAS = ("CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_FRONT_LEFT")
RADARS = ("RADAR_FRONT", "RADAR_FRONT_LEFT", "RADAR_FRONT_RIGHT", "RADAR_BACK_LEFT", "RADAR_BACK_RIGHT")
CHANNELS = CAMERAS + ("LIDAR_TOP",) + RADARS
ROWS_PER_SAMPLE = {**{c: 6 for c in CAMERAS}, "LIDAR_TOP": 11, **{r: 6 for r in RADARS}}  # 77 in all
SAMPLE_PERIOD_US = 500_000
T0_US = 1_533_000_000_000_000


# ---------------------------------------------------------------------------- writing the tables


def tokens(rng: np.random.Generator, n: int) -> list[str]:
    """n random 32-hex-digit tokens."""
    text = rng.bytes(16 * n).hex()
    return [text[32 * i: 32 * i + 32] for i in range(n)]


def number_list(values, indent: str) -> str:
    """A JSON list of numbers as ``json.dumps(indent=1)`` lays it out at depth ``len(indent)``."""
    return "[\n" + ",\n".join(f"{indent} {v!r}" for v in values) + f"\n{indent}]"


def write_rows(path: Path, columns: dict[str, list[str]], order: np.ndarray) -> int:
    """Write rows (columns of JSON-encoded values, key order sorted) in ``order``; bytes written."""
    keys = sorted(columns)
    cols = [columns[k] for k in keys]
    heads = [f'  "{k}": ' for k in keys]
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as f:
        f.write("[\n")
        for start in range(0, len(order), 100_000):
            chunk = order[start: start + 100_000].tolist()
            text = ",\n".join(" {\n" + ",\n".join(h + c[i] for h, c in zip(heads, cols)) + "\n }" for i in chunk)
            f.write(("" if start == 0 else ",\n") + text)
        f.write("\n]")
    os.replace(tmp, path)
    return path.stat().st_size


def write_small(path: Path, rows: list[dict]) -> None:
    path.write_text(json.dumps(rows, indent=1, sort_keys=True))


def same_fields(name: str, columns: dict) -> None:
    """The generated rows of ``name`` have exactly the fields of the bundled examples' rows."""
    bundled = set(json.loads((BUNDLED / f"{name}.json").read_text())[0])
    if set(columns) != bundled:
        raise SystemExit(f"{name}: generated fields {sorted(columns)} differ from the bundled {sorted(bundled)}")


def generate(table_dir: Path, scale: float, seed: int = 0) -> dict:
    """Write the synthetic table set; returns row counts and file sizes."""
    rng = np.random.default_rng(seed)
    table_dir.mkdir(parents=True, exist_ok=True)
    n_samples = max(SAMPLES_PER_SCENE, int(round(TRAINVAL_SAMPLES * scale)))
    n_scenes = -(-n_samples // SAMPLES_PER_SCENE)
    sample_tok, scene_tok = tokens(rng, n_samples), tokens(rng, n_scenes)
    scene_of = np.arange(n_samples) // SAMPLES_PER_SCENE
    n_logs = min(68, n_scenes)
    log_tok = tokens(rng, n_logs)
    sizes = {}

    sensors = [{"channel": c, "modality": "camera" if c.startswith("CAM") else c.split("_")[0].lower(),
                "token": t} for c, t in zip(CHANNELS, tokens(rng, len(CHANNELS)))]
    write_small(table_dir / "sensor.json", sensors)
    calib_tok = np.array(tokens(rng, n_scenes * len(CHANNELS)), dtype=object).reshape(n_scenes, len(CHANNELS))
    calib = []
    for s in range(n_scenes):
        for c, sensor in enumerate(sensors):
            camera = sensor["modality"] == "camera"
            calib.append({"camera_intrinsic": [[1266.417, 0.0, 816.267], [0.0, 1266.417, 491.507], [0.0, 0.0, 1.0]]
                          if camera else [], "rotation": [0.5, -0.5, 0.5, -0.5] if camera else [1.0, 0.0, 0.0, 0.0],
                          "sensor_token": sensor["token"], "token": calib_tok[s, c],
                          "translation": [1.7, 0.01 * c, 1.5]})
    write_small(table_dir / "calibrated_sensor.json", calib)
    for name in ("category", "attribute", "visibility"):
        shutil.copyfile(BUNDLED / f"{name}.json", table_dir / f"{name}.json")
    categories = [r["token"] for r in json.loads((BUNDLED / "category.json").read_text()) if "vehicle" in r["name"]]
    attribute = json.loads((BUNDLED / "attribute.json").read_text())[0]["token"]
    write_small(table_dir / "log.json", [{"date_captured": "2018-08-01", "location": "boston-seaport",
                                          "logfile": f"n008-2018-08-01-00-00-00-{i:04d}", "token": t, "vehicle": "n008"}
                                         for i, t in enumerate(log_tok)])
    write_small(table_dir / "map.json", [{"category": "semantic_prior", "filename": "", "log_tokens": log_tok,
                                          "token": tokens(rng, 1)[0]}])
    write_small(table_dir / "scene.json", [{
        "description": "synthetic", "first_sample_token": sample_tok[s * SAMPLES_PER_SCENE],
        "last_sample_token": sample_tok[min(n_samples, (s + 1) * SAMPLES_PER_SCENE) - 1], "log_token": log_tok[s % n_logs],
        "name": f"scene-{s:04d}", "nbr_samples": int(np.sum(scene_of == s)), "token": scene_tok[s]}
        for s in range(n_scenes)])
    write_small(table_dir / "sample.json", [{
        "next": sample_tok[i + 1] if i + 1 < n_samples and scene_of[i + 1] == scene_of[i] else "",
        "prev": sample_tok[i - 1] if i > 0 and scene_of[i - 1] == scene_of[i] else "",
        "scene_token": scene_tok[scene_of[i]], "timestamp": T0_US + i * SAMPLE_PERIOD_US, "token": sample_tok[i]}
        for i in range(n_samples)])

    # sample_data and ego_pose: one row per (sample, channel, k)
    channel_of_slot = np.repeat(np.arange(len(CHANNELS)), [ROWS_PER_SAMPLE[c] for c in CHANNELS])
    k_of_slot = np.concatenate([np.arange(ROWS_PER_SAMPLE[c]) for c in CHANNELS])
    per = len(channel_of_slot)
    sample = np.repeat(np.arange(n_samples), per)
    channel, k = np.tile(channel_of_slot, n_samples), np.tile(k_of_slot, n_samples)
    scene = scene_of[sample]
    n_sd = len(sample)
    sd_tok = tokens(rng, n_sd)
    counts = np.array([ROWS_PER_SAMPLE[c] for c in CHANNELS])[channel]
    timestamp = T0_US + sample * SAMPLE_PERIOD_US + (k * SAMPLE_PERIOD_US) // counts + channel * 1000
    seq = np.lexsort((k, sample, channel, scene))
    same = np.zeros(n_sd, dtype=bool)
    same[1:] = (scene[seq][1:] == scene[seq][:-1]) & (channel[seq][1:] == channel[seq][:-1])
    prev, nxt = np.full(n_sd, -1), np.full(n_sd, -1)
    prev[seq[1:][same[1:]]] = seq[:-1][same[1:]]
    nxt[seq[:-1][same[1:]]] = seq[1:][same[1:]]
    quoted = [f'"{t}"' for t in sd_tok]
    keyframe = k == 0
    names = np.array(CHANNELS)[channel]
    is_cam = channel < len(CAMERAS)
    columns = {
        "calibrated_sensor_token": [f'"{calib_tok[s, c]}"' for s, c in zip(scene.tolist(), channel.tolist())],
        "ego_pose_token": quoted,
        "fileformat": ['"jpg"' if c else '"pcd"' for c in is_cam.tolist()],
        "filename": [f'"{"samples" if kf else "sweeps"}/{ch}/n008-2018-08-01-00-00-00-0400__{ch}__{t}.'
                     f'{"jpg" if cam else "pcd.bin" if ch == "LIDAR_TOP" else "pcd"}"'
                     for kf, ch, t, cam in zip(keyframe.tolist(), names.tolist(), timestamp.tolist(), is_cam.tolist())],
        "height": ["900" if c else "0" for c in is_cam.tolist()],
        "is_key_frame": ["true" if kf else "false" for kf in keyframe.tolist()],
        "next": [quoted[j] if j >= 0 else '""' for j in nxt.tolist()],
        "prev": [quoted[j] if j >= 0 else '""' for j in prev.tolist()],
        "sample_token": [f'"{sample_tok[s]}"' for s in sample.tolist()],
        "timestamp": [str(t) for t in timestamp.tolist()],
        "token": quoted,
        "width": ["1600" if c else "0" for c in is_cam.tolist()],
    }
    same_fields("sample_data", columns)
    order = rng.permutation(n_sd)
    sizes["sample_data"] = write_rows(table_dir / "sample_data.json", columns, order)
    del columns
    yaw = (timestamp - T0_US) * 1e-7
    x, y = np.round(1000 + 5 * yaw, 6), np.round(500 + 3 * yaw, 6)
    qw, qz = np.round(np.cos(yaw / 2), 10), np.round(np.sin(yaw / 2), 10)
    columns = {"rotation": [number_list((w, 0.0, 0.0, z), "  ") for w, z in zip(qw.tolist(), qz.tolist())],
               "timestamp": [str(t) for t in timestamp.tolist()], "token": quoted,
               "translation": [number_list((a, b, 0.0), "  ") for a, b in zip(x.tolist(), y.tolist())]}
    same_fields("ego_pose", columns)
    sizes["ego_pose"] = write_rows(table_dir / "ego_pose.json", columns, rng.permutation(n_sd))
    del columns, quoted

    # sample_annotation and instance: 34 per sample, instances of 20 consecutive samples of a scene
    n_ann = n_samples * ANNOTATIONS_PER_SAMPLE
    a_sample = np.repeat(np.arange(n_samples), ANNOTATIONS_PER_SAMPLE)
    a_slot = np.tile(np.arange(ANNOTATIONS_PER_SAMPLE), n_samples)
    group = (a_sample % SAMPLES_PER_SCENE) // 20
    instance = (scene_of[a_sample] * 2 + group) * ANNOTATIONS_PER_SAMPLE + a_slot
    n_inst = int(instance.max()) + 1
    inst_tok, ann_tok = tokens(rng, n_inst), tokens(rng, n_ann)
    seq = np.lexsort((a_sample, instance))
    same = np.zeros(n_ann, dtype=bool)
    same[1:] = instance[seq][1:] == instance[seq][:-1]
    prev, nxt = np.full(n_ann, -1), np.full(n_ann, -1)
    prev[seq[1:][same[1:]]] = seq[:-1][same[1:]]
    nxt[seq[:-1][same[1:]]] = seq[1:][same[1:]]
    quoted = [f'"{t}"' for t in ann_tok]
    centre = rng.uniform(0, 2000, size=(n_ann, 2)).round(3)
    heading = rng.uniform(-np.pi, np.pi, n_ann)
    qw, qz = np.round(np.cos(heading / 2), 10), np.round(np.sin(heading / 2), 10)
    columns = {
        "attribute_tokens": [f'[\n   "{attribute}"\n  ]'] * n_ann,
        "instance_token": [f'"{inst_tok[i]}"' for i in instance.tolist()],
        "next": [quoted[j] if j >= 0 else '""' for j in nxt.tolist()],
        "num_lidar_pts": [str(v) for v in rng.integers(0, 500, n_ann).tolist()],
        "num_radar_pts": [str(v) for v in rng.integers(0, 10, n_ann).tolist()],
        "prev": [quoted[j] if j >= 0 else '""' for j in prev.tolist()],
        "rotation": [number_list((w, 0.0, 0.0, z), "  ") for w, z in zip(qw.tolist(), qz.tolist())],
        "sample_token": [f'"{sample_tok[s]}"' for s in a_sample.tolist()],
        "size": [number_list((1.9, 4.6, 1.7), "  ")] * n_ann,
        "token": quoted,
        "translation": [number_list((a, b, 0.9), "  ") for a, b in centre.tolist()],
        "visibility_token": ['"4"'] * n_ann,
    }
    same_fields("sample_annotation", columns)
    sizes["sample_annotation"] = write_rows(table_dir / "sample_annotation.json", columns, rng.permutation(n_ann))
    del columns
    first = np.full(n_inst, -1)
    last = np.full(n_inst, -1)
    first[instance[seq][~same]] = seq[~same]
    ends = np.ones(n_ann, dtype=bool)
    ends[:-1] = ~same[1:]
    last[instance[seq][ends]] = seq[ends]
    columns = {"category_token": [f'"{categories[i % len(categories)]}"' for i in range(n_inst)],
               "first_annotation_token": [quoted[j] for j in first.tolist()],
               "last_annotation_token": [quoted[j] for j in last.tolist()],
               "nbr_annotations": [str(v) for v in np.bincount(instance, minlength=n_inst).tolist()],
               "token": [f'"{t}"' for t in inst_tok]}
    same_fields("instance", columns)
    sizes["instance"] = write_rows(table_dir / "instance.json", columns, rng.permutation(n_inst))

    for name in ("sample_data", "ego_pose", "sample_annotation"):  # the layout is json.dumps(indent=1)'s
        with open(table_dir / f"{name}.json") as f:
            head = f.read(20000)
        first_row = head[2: head.index("\n }") + 3]
        if " " + json.dumps(json.loads(first_row), indent=1, sort_keys=True).replace("\n", "\n ") != first_row:
            raise SystemExit(f"{name}: generated rows are not laid out as json.dumps(indent=1) lays them out")
    middle = sample_tok[n_samples // 2]
    return {"scale": scale, "generator": GENERATOR, "samples": n_samples, "scenes": n_scenes, "sample_data": n_sd,
            "ego_pose": n_sd, "sample_annotation": n_ann, "instance": n_inst, "bytes": sizes, "token": middle,
            "boxes": ANNOTATIONS_PER_SAMPLE}


# ---------------------------------------------------------------------------- timing


CHILD = """
import hashlib, json, resource, sys, time
t0, c0 = time.perf_counter(), time.process_time()
from streetaug.datasets.nuscenes import NuScenesReader
t1 = time.perf_counter()
root, version, token, indexed = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4] == "1"
reader = NuScenesReader(root, version, with_map=False, **({} if indexed else {"index_min_bytes": None}))
sample = reader.sample(token)
t2 = time.perf_counter()
digest = hashlib.sha256(json.dumps([sorted((c, v.sample_data_token, v.T_global_from_ego.round(9).tolist(),
                                            repr(v.ego_poses_around)) for c, v in sample.cameras.items()),
                                    [(b.token, b.center.tolist(), b.wlh.tolist()) for b in sample.boxes]]).encode())
hwm = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:"))
print(json.dumps({"import_s": t1 - t0, "open_and_sample_s": t2 - t1, "cameras": len(sample.cameras),
                  "boxes": len(sample.boxes), "digest": digest.hexdigest(), "vm_hwm_mib": hwm / 1024}))
"""


def timed_child(root: Path, token: str, indexed: bool, cache: Path) -> dict:
    """One fresh process reading the sample: wall s (parent clock), CPU s (``os.wait4`` rusage) and peak RSS MiB
    (the child's ``VmHWM``; its ``ru_maxrss`` is kept too, though it starts from the parent's RSS at fork)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(cache), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", CHILD, str(root), VERSION, token, "1" if indexed else "0"],
                                stdout=out, stderr=err, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if proc.returncode:
            raise SystemExit(f"child failed ({proc.returncode}): {err.read().decode()[-2000:]}")
        result = json.loads(out.read())
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "peak_rss_mib": result.pop("vm_hwm_mib"),
            "ru_maxrss_mib": usage.ru_maxrss / 1024, **result}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="Row counts as a fraction of trainval's.")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--modes", default="cold,warm,full_parse")
    parser.add_argument("--root", type=Path, default=Path("/tmp/streetaug_bench_tables"))
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "table_reading_s14.json")
    parser.add_argument("--label", default=None, help="Key of this run in --out (default: scale_<scale>).")
    parser.add_argument("--generate-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    modes = args.modes.split(",")
    root = args.root / f"scale_{args.scale:g}"
    marker = root / "generated.json"
    if args.generate_only:
        marker.unlink(missing_ok=True)
        info = generate(root / VERSION, args.scale)
        marker.write_text(json.dumps(info, indent=1))
        return
    info = json.loads(marker.read_text()) if marker.is_file() else None
    if info is None or info.get("generator") != GENERATOR or info.get("scale") != args.scale:
        start = time.perf_counter()  # in a process of its own: this one stays small (its children fork it)
        subprocess.run([sys.executable, __file__, "--generate-only", "--scale", str(args.scale), "--root",
                        str(args.root)], check=True)
        info = json.loads(marker.read_text())
        info["generate_s"] = time.perf_counter() - start
        marker.write_text(json.dumps(info, indent=1))
    print(f"tables: {info['samples']} samples, {info['sample_data']} sample_data, {info['sample_annotation']} "
          f"annotations, {info['instance']} instances; MB " +
          ", ".join(f"{k} {v / 1e6:.0f}" for k, v in info["bytes"].items()), flush=True)

    cache = Path(tempfile.mkdtemp(prefix="streetaug_bench_cache_"))
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    try:
        for run in range(args.runs):
            for mode in modes:
                if mode == "cold":
                    shutil.rmtree(cache / "streetaug", ignore_errors=True)
                elif mode == "warm" and not (cache / "streetaug").is_dir():
                    timed_child(root, info["token"], True, cache)  # build the cache first
                result = timed_child(root, info["token"], mode != "full_parse", cache)
                if (result["cameras"], result["boxes"]) != (len(CAMERAS), info["boxes"]):
                    raise SystemExit(f"{mode}: read {result['cameras']} cameras and {result['boxes']} boxes")
                runs[mode].append(result)
                print(f"run {run} {mode}: wall {result['wall_s']:.2f} s, cpu {result['cpu_s']:.2f} s, "
                      f"peak RSS {result['peak_rss_mib']:.0f} MiB (open + sample {result['open_and_sample_s']:.2f} s)",
                      flush=True)
        cache_bytes = {p.name: p.stat().st_size for p in (cache / "streetaug" / "tables").glob("*.npz")} \
            if (cache / "streetaug" / "tables").is_dir() else {}
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    digests = {r["digest"] for rs in runs.values() for r in rs}
    if len(digests) != 1:
        raise SystemExit(f"the modes read different samples: {digests}")
    summary = {m: {f"median_{k}": statistics.median(r[k] for r in rs)
                   for k in ("wall_s", "cpu_s", "peak_rss_mib", "open_and_sample_s", "import_s")}
               for m, rs in runs.items()}
    for m, s in summary.items():
        print(f"{m}: wall {s['median_wall_s']:.2f} s, cpu {s['median_cpu_s']:.2f} s, peak RSS "
              f"{s['median_peak_rss_mib']:.0f} MiB")
    existing = json.loads(args.out.read_text()) if args.out.exists() else {}
    existing[args.label or f"scale_{args.scale:g}"] = {
        "dataset": {k: v for k, v in info.items() if k != "token"}, "sample_token": info["token"],
        "runs": args.runs, "modes": summary, "per_run": {m: [{k: v for k, v in r.items() if k != "digest"} for r in rs]
                                                         for m, rs in runs.items()},
        "index_cache_bytes": cache_bytes, "same_sample_in_every_mode": True, "load_avg": os.getloadavg(),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
    }
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text(json.dumps(existing, indent=1) + "\n")
    os.replace(tmp, args.out)


if __name__ == "__main__":
    main()
