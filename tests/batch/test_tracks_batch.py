"""``streetaug batch --tracks``: instances through the real dev scene's keyframes, as the devkit reads them.

Needs ``../shared/data/nuscenes-seq`` (real scene-0916; skips without it). One run renders the first 3
keyframes into CAM_FRONT and CAM_FRONT_LEFT (draft quality, L1 lighting: the labels and tables are what is
tested here, not the shading).
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SHARED_DATA, devkit
from streetaug.augment.batch import BatchConfig, RunOptions, read_log, run_batch
from streetaug.augment.batch.tracks import read_scene_tracks, saved_scene_tracks
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.datasets.nuscenes_format import new_token

SEQ = SHARED_DATA / "nuscenes-seq"
pytestmark = pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file(),
                                reason=f"{SEQ} (real nuScenes scene-0916) not present")
N_SAMPLES = 3


def config(**kw) -> BatchConfig:
    values = dict(dataroot=str(SEQ.resolve()), version="v1.0-mini", cameras=("CAM_FRONT", "CAM_FRONT_LEFT"),
                  limit=N_SAMPLES, quality="draft", level="L1", seed=3, tracks=3)
    values.update(kw)
    return BatchConfig(**values)


@pytest.fixture(scope="module")
def nusc(run):
    """The devkit's view of the output (loaded once: the real scene's tables take seconds)."""
    return devkit().NuScenes(version="v1.0-mini", dataroot=str(run[0]), verbose=False)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tracks") / "out"
    summary = run_batch(config(), out, RunOptions(workers=1, progress=False, contact_sheet=0))
    return out, summary


def test_scene_is_planned_once_over_all_its_keyframes(run):
    out, summary = run
    reader = NuScenesReader(SEQ, "v1.0-mini")
    (planned,) = saved_scene_tracks(out)
    assert list(planned.sample_tokens) == reader.sample_tokens()  # all 41, though only 3 are rendered
    assert summary["tracks"]["tracks"] == len(planned.tracks) >= 2
    assert summary["tracks"]["per_scene"]["scene-0916"]["traffic_side"].startswith("traffic keeps left")
    # a rerun reads the saved plan (tracks never re-drawn); other options plan again
    again = read_scene_tracks(out, planned.scene_token, config(), reader.sample_tokens())
    assert again.to_json() == planned.to_json()
    assert read_scene_tracks(out, planned.scene_token, config(seed=4), reader.sample_tokens()) is None


def test_every_track_annotation_is_logged_once_per_sample(run):
    out, _ = run
    (planned,) = saved_scene_tracks(out)
    rows = [r for r in read_log(out / "augment_log.jsonl") if r.status != "failed"]
    assert len(rows) == 2 * N_SAMPLES
    seen = {}
    for r in rows:
        for o in r.objects or ():
            key = (r.sample_token, o.track)
            assert key not in seen, f"{key} logged twice"
            seen[key] = o
    expected = {(s, f"{planned.scene_token}/{t.track_index}") for s in list(planned.sample_tokens)[:N_SAMPLES]
                for t in planned.at(s)}
    assert set(seen) == expected


def test_devkit_chains_instances_and_velocity_matches_the_trajectory(run, nusc):
    out, _ = run
    (planned,) = saved_scene_tracks(out)
    rendered = list(planned.sample_tokens)[:N_SAMPLES]
    checked = 0
    for track in planned.tracks:
        here = [s for s in rendered if track.index_of(s) is not None]
        if not here:
            continue
        inst = nusc.get("instance", new_token("instance", 3, "track", f"{planned.scene_token}/{track.track_index}"))
        assert inst["nbr_annotations"] == len(here)
        chain, token = [], inst["first_annotation_token"]
        while token:
            ann = nusc.get("sample_annotation", token)
            chain.append(ann)
            token = ann["next"]
        assert [a["sample_token"] for a in chain] == here and chain[-1]["token"] == inst["last_annotation_token"]
        attributes = [nusc.get("attribute", t)["name"] for a in chain for t in a["attribute_tokens"]]
        assert attributes == [track.attribute_at(track.index_of(a["sample_token"])) for a in chain]
        for ann in chain:
            i = track.index_of(ann["sample_token"])
            assert np.allclose(ann["translation"], track.box_at(i).center, atol=1e-6)
            v = nusc.box_velocity(ann["token"])
            if len(chain) > 1:
                # the devkit's difference of neighbouring annotations vs the trajectory's velocity
                assert np.linalg.norm(v[:2] - track.velocity_global[i, :2]) < 0.3
        checked += 1
    assert checked >= 2


def test_log_names_each_annotation_by_track_with_velocity_and_attribute(run):
    out, _ = run
    (planned,) = saved_scene_tracks(out)
    by_key = {f"{planned.scene_token}/{t.track_index}": t for t in planned.tracks}
    logged = [(r.sample_token, o) for r in read_log(out / "augment_log.jsonl") for o in r.objects or ()]
    assert logged
    for sample_token, o in logged:
        track = by_key[o.track]
        assert o.object_index == track.track_index
        assert o.attribute == track.attribute_at(track.index_of(sample_token))
        assert np.allclose(o.velocity, track.velocity_global[track.index_of(sample_token)], atol=1e-5)


def test_devkit_detection_and_tracking_loaders_read_the_new_boxes(run, nusc):
    """The evaluation code's own ground-truth loaders (mini_val holds scene-0916): velocities and attributes."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.common.loaders import load_gt
    from nuscenes.eval.detection.data_classes import DetectionBox
    from nuscenes.eval.tracking.data_classes import TrackingBox

    out, _ = run
    (planned,) = saved_scene_tracks(out)
    ours = {new_token("instance", 3, "track", f"{planned.scene_token}/{t.track_index}"): t for t in planned.tracks}
    config_factory("tracking_nips_2019")  # the tracking benchmark's config (sets its class names), as its eval does
    tracking = load_gt(nusc, "mini_val", TrackingBox)
    detection = load_gt(nusc, "mini_val", DetectionBox)
    found = 0
    for sample_token in tracking.sample_tokens:
        det = {tuple(np.round(b.translation, 4)): b for b in detection[sample_token]}
        for box in tracking[sample_token]:
            track = ours.get(box.tracking_id)
            if track is None:
                continue
            i = track.index_of(sample_token)
            assert box.tracking_name == "car"
            d = det[tuple(np.round(box.translation, 4))]
            assert d.detection_name == "car" and d.attribute_name == track.attribute_at(i)
            assert np.all(np.isfinite(box.velocity))  # from the neighbouring annotations (3 rendered keyframes)
            found += 1
    assert found >= 2
