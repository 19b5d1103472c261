"""The reader on corrupt and malicious tables (copies of the bundled scenes): each error names the table, row,
token and field, and is raised where the bad value is needed (a camera's image, the LiDAR, the boxes)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import fault_cases as fc
from streetaug.augment.core import InputError
from streetaug.datasets import DatasetError, NuScenesReader


@pytest.fixture()
def root(tmp_path):
    return fc.copy_bundled(tmp_path / "data")


def reader(root) -> NuScenesReader:
    return NuScenesReader(root, fc.VERSION)


def rows(root, table: str) -> list[dict]:
    return json.loads((root / fc.VERSION / f"{table}.json").read_text())


def first_camera(root) -> tuple[int, dict]:
    table = rows(root, "sample_data")
    row = fc.first_camera_row(table)
    return table.index(row), row


class TestTablePaths:
    @pytest.mark.parametrize("filename, expect", [("../private/secret_photo.jpg", "climbs outside"),
                                                  ("/etc/passwd", "absolute path")])
    def test_a_camera_path_out_of_the_dataroot_fails_when_its_image_is_opened(self, root, filename, expect):
        index, row = first_camera(root)
        fc.edit_table(root, "sample_data", lambda r: fc.first_camera_row(r).update(filename=filename))
        sample = reader(root).sample(row["sample_token"])  # building the sample opens no file
        with pytest.raises(InputError) as e:
            _ = sample.cameras["CAM_FRONT"].image
        msg = str(e.value)
        assert f"{fc.VERSION}/sample_data.json row {index} (token {row['token']}) field 'filename'" in msg
        assert filename in msg and expect in msg
        others = [c for c in sample.cameras if c != "CAM_FRONT"]
        assert sample.cameras[others[0]].image.ndim == 3  # the sample's other cameras still read

    def test_a_symlink_leaving_the_dataroot_is_refused(self, root, tmp_path):
        _, row = first_camera(root)
        outside = tmp_path / "outside.jpg"
        (root / row["filename"]).rename(outside)
        (root / row["filename"]).symlink_to(outside)
        with pytest.raises(InputError, match="outside"):
            _ = reader(root).sample(row["sample_token"]).cameras["CAM_FRONT"].image

    def test_a_symlinked_samples_folder_is_followed(self, root, tmp_path):
        (root / "samples").rename(tmp_path / "disk2")
        (root / "samples").symlink_to(tmp_path / "disk2")
        _, row = first_camera(root)
        assert reader(root).sample(row["sample_token"]).cameras["CAM_FRONT"].image.shape == (900, 1600, 3)

    def test_a_lidarseg_path_out_of_the_dataroot_fails_with_the_lidar(self, root):
        seg = rows(root, "lidarseg")[0]
        fc.edit_table(root, "lidarseg", lambda r: r[0].update(filename="../../labels.bin"))
        sd = next(r for r in rows(root, "sample_data") if r["token"] == seg["sample_data_token"])
        sample = reader(root).sample(sd["sample_token"])
        with pytest.raises(InputError, match=r"lidarseg.json row 0 .* field 'filename': '../../labels.bin' climbs"):
            _ = sample.lidar

    def test_a_location_climbing_out_of_the_maps_folder_is_refused(self, root):
        fc.edit_table(root, "log", lambda r: [row.update(location="../../../etc/x") for row in r])
        r = reader(root)
        with pytest.raises(InputError, match=r"map expansion of location '../../../etc/x'.*climbs outside"):
            r.sample(r.sample_tokens()[0])


class TestTableRows:
    def test_duplicated_tokens_are_refused_when_the_table_is_read(self, root):
        n = len(rows(root, "sample_annotation"))
        fc.edit_table(root, "sample_annotation", lambda r: r.append(dict(r[0])))
        token = rows(root, "sample_annotation")[0]["token"]
        with pytest.raises(DatasetError, match=f"sample_annotation.json: token '{token}' appears in rows 0 and {n}"):
            reader(root).table("sample_annotation")

    def test_a_non_numeric_timestamp_names_the_row_and_the_value(self, root):
        index, row = first_camera(root)
        fc.edit_table(root, "sample_data", lambda r: fc.first_camera_row(r).update(timestamp="yesterday"))
        with pytest.raises(DatasetError) as e:
            reader(root).sample(row["sample_token"])
        assert (f"sample_data.json row {index} (token {row['token']}) field 'timestamp': expected an integer"
                in str(e.value)) and "'yesterday'" in str(e.value)

    @pytest.mark.parametrize("field, value, expect", [
        ("rotation", [0, 0, 0, 0], "non-zero rotation quaternion"),
        ("rotation", [float("nan"), 0, 0, 1], "4 finite numbers"),
        ("size", [float("nan"), 4.0, 1.5], "[nan, 4.0, 1.5]"),
        ("size", [1.8, -4.0, 1.5], "positive box size"),
        ("translation", [1.0, 2.0], "box centre"),
    ])
    def test_a_bad_annotation_fails_its_sample_naming_the_field(self, root, field, value, expect):
        ann = rows(root, "sample_annotation")[3]
        fc.edit_table(root, "sample_annotation", lambda r: r[3].update({field: value}))
        r = reader(root)
        with pytest.raises(DatasetError) as e:
            r.sample(ann["sample_token"])
        assert f"sample_annotation.json row 3 (token {ann['token']}) field '{field}'" in str(e.value)
        assert expect in str(e.value)
        other = next(t for t in r.sample_tokens() if t != ann["sample_token"])
        assert r.sample(other).boxes  # the other samples still read

    def test_nan_in_a_lidar_file_is_counted(self, root):
        path = sorted((root / "samples" / "LIDAR_TOP").iterdir())[0]
        points = np.fromfile(path, np.float32).reshape(-1, 5)
        points[::10, 2] = np.inf
        points.tofile(path)
        sd = next(r for r in rows(root, "sample_data") if r["filename"].endswith(path.name))
        with pytest.raises(DatasetError) as e:
            _ = reader(root).sample(sd["sample_token"]).lidar
        assert path.name in str(e.value) and f"{len(points[::10])} of {len(points)} points are non-finite" in str(e.value)

    def test_an_image_whose_size_differs_from_its_row(self, root):
        index, row = first_camera(root)
        fc.edit_table(root, "sample_data", lambda r: fc.first_camera_row(r).update(width=800, height=450))
        with pytest.raises(DatasetError) as e:
            _ = reader(root).sample(row["sample_token"]).cameras["CAM_FRONT"].image
        assert (f"is 1600 x 900 but {fc.VERSION}/sample_data.json row {index} (token {row['token']}) says 800 x 450"
                in str(e.value)) and os.path.basename(row["filename"]) in str(e.value)

    def test_rows_of_a_slice_are_named_by_their_row_in_the_file(self, root):
        table = rows(root, "sample_data")
        row = fc.first_camera_row(table, index=2)
        index = table.index(row)
        fc.edit_table(root, "sample_data", lambda r: fc.first_camera_row(r, index=2).update(filename="../x.jpg"))
        full = reader(root)
        tables = {"sample_data": [r for r in full.sample_data_rows(row["sample_token"])]}
        with pytest.raises(InputError, match=f"sample_data.json row {index} "):
            _ = full.with_tables(tables, full.row_numbers_of(tables)).sample(row["sample_token"]).cameras["CAM_FRONT"].image
        with pytest.raises(InputError, match=r"sample_data.json \(token"):  # without them: the token only
            _ = full.with_tables(tables).sample(row["sample_token"]).cameras["CAM_FRONT"].image


class TestMap:
    def test_a_too_deep_map_expansion_names_the_file_and_is_not_skipped(self, root, monkeypatch):
        path = root / "maps" / "expansion" / "boston-seaport.json"
        path.write_text("[" * 100_000 + "]" * 100_000)
        r = reader(root)
        token = next(t for t in r.sample_tokens() if r.location_of(t) == "boston-seaport")
        with pytest.raises(InputError, match="boston-seaport.json: JSON nested too deeply"):
            r.sample(token)
        monkeypatch.setattr(path.__class__, "read_text", lambda *a, **k: pytest.fail("the map was parsed twice"))
        with pytest.raises(InputError, match="nested too deeply"):  # remembered: every sample of the location fails
            r.sample(token)

    def test_without_a_map_file_there_is_no_map(self, root):
        (root / "maps" / "expansion" / "boston-seaport.json").unlink()
        r = reader(root)
        token = next(t for t in r.sample_tokens() if r.location_of(t) == "boston-seaport")
        assert r.sample(token).drivable_area_global is None
