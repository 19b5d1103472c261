"""A ``--tracks`` sample's task builds the assets of the tracks annotated at that keyframe only (each track's asset
is its own draw), not every track of the scene."""

from __future__ import annotations

from dataclasses import replace

from streetaug.augment.assets import select as select_module
from streetaug.augment.batch import BatchConfig, RunOptions, run_batch
from streetaug.augment.batch.job import augment_track_sample
from streetaug.augment.batch.tracks import saved_scene_tracks, track_assets
from streetaug.datasets.bundled import bundled_sequence_dataroot
from streetaug.datasets.nuscenes import NuScenesReader

VERSION = "v1.0-sequence"


def _config() -> BatchConfig:
    return BatchConfig(dataroot=str(bundled_sequence_dataroot().resolve()), version=VERSION, quality="draft",
                       level="L0", seed=0, tracks=3, cameras=("CAM_FRONT",), limit=1)


def test_one_tracks_asset_is_the_one_drawn_with_all_of_them():
    from streetaug.augment.batch.tracks import track_asset

    config = _config()
    every = track_assets(config, "scene-x", 3, "singapore-onenorth")
    assert [track_asset(config, "scene-x", i, "singapore-onenorth").name for i in range(3)] == [a.name for a in every]


def test_a_sample_builds_only_the_assets_of_the_tracks_annotated_there(tmp_path, monkeypatch):
    config = _config()
    out = tmp_path / "out"
    run_batch(config, out, RunOptions(workers=1, progress=False, contact_sheet=0, dry_run=True))
    (planned,) = saved_scene_tracks(out)
    assert len(planned.tracks) >= 2
    last = planned.tracks[-1]
    reader = NuScenesReader(bundled_sequence_dataroot(), VERSION)
    token = next(t for t in planned.sample_tokens if last.index_of(t) is not None)
    scene = replace(planned, tracks=(last,))  # only the last track is annotated here
    drawn: list[int] = []
    original = select_module.select_assets

    def counting(*a, **k):
        drawn.append(1)
        return original(*a, **k)

    monkeypatch.setattr(select_module, "select_assets", counting)
    rows = augment_track_sample(reader, config, out, token, ["CAM_FRONT"], scene, dry_run=True)
    assert len(rows) == 1
    assert len(drawn) == 1  # the last track's asset, not those of the tracks before it
