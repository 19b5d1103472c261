"""The nuScenes reader parses a table only when a question needs it, and each table once.

``read_table_rows`` (what the reader parses a table file with) is wrapped to count the parses; the tables are
the bundled sample scenes', one test with ``sample_data.json`` grown to a million rows.
"""

from __future__ import annotations

import collections
import shutil
from pathlib import Path

import pytest

import streetaug.datasets.nuscenes as nuscenes
from streetaug.datasets import BUNDLED_VERSION, NuScenesReader, bundled_dataroot

BIG_ROWS = 1_000_000


@pytest.fixture
def parses(monkeypatch) -> collections.Counter:
    """Table name -> how many times the reader parsed its file."""
    counts: collections.Counter = collections.Counter()
    real = nuscenes.read_table_rows

    def counting(path: Path) -> list[dict]:
        counts[Path(path).stem] += 1
        return real(path)

    monkeypatch.setattr(nuscenes, "read_table_rows", counting)
    return counts


def big_sample_data_copy(tmp_path: Path) -> Path:
    """A dataroot with the bundled tables, ``sample_data.json`` holding the real rows + 1e6 rows of no sample."""
    root = tmp_path / "root"
    shutil.copytree(bundled_dataroot() / BUNDLED_VERSION, root / BUNDLED_VERSION)
    path = root / BUNDLED_VERSION / "sample_data.json"
    real = path.read_text().strip()
    assert real.startswith("[") and real.endswith("]")
    filler = ",".join(f'{{"token":"filler{i:07d}","sample_token":"","is_key_frame":false}}' for i in range(BIG_ROWS))
    path.write_text(real[:-1] + "," + filler + "]")
    assert path.stat().st_size > 40e6
    return root


def test_opening_and_finding_a_sample_leave_the_big_table_unparsed(tmp_path, parses):
    root = big_sample_data_copy(tmp_path)
    reader = NuScenesReader(root, BUNDLED_VERSION)
    assert sum(parses.values()) == 0  # opening checks the files exist, parses none
    token = reader.sample_tokens("sample-sunny")[0]
    assert reader.location_of(token) and reader.scene_of(token)["name"] == "sample-sunny"
    assert set(parses) == {"scene", "sample", "log"}
    assert "sample_data" not in parses and "ego_pose" not in parses and "sample_annotation" not in parses


def test_building_samples_parses_each_needed_table_once(parses):
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    tokens = [reader.sample_tokens(name)[0] for name in ("sample-sunny", "sample-lowsun")]
    first = reader.sample(tokens[0])
    assert first.cameras and first.boxes
    after_first = dict(parses)
    assert {"sample_data", "ego_pose", "sample_annotation", "calibrated_sensor", "sensor"} <= set(after_first)
    assert "lidarseg" not in after_first and "visibility" not in after_first  # no LiDAR read yet, never needed
    reader.sample(tokens[1])
    assert dict(parses) == after_first  # nothing parsed again
    assert max(parses.values()) == 1
