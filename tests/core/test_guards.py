"""Core guards against bad inputs: paths that leave their root, oversized images, output locks, write errors."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.core import InputError, read_image_rgb, read_json, write_bytes_atomic, write_image_rgb
from streetaug.augment.core.limits import (ResourceLimits, check_triangles, image_size_from_bytes,
                                           image_size_from_header, texture_reduction)
from streetaug.augment.core.lock import LOCK_NAME, OutputLock, pid_alive
from streetaug.augment.core.paths import is_inside, refuse_output_inside, resolve_inside


class TestResolveInside:
    def test_a_path_inside_resolves(self, tmp_path):
        (tmp_path / "samples").mkdir()
        assert resolve_inside(tmp_path, "samples/a.jpg", "t") == (tmp_path / "samples" / "a.jpg").resolve()

    @pytest.mark.parametrize("bad", ["../secret.jpg", "samples/../../secret.jpg", "/etc/passwd", "", "a\x00b"])
    def test_escapes_are_refused_naming_the_source(self, tmp_path, bad):
        with pytest.raises(InputError, match="sample_data.json row 3"):
            resolve_inside(tmp_path / "root", bad, "sample_data.json row 3 field 'filename'")

    def test_a_symlink_out_of_the_root_is_refused(self, tmp_path):
        root = tmp_path / "root"
        root.mkdir()
        (tmp_path / "outside.jpg").write_bytes(b"x")
        (root / "link.jpg").symlink_to(tmp_path / "outside.jpg")
        with pytest.raises(InputError, match="outside"):
            resolve_inside(root, "link.jpg", "where")
        assert not is_inside(root / "link.jpg", root)

    @pytest.mark.parametrize("sub", [".", "v1.0-mini", "samples/CAM_FRONT"])
    def test_outputs_inside_a_source_are_refused(self, tmp_path, sub):
        with pytest.raises(InputError, match="inside the source dataset"):
            refuse_output_inside(tmp_path / sub, tmp_path)
        with pytest.raises(InputError, match="contains the source"):
            refuse_output_inside(tmp_path, tmp_path / "data")
        refuse_output_inside(tmp_path / "out", tmp_path / "data")  # siblings are fine


class TestLimits:
    def test_header_sizes_without_decoding(self, tmp_path):
        image = np.zeros((5, 7, 3), np.uint8)
        for suffix in (".png", ".jpg"):
            write_image_rgb(tmp_path / f"a{suffix}", image)
            assert image_size_from_header(tmp_path / f"a{suffix}") == (7, 5)
        assert image_size_from_bytes(b"not an image") is None

    def test_an_oversized_image_is_refused_before_decoding(self, tmp_path):
        # a 20000 x 20000 PNG header over a truncated body: decoding it would fail or take GBs, the check comes first
        png = (tmp_path / "big.png")
        write_image_rgb(png, np.zeros((4, 4, 3), np.uint8))
        data = bytearray(png.read_bytes())
        data[16:24] = (20000).to_bytes(4, "big") * 2
        png.write_bytes(bytes(data))
        with pytest.raises(InputError, match=r"20000 x 20000 = 400.0 MP, above the limit of 64.0 MP"):
            read_image_rgb(png)

    def test_limits_from_the_environment(self):
        limits = ResourceLimits.from_env({"STREETAUG_MAX_IMAGE_PIXELS": "100"})
        assert limits.max_image_pixels == 100
        with pytest.raises(InputError, match="STREETAUG_MAX_TRIANGLES"):
            ResourceLimits.from_env({"STREETAUG_MAX_TRIANGLES": "many"})
        with pytest.raises(InputError, match="positive integer"):
            ResourceLimits(max_triangles=0)

    def test_textures_are_reduced_or_refused(self):
        limits = ResourceLimits()
        assert texture_reduction((1024, 1024), "t", limits) == 1
        assert texture_reduction((9000, 9000), "t", limits) == 4
        with pytest.raises(InputError, match="13000 x 13000"):
            texture_reduction((13000, 13000), "car.gltf image 0", limits)
        with pytest.raises(InputError, match="3000000 triangles"):
            check_triangles(3_000_000, "car.glb", limits)


class TestIOErrors:
    def test_deep_json_names_the_file(self, tmp_path):
        path = tmp_path / "map.json"
        path.write_text("[" * 100_000 + "]" * 100_000)
        with pytest.raises(InputError, match="map.json: JSON nested too deeply"):
            read_json(path)

    def test_a_failed_write_names_the_file_and_leaves_nothing(self, tmp_path):
        folder = tmp_path / "ro"
        folder.mkdir()
        target = folder / "a.json"
        if os.geteuid() == 0:  # root ignores permissions: make the rename fail instead
            target.mkdir()
            (target / "x").write_text("")
        else:
            folder.chmod(0o500)
        with pytest.raises(InputError, match=r"a.json: cannot write"):
            write_bytes_atomic(target, b"{}")
        assert [p.name for p in folder.iterdir() if p.name.startswith(".a.json")] == []


class TestOutputLock:
    def test_a_second_run_is_refused_naming_the_first(self, tmp_path):
        with OutputLock(tmp_path, "batch"):
            assert (tmp_path / LOCK_NAME).is_file()
            with pytest.raises(InputError, match=rf"another streetaug batch is writing here \(pid {os.getpid()}"):
                OutputLock(tmp_path, "batch").acquire()
        assert not (tmp_path / LOCK_NAME).exists()

    def test_a_stale_lock_is_taken_over(self, tmp_path):
        dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
        owner = {"pid": int(dead.stdout), "host": socket.gethostname(), "command": "batch", "started_unix": time.time()}
        (tmp_path / LOCK_NAME).write_text(json.dumps(owner))
        lock = OutputLock(tmp_path, "batch")
        with lock:
            assert lock.took_over["pid"] == owner["pid"]
            assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == os.getpid()

    def test_a_lock_from_another_host_is_not_taken(self, tmp_path):
        owner = {"pid": 1, "host": "elsewhere.example", "command": "batch", "started_unix": 0}
        (tmp_path / LOCK_NAME).write_text(json.dumps(owner))
        with pytest.raises(InputError, match="on host elsewhere.example"):
            OutputLock(tmp_path).acquire()


def test_a_worker_exits_when_its_parent_is_killed(tmp_path):
    pid_file = tmp_path / "child.pid"
    parent_code = f"""
import subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", '''
import os, time
from streetaug.augment.core.lock import exit_with_parent
exit_with_parent(poll_s=0.1)
open({str(pid_file)!r}, "w").write(str(os.getpid()))
time.sleep(60)
'''])
time.sleep(60)
"""
    assert_child_dies_with_parent(subprocess.Popen([sys.executable, "-c", parent_code]), pid_file, within_s=5)


def assert_child_dies_with_parent(parent: subprocess.Popen, pid_file: Path, within_s: float) -> None:
    """Wait for the child to write its pid, SIGKILL ``parent``, and assert the child is gone within ``within_s``."""
    deadline = time.time() + 30
    while not pid_file.exists() or not pid_file.read_text():
        assert time.time() < deadline, "the child never started"
        time.sleep(0.05)
    child_pid = int(pid_file.read_text())
    parent.kill()
    parent.wait()
    deadline = time.time() + within_s
    while pid_alive(child_pid):
        stat = Path(f"/proc/{child_pid}/stat")
        if stat.exists() and stat.read_text().rpartition(")")[2].split()[0] == "Z":
            break  # exited, waiting to be reaped by init
        assert time.time() < deadline, f"the worker outlived its parent by {within_s} s"
        time.sleep(0.05)


def test_a_linked_top_folder_of_the_root_is_followed(tmp_path):
    disk2 = tmp_path / "disk2" / "samples"
    (disk2 / "CAM_FRONT").mkdir(parents=True)
    (disk2 / "CAM_FRONT" / "a.jpg").write_bytes(b"x")
    root = tmp_path / "root"
    root.mkdir()
    (root / "samples").symlink_to(disk2)
    assert resolve_inside(root, "samples/CAM_FRONT/a.jpg", "w") == (disk2 / "CAM_FRONT" / "a.jpg").resolve()
    (disk2 / "CAM_FRONT" / "b.jpg").symlink_to("/etc/passwd")  # a link below the linked folder is not
    with pytest.raises(InputError, match="outside"):
        resolve_inside(root, "samples/CAM_FRONT/b.jpg", "w")
    with pytest.raises(InputError, match="climbs out"):
        resolve_inside(root, "samples/../../disk2/samples/CAM_FRONT/a.jpg", "w")


def test_a_spawned_worker_whose_parent_died_while_it_started_exits(tmp_path):
    """The parent dies before the worker's initialiser runs: getppid() then names init, yet it must exit."""
    pid_file = tmp_path / "child.pid"
    parent_code = f"""
import multiprocessing, os, time

def work(path):
    open(path, "w").write(str(os.getpid()))
    time.sleep(1.5)  # the parent is killed meanwhile
    from streetaug.augment.core.lock import exit_with_parent
    exit_with_parent(poll_s=0.1)
    time.sleep(60)

if __name__ == "__main__":
    multiprocessing.get_context("spawn").Process(target=work, args=({str(pid_file)!r},)).start()
    time.sleep(60)
"""
    script = tmp_path / "parent.py"
    script.write_text(parent_code)
    assert_child_dies_with_parent(subprocess.Popen([sys.executable, str(script)]), pid_file, within_s=8)
