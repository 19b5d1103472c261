"""Batch guards (issue 21): output names that keep the source's path, a plan refusing two inputs on one output,
one run per output folder, resume that verifies what it skips, a broken asset named before any work."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from streetaug.augment.batch import BatchConfig, LogRow, RunOptions, run_batch
from streetaug.augment.batch.layout import check_unique_outputs, labels_file, output_file
from streetaug.augment.batch.log import file_check, row_complete
from streetaug.augment.core import InputError
from streetaug.augment.core.lock import OutputLock
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot

QUIET = RunOptions(workers=1, progress=False, contact_sheet=0)


def config(root: Path, **kw) -> BatchConfig:
    values = dict(dataroot=str(root), version=BUNDLED_VERSION, cameras=("CAM_FRONT",), quality="draft", limit=1)
    return BatchConfig(**{**values, **kw})


def copy_tables(tmp_path: Path) -> Path:
    src = tmp_path / "src"
    shutil.copytree(bundled_dataroot(), src, ignore=shutil.ignore_patterns("ground_truth"))
    return src


class TestOutputNames:
    def test_a_normal_nuscenes_layout_keeps_todays_names(self):
        name = "samples/CAM_FRONT/n015-2018__CAM_FRONT__1.jpg"
        assert output_file(name, "CAM_FRONT") == name
        assert labels_file(name) == "labels/CAM_FRONT/n015-2018__CAM_FRONT__1.json"
        assert output_file("samples/LIDAR_TOP/x.pcd.bin", "LIDAR_TOP") == "samples/LIDAR_TOP/x.pcd.bin"

    def test_sweeps_keep_their_folder_and_label_apart(self):
        name = "sweeps/CAM_FRONT/n015-2018__CAM_FRONT__2.jpg"
        assert output_file(name, "CAM_FRONT") == name
        assert labels_file(name) == "labels/sweeps/CAM_FRONT/n015-2018__CAM_FRONT__2.json"

    def test_sub_folders_are_kept(self):
        a, b = output_file("samples/CAM_FRONT/sub0/same.jpg", "CAM_FRONT"), output_file(
            "samples/CAM_FRONT/sub1/same.jpg", "CAM_FRONT")
        assert a != b and labels_file(a) == "labels/CAM_FRONT/sub0/same.json"

    def test_a_file_outside_samples_goes_under_its_channel(self):
        assert output_file("other/CAM_FRONT/x.jpg", "CAM_FRONT") == "samples/CAM_FRONT/other/CAM_FRONT/x.jpg"
        assert output_file("./samples/CAM_FRONT/x.jpg", "CAM_FRONT") == "samples/CAM_FRONT/x.jpg"

    @pytest.mark.parametrize("bad", ["../private/x.jpg", "/etc/passwd", "samples/../../x.jpg"])
    def test_names_that_leave_are_refused(self, bad):
        with pytest.raises(InputError, match="relative path inside the dataroot"):
            output_file(bad, "CAM_FRONT", "tok")

    def test_a_collision_names_both_tokens(self):
        with pytest.raises(InputError, match="sample_data aaa and bbb .*OUT/samples/CAM_FRONT/x.jpg"):
            check_unique_outputs({"aaa": ["samples/CAM_FRONT/x.jpg"], "bbb": ["samples/CAM_FRONT/x.jpg"]})
        check_unique_outputs({"aaa": ["samples/CAM_FRONT/x.jpg"], "bbb": ["samples/CAM_FRONT/y.jpg"]})

    def test_two_rows_on_one_file_are_refused_before_any_work(self, tmp_path):
        src = copy_tables(tmp_path)
        path = src / BUNDLED_VERSION / "sample_data.json"
        rows = json.loads(path.read_text())
        front = [r for r in rows if "/CAM_FRONT/" in r["filename"]]
        front[1]["filename"] = front[0]["filename"]
        path.write_text(json.dumps(rows))
        out = tmp_path / "out"
        with pytest.raises(InputError, match=f"{front[0]['token']} and {front[1]['token']}"):
            run_batch(config(src, limit=None), out, QUIET)
        assert not (out / "augment_log.jsonl").exists() and not (out / ".streetaug.lock").exists()


class TestOneRunPerOutput:
    def test_a_held_lock_refuses_a_second_run(self, tmp_path):
        out = tmp_path / "out"
        with OutputLock(out, "batch"):
            with pytest.raises(InputError, match="another streetaug batch is writing here"):
                run_batch(config(bundled_dataroot().resolve()), out, QUIET)
        assert not (out / "augment_log.jsonl").exists()

    def test_shards_lock_their_own_folder(self, tmp_path):
        out = tmp_path / "out"
        with OutputLock(out, "batch"):  # another shard (or run) on the folder: this shard still runs
            summary = run_batch(config(bundled_dataroot().resolve()), out,
                                RunOptions(workers=1, progress=False, contact_sheet=0, shard=(0, 2)))
        assert summary["images"] == 1
        assert not (out / "shards" / "0-of-2" / ".streetaug.lock").exists()

    def test_out_inside_the_source_is_refused_before_the_lock(self, tmp_path):
        src = copy_tables(tmp_path)
        with pytest.raises(InputError, match="inside the source dataset"):
            run_batch(config(src), src / "samples" / "CAM_FRONT", QUIET)
        assert not (src / "samples" / "CAM_FRONT" / ".streetaug.lock").exists()


class TestResumeVerifies:
    def row(self, out: Path, name: str, data: bytes) -> LogRow:
        (out / name).write_bytes(data)
        return LogRow("s", "CAM_FRONT", "ok", files=(name,), file_checks={name: file_check(out / name)})

    def test_whole_files_are_complete(self, tmp_path):
        assert row_complete(self.row(tmp_path, "a.jpg", b"0123456789"), tmp_path)

    def test_a_truncated_file_is_not(self, tmp_path):
        row = self.row(tmp_path, "a.jpg", b"0123456789")
        (tmp_path / "a.jpg").write_bytes(b"01234")
        assert not row_complete(row, tmp_path)

    def test_an_overwritten_file_of_the_same_size_is_not(self, tmp_path):
        row = self.row(tmp_path, "a.jpg", b"0123456789")
        (tmp_path / "a.jpg").write_bytes(b"9876543210")
        assert not row_complete(row, tmp_path)

    def test_rows_of_older_logs_check_existence(self, tmp_path):
        (tmp_path / "a.jpg").write_bytes(b"x")
        assert row_complete(LogRow("s", "CAM_FRONT", "ok", files=("a.jpg",)), tmp_path)
        assert not row_complete(LogRow("s", "CAM_FRONT", "ok", files=("b.jpg",)), tmp_path)

    def test_the_log_records_sizes_and_checksums(self, tmp_path):
        out = tmp_path / "out"
        run_batch(config(bundled_dataroot().resolve()), out, QUIET)
        (row,) = [json.loads(line) for line in (out / "augment_log.jsonl").read_text().splitlines()]
        assert row["status"] == "ok" and set(row["file_checks"]) == set(row["files"])
        for name, check in row["file_checks"].items():
            assert check == file_check(out / name)


class TestAssetsUpFront:
    def test_a_broken_single_asset_stops_the_batch(self, tmp_path):
        broken = tmp_path / "broken.glb"
        broken.write_bytes(b"glTF not really")
        out = tmp_path / "out"
        with pytest.raises(InputError, match="broken.glb"):
            run_batch(config(bundled_dataroot().resolve(), asset=str(broken)), out, QUIET)
        assert not (out / "augment_log.jsonl").exists()
