"""``streetaug batch --tracks`` on the bundled sequence scene (examples/nuscenes-sequence: 5 keyframes, 3 cameras,
800 x 450, the ego driving at 8 m/s, annotated parked and moving cars, map lanes): the same output whatever the
number of workers or a kill, rules that hold at every keyframe, labels and the track sheet.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.batch import BatchConfig, RunOptions, read_log, run_batch
from streetaug.augment.batch.tracks import saved_scene_tracks
from streetaug.augment.evaluation.track_audit import audit_tracks
from streetaug.datasets.bundled import bundled_sequence_dataroot
from test_batch import assert_same_output

VERSION = "v1.0-sequence"
QUIET = dict(progress=False, contact_sheet=4)
CAMERAS = ("CAM_FRONT", "CAM_BACK")  # of the 3, and
N_SAMPLES = 3  # of the 5 keyframes (planned over all 5): the suite's time


def config(**kw) -> BatchConfig:
    values = dict(dataroot=str(bundled_sequence_dataroot().resolve()), version=VERSION, quality="draft", level="L1",
                  seed=0, tracks=3, sweeps=True, cameras=CAMERAS, limit=N_SAMPLES)
    values.update(kw)
    return BatchConfig(**values)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("seq") / "inline"
    summary = run_batch(config(), out, RunOptions(workers=1, **QUIET))
    return out, summary


def test_tracks_are_planned_and_shown_through_the_scene(reference):
    out, summary = reference
    tracks = summary["tracks"]
    assert tracks["tracks"] >= 2 and tracks["keyframes_per_track_median"] >= 3
    # the committed copy holds keyframes only: the sweeps are skipped, with the reason said once
    sweeps = summary["sweeps"]
    assert sweeps["files"] == 0 and sweeps["samples_not_rendered"] == N_SAMPLES - 1  # the first has none
    assert "sweep files are absent" in sweeps["reason"] and "make-samples --sequence --sweeps" in sweeps["reason"]
    assert summary["outputs"]["tracks_sheet"] == "tracks_sheet.png" and (out / "tracks_sheet.png").is_file()
    labelled = [o for p in sorted((out / "labels").rglob("*.json")) for o in json.loads(p.read_text())["objects"]]
    assert labelled and all(o["track"] and len(o["velocity"]) == 3 and o["motion"] in ("parked", "moving")
                            for o in labelled)
    # the labels' LiDAR count is the annotation's (the augmented sweep's points on the object)
    rows = read_log(out / "augment_log.jsonl")
    logged = {(r.sample_token, o.object_index): o.num_lidar_pts for r in rows for o in r.objects or ()}
    for p in sorted((out / "labels").rglob("*.json")):
        doc = json.loads(p.read_text())
        for o in doc["objects"]:
            assert o["num_lidar_pts"] == logged[(doc["sample_token"], o["track_index"])]


def test_audit_finds_no_violation_no_pop_and_renders_what_is_visible(reference):
    out, _ = reference
    audit = audit_tracks(out, bundled_sequence_dataroot(), VERSION, CAMERAS)
    assert audit["frames_checked"] >= 2 * N_SAMPLES
    assert audit["violations"] == 0, audit["per_scene"]
    assert audit["pops"] == 0, audit["per_scene"]
    assert audit["recall"] is not None and audit["recall"] >= 0.9, audit
    assert audit["lidar_pts_nonzero_fraction"] > 0.5


def test_two_workers_give_the_same_output(reference, tmp_path):
    run_batch(config(), tmp_path / "out", RunOptions(workers=2, **QUIET))
    assert_same_output(tmp_path / "out", reference[0])
    a = [t.to_json() for t in saved_scene_tracks(tmp_path / "out")[0].tracks]
    assert a == [t.to_json() for t in saved_scene_tracks(reference[0])[0].tracks]


def test_sigkill_mid_scene_then_rerun_gives_the_same_output(reference, tmp_path):
    out = tmp_path / "out"
    cmd = [str(Path(sys.executable).with_name("streetaug")), "batch", "--dataroot", str(bundled_sequence_dataroot()),
           "--version", VERSION, "--tracks", "3", "--sweeps", "--cameras", ",".join(CAMERAS), "--limit", str(N_SAMPLES),
           "--quality", "draft",
           "--level", "L1", "--workers", "1",
           "--no-progress", "--contact-sheet", "4", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    log = out / "augment_log.jsonl"
    deadline = time.monotonic() + 240
    while not (log.is_file() and log.stat().st_size > 0) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)  # after the first sample of the scene, while the next is being rendered
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    done_before = {r.sample_token for r in read_log(log)}
    assert 0 < len(done_before) < N_SAMPLES
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert "resuming" in rerun.stderr
    assert_same_output(out, reference[0])


def test_a_scene_with_a_sample_missing_its_ego_pose_fails_alone(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(bundled_sequence_dataroot(), src)
    table = src / VERSION / "ego_pose.json"
    poses = json.loads(table.read_text())
    sample_data = json.loads((src / VERSION / "sample_data.json").read_text())
    key = next(sd for sd in sample_data if sd["is_key_frame"] and "CAM_FRONT/" in sd["filename"])
    table.write_text(json.dumps([p for p in poses if p["token"] != key["ego_pose_token"]]))
    summary = run_batch(config(dataroot=str(src)), tmp_path / "out", RunOptions(workers=1, **QUIET))
    assert summary["tracks"]["scenes_failed"] == 1
    rows = read_log(tmp_path / "out" / "augment_log.jsonl")
    assert rows and all(r.status == "failed" for r in rows)
    assert all("ego_pose" in r.reason for r in rows), rows[0].reason


@pytest.fixture(scope="module")
def with_sweeps(tmp_path_factory):
    """A small generated sequence WITH its sweep files (2 keyframes, CAM_FRONT + CAM_BACK, 160 x 90), batched."""
    from streetaug.augment.scenegen.sequence import make_sequence_scene

    src = tmp_path_factory.mktemp("seq_sweeps") / "src"
    make_sequence_scene(src, sweeps=True, width=160, height=90, spp=1, sky_rays=1, n_keyframes=2,
                        cameras=("CAM_FRONT", "CAM_BACK"))
    out = src.parent / "out"
    summary = run_batch(config(dataroot=str(src)), out, RunOptions(workers=1, **QUIET))
    return src, out, summary


def test_sweeps_show_the_tracks_at_their_interpolated_poses(with_sweeps):
    from streetaug.datasets.nuscenes import NuScenesReader

    src, out, summary = with_sweeps
    assert summary["sweeps"]["reason"] is None and summary["sweeps"]["files"] > 0
    (planned,) = saved_scene_tracks(out)
    by_key = {f"{planned.scene_token}/{t.track_index}": t for t in planned.tracks}
    reader = NuScenesReader(src, VERSION)
    labelled = 0
    for path in sorted((out / "labels" / "sweeps").rglob("*.json")):
        doc = json.loads(path.read_text())
        assert doc["is_key_frame"] is False
        t_us = int(reader.get("sample_data", doc["sample_data_token"])["timestamp"])
        for obj in doc["objects"]:
            track = by_key[obj["track"]]
            expected = track.pose_at(t_us)
            center = expected[:3, 3] + 0.5 * track.wlh[2] * expected[:3, 2]
            assert np.allclose(obj["box_global"]["translation"], center, atol=1e-6)
            # between its keyframes' poses: a moving track has moved since the previous keyframe
            labelled += 1
    assert labelled > 0


def test_sweep_files_are_linked_in_the_tables_and_hold_the_objects(with_sweeps):
    from conftest import devkit

    from streetaug.datasets.lidarseg import read_lidar_points
    from streetaug.datasets.nuscenes import NuScenesReader

    src, out, summary = with_sweeps
    nusc = devkit().NuScenes(version=VERSION, dataroot=str(out), verbose=False)
    rows = read_log(out / "augment_log.jsonl")
    files = {t: f for r in rows for t, f in (r.sweep_files or {}).items()}
    assert len(files) == summary["sweeps"]["files"]
    for token, file in files.items():
        sd = nusc.get("sample_data", token)
        assert not sd["is_key_frame"] and sd["filename"] == file and (out / file).is_file()
    # the LiDAR sweeps have points on the moving tracks at their own time
    (planned,) = saved_scene_tracks(out)
    reader = NuScenesReader(src, VERSION)
    lidar = [t for t, f in files.items() if f.startswith("sweeps/LIDAR_TOP/")]
    assert lidar
    hits = 0
    for token in lidar:
        sd = reader.get("sample_data", token)
        points = read_lidar_points(out / files[token])[:, :3].astype(np.float64)
        T = reader.T_global_from_ego(sd) @ reader.T_ego_from_sensor(sd)
        xyz = points @ T[:3, :3].T + T[:3, 3]
        for track in planned.tracks:
            T_obj = track.pose_at(int(sd["timestamp"]))
            local = (xyz - T_obj[:3, 3]) @ T_obj[:3, :3]
            w, l, h = track.wlh
            inside = (np.abs(local[:, 0]) <= l / 2) & (np.abs(local[:, 1]) <= w / 2) & (local[:, 2] >= 0) & (local[:, 2] <= h)
            hits += int(inside.sum() > 0)
    assert hits > 0


def test_devkit_returns_and_renders_the_tracks_in_each_camera(reference, tmp_path):
    from conftest import devkit

    from streetaug.datasets.nuscenes_format import new_token

    out, _ = reference
    nusc = devkit().NuScenes(version=VERSION, dataroot=str(out), verbose=False)
    ok = [r for r in read_log(out / "augment_log.jsonl") if r.status == "ok"]
    assert ok
    for r in ok:
        path, boxes, K = nusc.get_sample_data(r.sample_data_token)
        assert Path(path) == out / r.image
        by_token = {b.token: b for b in boxes}
        for label in json.loads((out / r.files[1]).read_text())["objects"]:
            box = by_token[new_token("sample_annotation", 0, r.sample_token, label["track_index"])]
            u, v, z = np.asarray(K) @ box.center
            x0, y0, x1, y1 = label["bbox_2d"]
            assert z > 0 and x0 <= u / z <= x1 and y0 <= v / z <= y1
    (planned,) = saved_scene_tracks(out)
    instance = new_token("instance", 0, "track", f"{planned.scene_token}/{planned.tracks[0].track_index}")
    first = nusc.get("instance", instance)["first_annotation_token"]
    nusc.render_annotation(first, out_path=str(tmp_path / "ann.png"))
    nusc.render_sample_data(ok[0].sample_data_token, out_path=str(tmp_path / "cam.png"), verbose=False)
    assert (tmp_path / "ann.png").stat().st_size > 10_000 and (tmp_path / "cam.png").stat().st_size > 10_000


def test_dry_run_writes_the_planned_tracks(tmp_path):
    from streetaug.augment.batch.tracks import tracks_file

    summary = run_batch(config(limit=1), tmp_path / "plan", RunOptions(workers=1, progress=False, dry_run=True,
                                                                       contact_sheet=0))
    (planned,) = saved_scene_tracks(tmp_path / "plan")
    assert tracks_file(tmp_path / "plan", planned.scene_token).is_file() and planned.tracks
    assert summary["objects_planned"] == len(planned.at(planned.sample_tokens[0]))
    assert not list((tmp_path / "plan").glob("samples/*/*"))  # nothing rendered
