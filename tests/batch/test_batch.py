"""``streetaug batch``: a nuScenes dataset the devkit loads, the same output whatever the executor, crash-safe resume.

One inline run on the bundled scenes is the reference; 2 local processes, a 2-worker Dask LocalCluster,
shards + merge, and a run SIGKILLed then resumed must all reproduce it exactly (images byte for byte,
tables, labels and log rows without their timings).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import devkit
from streetaug.augment.batch import BatchConfig, LogRow, RunOptions, merge, read_log, run_batch
from streetaug.augment.batch.config import load_config
from streetaug.augment.batch.execute import init_pool_worker, tune_malloc
from streetaug.augment.core import InputError
from streetaug.cli.main import main
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.nuscenes_format import new_token

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "nuscenes-real"
CAMERAS = ("CAM_FRONT", "CAM_BACK")
N_SAMPLES = 2  # of the 3 bundled scenes: enough for 2 workers and shards, fast
# file_checks: the sha256 of each output, labels.json included, whose "timing_s" varies (the images' and
# sweeps' bytes are compared by tree_hash)
VOLATILE = ("timing_s", "seconds", "cpu_s", "worker", "peak_rss_mb", "file_checks", "task_span")
QUIET = dict(progress=False, contact_sheet=4)


def config(**kw) -> BatchConfig:
    values = dict(dataroot=str(bundled_dataroot().resolve()), version=BUNDLED_VERSION, cameras=CAMERAS,
                  quality="draft", seed=0, limit=N_SAMPLES)
    values.update(kw)
    return BatchConfig(**values)


def log_json(path: Path) -> list[dict]:
    """The lines of a log as the file contract has them (JSON objects)."""
    return [json.loads(line) for line in path.read_text().splitlines()]


def tree_hash(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def digest(out: Path) -> dict:
    """Everything a run produces that must not depend on workers, order or interruptions."""
    files = {}
    for folder in ("samples", BUNDLED_VERSION, "v1.0-mini"):
        for p in sorted((out / folder).rglob("*")):
            if p.is_file():
                files[str(p.relative_to(out))] = hashlib.sha256(p.read_bytes()).hexdigest()
    for p in sorted((out / "labels").rglob("*.json")):
        doc = json.loads(p.read_text())
        doc.pop("timing_s")
        files[str(p.relative_to(out))] = doc
    rows = sorted(json.dumps({k: v for k, v in r.items() if k not in VOLATILE}, sort_keys=True)
                  for r in log_json(out / "augment_log.jsonl"))
    return {"files": files, "log": rows}


def assert_same_output(out: Path, reference_out: Path) -> None:
    a, b = digest(out), digest(reference_out)
    differ = sorted(k for k in set(a["files"]) | set(b["files"]) if a["files"].get(k) != b["files"].get(k))
    assert not differ, f"files differ from the reference: {differ[:5]}"
    extra, missing = sorted(set(a["log"]) - set(b["log"])), sorted(set(b["log"]) - set(a["log"]))
    assert a["log"] == b["log"], f"log rows differ: {extra[:2]} instead of {missing[:2]}"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Inline run on 2 bundled scenes (CAM_FRONT, CAM_BACK), with the source hashed before and after."""
    out = tmp_path_factory.mktemp("batch") / "inline"
    before = tree_hash(bundled_dataroot())
    summary = run_batch(config(), out, RunOptions(workers=1, **QUIET))
    return out, summary, before, tree_hash(bundled_dataroot())


