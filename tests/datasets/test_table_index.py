"""Large tables read through byte-offset indexes (datasets/table_index.py) give what parsing them whole gives.

Each reader here is built twice: ``index_min_bytes=0`` (every indexed table read through its index) and
``None`` (every table parsed whole, as before the index). The tables are the bundled scenes', the real
scene-0916 (skipped when absent) and copies edited to hold awkward rows: braces and escaped quotes inside
strings, compact and indented layouts, a row larger than the scan window. The index cache goes to a
folder of the test's own (``XDG_CACHE_HOME``).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from streetaug.datasets import BUNDLED_VERSION, NuScenesReader, bundled_dataroot
from streetaug.datasets import table_index as ti
from streetaug.datasets.bundled import BUNDLED_SEQUENCE_VERSION, bundled_sequence_dataroot
from streetaug.datasets.nuscenes import INDEXED_TABLES, DatasetError

REAL_SEQ = (Path(__file__).parents[2] / ".." / "shared" / "data" / "nuscenes-seq").resolve()
DATASETS = [(bundled_dataroot, BUNDLED_VERSION), (bundled_sequence_dataroot, BUNDLED_SEQUENCE_VERSION),
            (lambda: REAL_SEQ, "v1.0-mini")]


@pytest.fixture(autouse=True)
def cache_home(tmp_path, monkeypatch) -> Path:
    home = tmp_path / "cache_home"
    monkeypatch.setenv("XDG_CACHE_HOME", str(home))
    return home


def readers(root: Path, version: str) -> tuple[NuScenesReader, NuScenesReader]:
    """(indexed, parsed whole) readers of the same files."""
    return (NuScenesReader(root, version, with_map=False, index_min_bytes=0),
            NuScenesReader(root, version, with_map=False, index_min_bytes=None))


def table_copy(tmp_path: Path, source: Path = None, version: str = BUNDLED_VERSION) -> Path:
    """A dataroot holding a copy of the bundled tables (no images: building a Sample reads none)."""
    root = tmp_path / "root"
    shutil.copytree((source or bundled_dataroot()) / version, root / version)
    return root


def load(root: Path, table: str, version: str = BUNDLED_VERSION) -> list[dict]:
    return json.loads((root / version / f"{table}.json").read_text())


def save(root: Path, table: str, rows: list[dict], version: str = BUNDLED_VERSION, **dump) -> None:
    (root / version / f"{table}.json").write_text(json.dumps(rows, **dump))


def sample_summary(sample) -> list:
    """What a Sample holds from the tables, comparable with ==."""
    cams = [(c, v.sample_data_token, v.T_global_from_ego.tolist(), v.T_ego_from_cam.tolist(), v.timestamp_us,
             repr(v.ego_poses_around)) for c, v in sorted(sample.cameras.items())]
    boxes = [(b.token, b.center.tolist(), b.wlh.tolist(), b.rotation.tolist(), b.category, b.attributes, b.instance_token) for b in sample.boxes]
    return [sample.token, sample.timestamp_us, cams, boxes]


def assert_same_reading(indexed: NuScenesReader, whole: NuScenesReader) -> None:
    """Every sample, its rows (same dicts, same order), every indexed row by token and its row number."""
    for token in whole.sample_tokens():
        assert indexed.sample_data_rows(token) == whole.sample_data_rows(token)
        assert indexed.annotation_rows(token) == whole.annotation_rows(token)
        assert sample_summary(indexed.sample(token)) == sample_summary(whole.sample(token))
    for name in INDEXED_TABLES:
        for number, row in enumerate(json.loads((whole.table_dir / f"{name}.json").read_text())):
            assert indexed.get(name, row["token"]) == row
            assert indexed.row_number(name, row["token"]) == number
    assert indexed.sample_data_rows("no-such-sample") == [] == whole.sample_data_rows("no-such-sample")


def used_indexes(reader: NuScenesReader) -> set[str]:
    return {name for name, index in reader._indexes.items() if index is not None}


@pytest.mark.parametrize("dataset", DATASETS, ids=["samples", "sequence", "real-scene-0916"])
def test_indexed_tables_read_as_the_parsed_ones(dataset):
    root, version = dataset[0](), dataset[1]
    if not (root / version).is_dir():
        pytest.skip(f"{root / version} absent")
    indexed, whole = readers(root, version)
    assert_same_reading(indexed, whole)
    assert used_indexes(indexed) == set(INDEXED_TABLES)  # none fell back to parsing whole
    assert whole._indexes == {}
    assert not set(INDEXED_TABLES) & set(indexed._rows)  # and none was parsed whole on the way


def test_small_tables_are_parsed_whole_by_default():
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION, with_map=False)
    reader.sample(reader.sample_tokens()[0])
    assert used_indexes(reader) == set()
    assert {"sample_data", "ego_pose", "sample_annotation"} <= set(reader._rows)


AWKWARD = {
    "fileformat": 'jpg"}, {"token": "not-a-row", "sample_token": "x',
    "note": 'braces { } [ ] and \\"escaped quotes\\" and a backslash \\\\ and "token": "fake"',
    "tail": "ends with a backslash \\",
    "unicode": "caf\u00e9 \u2192 \U0001f697",
}


def awkward_dataset(tmp_path: Path) -> Path:
    """Bundled tables whose sample_data rows carry strings with braces, quotes and escapes; compact and
    indented layouts; one row larger than the test scan windows."""
    root = table_copy(tmp_path)
    rows = load(root, "sample_data")
    for i, row in enumerate(rows):
        row.update(AWKWARD if i % 2 else {"note": "{" * 3 + "}" * 2})
    rows[3]["long"] = "x" * 5000
    save(root, "sample_data", rows, separators=(",", ":"))  # compact
    save(root, "sample_annotation", load(root, "sample_annotation"), indent=3, ensure_ascii=False)
    save(root, "ego_pose", load(root, "ego_pose"), indent="\t")
    return root


def test_strings_with_braces_quotes_and_escapes(tmp_path):
    root = awkward_dataset(tmp_path)
    indexed, whole = readers(root, BUNDLED_VERSION)
    assert_same_reading(indexed, whole)
    assert used_indexes(indexed) == set(INDEXED_TABLES)
    row = indexed.sample_data_rows(whole.sample_tokens()[0])[1]
    assert row["fileformat"] == AWKWARD["fileformat"] and row["tail"].endswith("\\")


@pytest.mark.parametrize("window", [64, 100, 4096])
def test_small_scan_windows_find_the_same_rows(tmp_path, window):
    root = awkward_dataset(tmp_path)
    path = root / BUNDLED_VERSION / "sample_data.json"
    keys = INDEXED_TABLES["sample_data"]
    big, small = ti.scan_table(path, keys), ti.scan_table(path, keys, window_bytes=window)
    for name in big:
        np.testing.assert_array_equal(small[name], big[name])
    data, rows = path.read_bytes(), json.loads(path.read_text())
    assert [json.loads(data[o: o + n]) for o, n in zip(small["offset"], small["length"])] == rows
    assert small["hash_token"].tolist() == [ti.text_hash(r["token"]) for r in rows]


def test_hashes_do_not_depend_on_the_padding():
    texts = ["", "a", "ab", "abcdefgh", "abcdefghi", "x" * 40, "tok\u00e9n"]
    raw = [t.encode() for t in texts]
    values = np.zeros((len(raw), 64), np.uint8)
    for i, r in enumerate(raw):
        values[i, : len(r)] = np.frombuffer(r, np.uint8)
    hashes = ti.value_hashes(values, np.array([len(r) for r in raw]))
    assert hashes.tolist() == [ti.text_hash(t) for t in texts]
    assert len(set(hashes.tolist())) == len(texts)



def cached_ego_pose_index(tmp_path: Path, cache_home: Path) -> tuple[Path, Path, dict[str, np.ndarray]]:
    """A copy of the bundled tables read once (every index cached): (its root, the ego_pose index's cache file,
    that file's arrays)."""
    root = table_copy(tmp_path)
    assert_same_reading(*readers(root, BUNDLED_VERSION))
    (cached,) = (cache_home / "streetaug" / "tables").glob("ego_pose-*.npz")
    with np.load(cached, allow_pickle=False) as z:
        return root, cached, dict(z)

class TestCache:
    def test_the_second_reader_loads_the_cached_index(self, tmp_path, cache_home):
        root = table_copy(tmp_path)
        start = ti.scan_count()
        first, whole = readers(root, BUNDLED_VERSION)
        assert_same_reading(first, whole)
        assert ti.scan_count() - start == len(INDEXED_TABLES)
        cached = sorted((cache_home / "streetaug" / "tables").glob("*.npz"))
        assert len(cached) == len(INDEXED_TABLES)
        again = NuScenesReader(root, BUNDLED_VERSION, with_map=False, index_min_bytes=0)
        assert_same_reading(again, whole)
        assert ti.scan_count() - start == len(INDEXED_TABLES)  # no new scan
        assert used_indexes(again) == set(INDEXED_TABLES)
        assert not list((cache_home / "streetaug" / "tables").glob("*.tmp"))

    @pytest.mark.parametrize("change", ["mtime", "size"])
    def test_a_changed_file_is_scanned_again(self, tmp_path, change):
        root = table_copy(tmp_path)
        path = root / BUNDLED_VERSION / "sample_data.json"
        rows = load(root, "sample_data")
        save(root, "sample_data", rows, indent=1)
        assert_same_reading(*readers(root, BUNDLED_VERSION))  # every index cached
        if change == "size":
            new = "a-new-first-row"
            rows.insert(0, {**rows[0], "token": new, "sample_token": "elsewhere"})
        else:  # a token of the same length: the same size, only the mtime tells
            new = rows[0]["token"][::-1]
            rows[0]["token"] = new
        before = path.stat()
        save(root, "sample_data", rows, indent=1)
        assert (path.stat().st_size == before.st_size) == (change == "mtime")
        os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns + 10**9))
        start = ti.scan_count()
        again, whole = readers(root, BUNDLED_VERSION)
        assert again.row_number("sample_data", new) == 0
        assert ti.scan_count() - start == 1
        assert_same_reading(again, whole)
        assert ti.scan_count() - start == 1

    def test_a_corrupt_cache_file_is_rebuilt(self, tmp_path, cache_home):
        root = table_copy(tmp_path)
        assert_same_reading(*readers(root, BUNDLED_VERSION))  # every index cached
        (cached,) = (cache_home / "streetaug" / "tables").glob("sample_data-*.npz")
        for garbage in (b"not a zip file", cached.read_bytes()[: 200]):
            cached.write_bytes(garbage)
            start = ti.scan_count()
            indexed, whole = readers(root, BUNDLED_VERSION)
            assert_same_reading(indexed, whole)
            assert ti.scan_count() - start == 1  # sample_data only
            with np.load(cached, allow_pickle=False) as z:  # rewritten whole
                assert len(z["offset"]) == len(load(root, "sample_data"))

    def test_a_cache_file_of_other_arrays_is_rebuilt(self, tmp_path, cache_home):
        root, cached, arrays = cached_ego_pose_index(tmp_path, cache_home)
        for edit in (lambda a: a.update(offset=a["offset"][:-1]),  # a length that differs
                     lambda a: a.update(length=a["length"].astype(np.float64)),
                     lambda a: a.update(sorted_token=a["sorted_token"][::-1].copy()),  # not in order
                     lambda a: a.pop("order_token")):
            bad = dict(arrays)
            edit(bad)
            with open(cached, "wb") as f:
                np.savez(f, **bad)
            start = ti.scan_count()
            indexed, whole = readers(root, BUNDLED_VERSION)
            assert_same_reading(indexed, whole)
            assert ti.scan_count() - start == 1

    def test_a_damaged_row_span_fails_naming_the_cache_which_is_then_rebuilt(self, tmp_path, cache_home):
        root, cached, arrays = cached_ego_pose_index(tmp_path, cache_home)
        arrays["offset"] = arrays["offset"] + 10**9  # past the end of the file: found only when a row is read
        with open(cached, "wb") as f:
            np.savez(f, **arrays)
        indexed, whole = readers(root, BUNDLED_VERSION)
        with pytest.raises(DatasetError, match="inconsistent") as e:
            indexed.sample(whole.sample_tokens()[0])
        assert str(cached) in str(e.value) and not cached.exists()
        start = ti.scan_count()
        assert_same_reading(readers(root, BUNDLED_VERSION)[0], whole)
        assert ti.scan_count() - start == 1

    def test_an_unwritable_cache_folder_still_reads_warning_once(self, tmp_path, monkeypatch, caplog):
        blocker = tmp_path / "a_file"
        blocker.write_text("")
        monkeypatch.setenv("XDG_CACHE_HOME", str(blocker / "cache"))  # mkdir fails, even for root
        monkeypatch.setattr(ti, "_warned", set())
        root = table_copy(tmp_path)
        with caplog.at_level(logging.WARNING, logger=ti.__name__):
            indexed, whole = readers(root, BUNDLED_VERSION)
            assert_same_reading(indexed, whole)
            start = ti.scan_count()
            assert_same_reading(readers(root, BUNDLED_VERSION)[0], whole)
        assert ti.scan_count() - start == len(INDEXED_TABLES)  # nothing cached: scanned again
        warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 1 and "cannot cache table indexes" in warnings[0].getMessage()