class TestDataset:
    def test_log_summary_and_files(self, reference):
        out, summary, _, _ = reference
        rows = log_json(out / "augment_log.jsonl")
        assert sorted((r["sample_token"], r["camera"]) for r in rows) == sorted(
            {(r["sample_token"], r["camera"]) for r in rows})  # one line per image
        assert len(rows) == N_SAMPLES * len(CAMERAS) == summary["images"]
        assert {r["status"] for r in rows} <= {"ok", "skipped"}
        assert summary["counts"]["ok"] == sum(r["status"] == "ok" for r in rows) >= N_SAMPLES
        for r in rows:
            assert set(r["timing_s"]) >= {"placement", "lighting", "total"}
            assert r["status"] == "skipped" or (out / r["image"]).is_file() and r["reason"] == ""
        assert summary["objects_inserted"] == sum(len(r["objects"]) for r in rows) >= N_SAMPLES
        assert (out / "contact_sheet.png").is_file() and (out / "batch_config.json").is_file()

    def test_log_lines_carry_the_contract_keys(self, reference):
        for doc in log_json(reference[0] / "augment_log.jsonl"):
            assert {"sample_token", "camera", "status", "reason", "timing_s"} <= set(doc)
            assert doc["status"] in ("ok", "skipped", "failed") and isinstance(doc["timing_s"]["total"], float)

    def test_log_rows_round_trip(self, reference):
        """Every line reads into a LogRow and back into the same JSON, unknown keys included."""
        for doc in log_json(reference[0] / "augment_log.jsonl"):
            assert LogRow.from_json(doc).to_json() == doc
            newer = {**doc, "added_by_a_newer_version": {"x": 1}}
            assert LogRow.from_json(newer).to_json() == newer

    def test_source_is_never_written(self, reference):
        _, _, before, after = reference
        assert before == after

    def test_tables_extend_the_source(self, reference):
        out, summary, _, _ = reference
        src, new = bundled_dataroot() / BUNDLED_VERSION, out / BUNDLED_VERSION
        table = lambda root, name: json.loads((root / f"{name}.json").read_text())  # noqa: E731
        n = summary["objects_inserted"]
        assert len(table(new, "sample_annotation")) == len(table(src, "sample_annotation")) + n
        assert len(table(new, "instance")) == len(table(src, "instance")) + n
        rows = log_json(out / "augment_log.jsonl")
        ok = {r["sample_data_token"]: r["image"] for r in rows if r["status"] == "ok"}
        ok.update({r["lidar"]["sample_data_token"]: r["lidar"]["file"] for r in rows if r.get("lidar")})
        assert len(ok) > len({r["image"] for r in rows if r["status"] == "ok"})  # the LiDAR sweeps too
        for row in table(new, "sample_data"):
            if row["token"] in ok:
                assert row["filename"] == ok[row["token"]] and row["source_filename"].startswith("samples/")
            else:
                assert row["filename"].startswith("source/")
            assert (out / row["filename"]).is_file()
        for name in ("ego_pose", "calibrated_sensor", "scene", "sample"):
            assert table(new, name) == table(src, name)


class TestDevkit:
    def test_devkit_loads_boxes_and_renders(self, reference, tmp_path):
        nuscenes = devkit()
        out, _, _, _ = reference
        nusc = nuscenes.NuScenes(version=BUNDLED_VERSION, dataroot=str(out), verbose=False)
        rows = [r for r in log_json(out / "augment_log.jsonl") if r["status"] == "ok"]
        for r in rows:
            path, boxes, K = nusc.get_sample_data(r["sample_data_token"])
            assert Path(path) == out / r["image"]
            labels = json.loads((out / r["files"][1]).read_text())["objects"]
            by_token = {b.token: b for b in boxes}
            for label in labels:
                token = new_token("sample_annotation", 0, r["sample_token"], label["object_index"])
                box = by_token[token]  # the devkit returns our box in this camera's frame
                assert box.name == "vehicle.car"
                np.testing.assert_allclose(box.center, label["box_camera"]["center"], atol=1e-6)
                np.testing.assert_allclose(box.wlh, label["box_camera"]["size_wlh"], atol=1e-9)
                u, v, z = np.asarray(K) @ box.center
                x0, y0, x1, y1 = label["bbox_2d"]
                assert x0 <= u / z <= x1 and y0 <= v / z <= y1
        sample = nusc.get("sample", rows[0]["sample_token"])
        lidar_path = Path(nusc.get_sample_data_path(sample["data"]["LIDAR_TOP"]))
        assert lidar_path == out / rows[0]["lidar"]["file"]  # the sweep with the inserted cars in it
        nusc.render_sample_data(rows[0]["sample_data_token"], out_path=str(tmp_path / "cam.png"), verbose=False)
        nusc.render_sample_data(sample["data"]["LIDAR_TOP"], out_path=str(tmp_path / "lidar.png"), verbose=False,
                                underlay_map=False)
        assert (tmp_path / "cam.png").stat().st_size > 10_000 and (tmp_path / "lidar.png").stat().st_size > 10_000

    @pytest.mark.skipif(not REAL.is_dir(), reason=f"real nuScenes excerpt not found at {REAL}")
    def test_real_sample(self, tmp_path):
        nuscenes = devkit()
        from nuscenes.map_expansion.map_api import NuScenesMap

        before = tree_hash(REAL)
        out = tmp_path / "real"
        result = CliRunner().invoke(main, ["batch", "--dataroot", str(REAL), "--version", "v1.0-mini", "--quality",
                                           "draft", "--workers", "1", "--no-progress", "--out", str(out)],
                                    catch_exceptions=False)
        assert result.exit_code == 0, result.output
        assert tree_hash(REAL) == before
        summary = json.loads((out / "summary.json").read_text())
        assert summary["counts"].get("ok", 0) >= 1 and not summary["counts"].get("failed")
        nusc = nuscenes.NuScenes(version="v1.0-mini", dataroot=str(out), verbose=False)
        sample = nusc.sample[0]
        assert len(sample["anns"]) == 68 + summary["objects_inserted"]
        ok = [r for r in log_json(out / "augment_log.jsonl") if r["status"] == "ok"]
        for r in ok:
            assert Path(nusc.get_sample_data_path(r["sample_data_token"])) == out / r["image"]
        nusc.render_sample_data(ok[0]["sample_data_token"], out_path=str(tmp_path / "cam.png"), verbose=False)
        nusc.render_sample_data(sample["data"]["LIDAR_TOP"], out_path=str(tmp_path / "lidar.png"), verbose=False,
                                underlay_map=False)
        nusc_map = NuScenesMap(dataroot=str(out), map_name="singapore-onenorth")
        assert len(nusc_map.drivable_area) > 0

    def test_lidar_agrees_with_the_boxes(self, reference):
        """Every box's num_lidar_pts (inserted, and source boxes partly hidden behind one) is what the devkit
        counts in the augmented sweep; inserted cars have points; the moved points are cars in the lidarseg."""
        nuscenes = devkit()
        from nuscenes.utils.data_classes import LidarPointCloud
        from nuscenes.utils.geometry_utils import points_in_box

        out = reference[0]
        nusc = nuscenes.NuScenes(version=BUNDLED_VERSION, dataroot=str(out), verbose=False)
        source = nuscenes.NuScenes(version=BUNDLED_VERSION, dataroot=str(bundled_dataroot()), verbose=False)
        car_index = next(c["index"] for c in nusc.category if c["name"] == "vehicle.car")
        inserted_points = []
        for sample in nusc.sample:
            lidar_token = sample["data"]["LIDAR_TOP"]
            path, boxes, _ = nusc.get_sample_data(lidar_token)
            xyz = LidarPointCloud.from_file(path).points[:3]
            src = LidarPointCloud.from_file(source.get_sample_data_path(lidar_token)).points
            assert xyz.shape == src[:3].shape  # same beams, some moved
            labels = np.fromfile(out / nusc.get("lidarseg", lidar_token)["filename"], np.uint8)
            moved = np.any(xyz != src[:3], axis=0)
            in_inserted = np.zeros(len(labels), bool)
            for box in boxes:
                ann = nusc.get("sample_annotation", box.token)
                inside = points_in_box(box, xyz)
                assert ann["num_lidar_pts"] == int(inside.sum()), ann["token"]
                if box.token not in source._token2ind["sample_annotation"]:
                    inserted_points.append(int(inside.sum()))
                    in_inserted |= inside
            assert np.all(labels[moved] == car_index) and np.all(in_inserted[moved])
        assert len(inserted_points) >= N_SAMPLES and min(inserted_points) > 0