class TestErrors:
    @pytest.mark.parametrize("more", ["", "later repeats", "concatenated"])
    def test_a_duplicated_token_names_both_rows_as_before(self, tmp_path, more):
        root = table_copy(tmp_path)
        rows = load(root, "sample_annotation")
        rows.insert(7, dict(rows[2]))
        if more == "later repeats":  # repeats of earlier rows after row 7: row 7 is still the first repeat
            rows += [dict(rows[0]), dict(rows[1]), dict(rows[2])]
        elif more == "concatenated":  # the whole table again after it: its own repeat at 7 comes first
            rows += [dict(r) for r in rows]
        save(root, "sample_annotation", rows)
        messages = []
        for reader in readers(root, BUNDLED_VERSION):
            with pytest.raises(DatasetError) as e:
                reader.sample(reader.sample_tokens()[0])
            messages.append(str(e.value))
        assert messages[0] == messages[1]
        assert f"token '{rows[2]['token']}' appears in rows 2 and 7" in messages[0]
        assert "sample_annotation.json" in messages[0]

    def test_an_unknown_token_reads_as_before(self, tmp_path):
        root = table_copy(tmp_path)
        messages = []
        for reader in readers(root, BUNDLED_VERSION):
            with pytest.raises(DatasetError) as e:
                reader.get("ego_pose", "no-such-pose")
            messages.append(str(e.value))
        assert messages[0] == messages[1]
        assert f"no ego_pose with token 'no-such-pose' ({len(load(root, 'ego_pose'))} rows)" in messages[0]

    def test_a_row_that_is_not_json_names_the_file_and_the_row(self, tmp_path, monkeypatch):
        monkeypatch.setattr(ti, "VERIFIED_ROWS", 2)  # the first and the last row: row 1 is read when needed
        root = table_copy(tmp_path)
        path = root / BUNDLED_VERSION / "sample_data.json"
        rows = load(root, "sample_data")
        assert rows[1]["sample_token"] == rows[0]["sample_token"] and rows[1]["is_key_frame"] is True
        save(root, "sample_data", rows, indent=1)
        text = path.read_text()
        at = text.index('"is_key_frame": true', text.index('"is_key_frame": true') + 1)
        path.write_text(text[:at] + '"is_key_frame": tru' + text[at + len('"is_key_frame": true'):])
        indexed, whole = readers(root, BUNDLED_VERSION)
        with pytest.raises(DatasetError, match=r"sample_data.json: table is not valid JSON"):
            whole.sample(rows[0]["sample_token"])
        with pytest.raises(DatasetError, match=r"sample_data.json: table is not valid JSON \(row 1, bytes"):
            indexed.sample(rows[0]["sample_token"])
        assert used_indexes(indexed) >= {"sample_data"}
        with pytest.raises(DatasetError) as e:
            indexed.get("sample_data", rows[1]["token"])
        assert str(path.absolute()) in str(e.value)

    @pytest.mark.parametrize("edit, expect", [
        (lambda rows: rows[1].update(token=17), "row 1: field 'token' must be a string"),
        (lambda rows: rows[1].pop("token"), "expected a JSON list of rows, each with a 'token'"),
        (lambda rows: rows.append(5), "expected a JSON list of rows, each with a 'token'"),
    ])
    def test_a_table_the_scan_cannot_read_is_parsed_whole_with_its_errors(self, tmp_path, edit, expect):
        root = table_copy(tmp_path)
        rows = load(root, "sample_data")
        edit(rows)
        save(root, "sample_data", rows)
        for reader in readers(root, BUNDLED_VERSION):
            with pytest.raises(DatasetError, match=expect):
                reader.sample(reader.sample_tokens()[0])

    @pytest.mark.parametrize("edit", [
        lambda rows: rows[4].update(extra={"nested": {"token": "inner"}}),  # a nested object
        lambda rows: rows[4].update(sample_token=None),  # an indexed field that is not a string
        lambda rows: rows[4].update(sample_token="with \\ escape"),
        lambda rows: rows[4].update(token="t\u00e9\u00e9n"),  # written escaped (ensure_ascii)
    ])
    def test_layouts_the_scan_refuses_fall_back_to_parsing_whole(self, tmp_path, edit):
        root = table_copy(tmp_path)
        rows = load(root, "sample_data")
        edit(rows)
        save(root, "sample_data", rows)
        indexed, whole = readers(root, BUNDLED_VERSION)
        assert_same_reading(indexed, whole)
        assert used_indexes(indexed) == set(INDEXED_TABLES) - {"sample_data"}

    def test_text_between_rows_is_refused(self, tmp_path):
        root = table_copy(tmp_path)
        path = root / BUNDLED_VERSION / "sample_data.json"
        save(root, "sample_data", load(root, "sample_data"), indent=1)
        text = path.read_text()
        path.write_text(text.replace("\n },\n {", "\n }, 5,\n {", 1))
        with pytest.raises(ti.UnexpectedLayout, match="between rows"):
            ti.scan_table(path, ("token",))
        assert ti.open_index(path, ("token",)) is None


def test_a_slice_of_an_indexed_reader_reads_its_rows(tmp_path):
    """with_tables (what batch workers get) over an indexed reader: the rows given replace the files."""
    root = table_copy(tmp_path)
    indexed, whole = readers(root, BUNDLED_VERSION)
    token = whole.sample_tokens()[1]
    tables = {"sample_data": indexed.sample_data_rows(token), "sample_annotation": indexed.annotation_rows(token)}
    sliced = indexed.with_tables(tables, indexed.row_numbers_of(tables))
    assert sample_summary(sliced.sample(token)) == sample_summary(whole.sample(token))
    assert sliced.row_numbers_of(tables) == whole.row_numbers_of(tables)
    assert used_indexes(sliced) == {"ego_pose", "instance"}
    assert sliced.sample_data_rows(whole.sample_tokens()[0]) == []  # only the slice's rows


def test_check_table_counts_rows_without_parsing_an_indexed_table(tmp_path):
    root = table_copy(tmp_path)
    indexed, whole = readers(root, BUNDLED_VERSION)
    for name in ("sample_data", "ego_pose", "scene"):
        assert indexed.check_table(name) == whole.check_table(name) == len(load(root, name))
    assert "sample_data" not in indexed._rows and "sample_data" in whole._rows