class TestSameOutput:
    """Per-item seeds: the output does not depend on the executor, the worker count or interruptions."""

    def test_two_local_processes(self, reference, tmp_path):
        summary = run_batch(config(), tmp_path, RunOptions(workers=2, **QUIET))
        assert "2 local processes" in summary["this_run"]["executor"]
        # Rendered in the spawned workers (which of the two takes which sample depends on their start-up).
        assert all(not r["worker"].endswith(f":{os.getpid()}") for r in log_json(tmp_path / "augment_log.jsonl"))
        assert_same_output(tmp_path, reference[0])

    def test_dask_local_cluster(self, reference, tmp_path):
        pytest.importorskip("distributed", reason="dask distributed not installed (pip install -e '.[test]')")
        summary = run_batch(config(), tmp_path, RunOptions(dask_local=2, **QUIET))
        assert summary["this_run"]["executor"].startswith("Dask")
        assert_same_output(tmp_path, reference[0])

    def test_shards_then_merge(self, reference, tmp_path):
        run_batch(config(), tmp_path, RunOptions(workers=1, shard=(1, 2), **QUIET))
        with pytest.raises(InputError, match="no result"):
            merge(tmp_path)  # shard 0 is missing
        run_batch(config(), tmp_path, RunOptions(workers=1, shard=(0, 2), **QUIET))
        result = CliRunner().invoke(main, ["merge", "--out", str(tmp_path), "--contact-sheet", "4"],
                                    catch_exceptions=False)
        assert result.exit_code == 0, result.output
        assert json.loads((tmp_path / "summary.json").read_text())["this_run"]["merged_shards"] == 2
        assert_same_output(tmp_path, reference[0])

    def test_rerun_redoes_nothing(self, reference, tmp_path):
        shutil.copytree(reference[0], tmp_path / "out", symlinks=True)
        summary = run_batch(config(), tmp_path / "out", RunOptions(workers=1, **QUIET))
        assert summary["this_run"]["samples"] == 0 and summary["this_run"]["resumed_samples"] == N_SAMPLES
        assert_same_output(tmp_path / "out", reference[0])

    def test_sigkill_then_rerun_completes_consistently(self, reference, tmp_path):
        out = tmp_path / "out"
        cmd = [str(Path(sys.executable).with_name("streetaug")), "batch", "--cameras", ",".join(CAMERAS), "--quality",
               "draft", "--limit", str(N_SAMPLES), "--workers", "1", "--no-progress", "--contact-sheet", "4",
               "--out", str(out)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        log = out / "augment_log.jsonl"
        deadline = time.monotonic() + 120
        while not (log.is_file() and log.stat().st_size > 0) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)  # after the first sample, while the second is being rendered/written
        proc.wait()
        assert proc.returncode == -signal.SIGKILL
        assert not (out / "summary.json").exists()
        killed_rows = read_log(log)  # typed rows; a truncated line is skipped
        # What a kill mid-write can leave: a truncated last log line and a temporary image file.
        with open(log, "ab") as f:
            f.write(b'{"camera": "CAM_FRONT", "sample_tok')
        (out / "samples" / "CAM_FRONT").mkdir(parents=True, exist_ok=True)
        (out / "samples" / "CAM_FRONT" / ".x.jpg.abc.tmp.jpg").write_bytes(b"\xff\xd8 half a jpeg")
        rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert rerun.returncode == 0, rerun.stderr
        assert "resuming" in rerun.stderr, (rerun.stderr, killed_rows)
        assert not list(out.glob("samples/*/.*"))
        assert_same_output(out, reference[0])


class TestRobustness:
    def test_failing_sample_is_logged_and_the_run_goes_on(self, tmp_path):
        src = tmp_path / "src"
        shutil.copytree(bundled_dataroot(), src)
        reader = NuScenesReader(src, BUNDLED_VERSION)
        broken = Path(reader.sample(reader.sample_tokens()[0]).cameras["CAM_FRONT"].image_path)
        broken.write_bytes(broken.read_bytes()[:200])  # a truncated JPEG
        cfg = config(dataroot=str(src), cameras=("CAM_FRONT",))
        summary = run_batch(cfg, tmp_path / "out", RunOptions(workers=1, **QUIET))
        rows = log_json(tmp_path / "out" / "augment_log.jsonl")
        failed = [r for r in rows if r["status"] == "failed"]
        assert len(failed) == 1 and broken.name in failed[0]["reason"]
        assert summary["counts"]["failed"] == 1 and summary["counts"].get("ok", 0) >= 1
        with pytest.raises(InputError, match=re.escape(broken.name)):
            run_batch(cfg, tmp_path / "out2", RunOptions(workers=1, fail_fast=True, **QUIET))

    def test_resuming_with_other_options_is_refused(self, reference, tmp_path):
        shutil.copytree(reference[0], tmp_path / "out", symlinks=True)
        with pytest.raises(InputError, match="seed"):
            run_batch(config(seed=1), tmp_path / "out", RunOptions(workers=1, **QUIET))

    def test_output_inside_the_source_is_refused(self, tmp_path):
        src = tmp_path / "src"
        shutil.copytree(bundled_dataroot() / BUNDLED_VERSION, src / BUNDLED_VERSION)
        with pytest.raises(InputError, match="inside the source dataset"):
            run_batch(config(dataroot=str(src)), src / "aug", RunOptions(workers=1, **QUIET))
        assert not (src / "aug").exists()

    def test_unknown_camera_is_a_clear_error(self, tmp_path):
        result = CliRunner().invoke(main, ["batch", "--cameras", "CAM_FRNT", "--out", str(tmp_path)])
        assert result.exit_code == 1 and "CAM_FRNT" in result.output and "CAM_FRONT" in result.output

    def test_dry_run_plans_without_rendering(self, tmp_path):
        summary = run_batch(config(), tmp_path, RunOptions(workers=1, dry_run=True, **QUIET))
        plan = log_json(tmp_path / "plan.jsonl")
        assert len(plan) == N_SAMPLES * len(CAMERAS) and {r["status"] for r in plan} <= {"planned", "no_placement"}
        assert summary["objects_planned"] == sum(len(r["objects"]) for r in plan) >= N_SAMPLES
        assert not (tmp_path / "samples").exists() and not (tmp_path / "augment_log.jsonl").exists()


def test_cli_batch_prints_a_summary(tmp_path):
    result = CliRunner().invoke(main, ["batch", "--cameras", "CAM_FRONT", "--limit", "1", "--quality", "draft",
                                       "--workers", "1", "--no-progress", "--out", str(tmp_path)],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "status:" in result.output and "NuScenes(version='v1.0-samples'" in result.output
    assert json.loads((tmp_path / "summary.json").read_text())["images"] == 1


def test_malloc_tuning_applies_on_glibc():
    """Workers keep image-sized arrays in the heap even under Dask's MALLOC_TRIM_THRESHOLD_ (see tune_malloc)."""
    import platform


    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        pytest.skip("mallopt tuning is glibc-only")
    assert tune_malloc() is True and tune_malloc() is True  # applied, idempotent


def test_config_of_an_older_run_still_resumes(reference, tmp_path):
    """A batch_config.json written before ``match_camera`` existed reads as its default; others stay required."""
    out = tmp_path / "out"
    shutil.copytree(reference[0], out, symlinks=True)
    doc = json.loads((out / "batch_config.json").read_text())
    del doc["match_camera"]
    (out / "batch_config.json").write_text(json.dumps(doc))
    assert load_config(out) == config()
    summary = run_batch(config(), out, RunOptions(workers=1, **QUIET))  # resumes: nothing to redo
    assert summary["this_run"]["images"] == 0
    del doc["quality"]
    (out / "batch_config.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="quality"):
        load_config(out)


def _pid(_: int) -> int:
    return os.getpid()


def test_pool_workers_deliver_every_result_and_exit_cleanly():
    """Local workers skip the interpreter teardown at exit (init_pool_worker): results arrive, exit code 0."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor


    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"), initializer=init_pool_worker)
    pids = list(pool.map(_pid, range(8)))
    processes = list(pool._processes.values())
    pool.shutdown(wait=True)
    assert len(pids) == 8 and os.getpid() not in pids
    assert processes and all(p.exitcode == 0 for p in processes)
