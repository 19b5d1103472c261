"""Write an augmented nuScenes dataset: the source tables copied and extended, untouched files referenced.

Layout written under ``out_dir`` (the devkit opens ``dataroot/filename``, so every file a table names
must be reachable under ``out_dir``)::

    out_dir/source -> <source dataroot>       symlink (absolute): every untouched file is read through it
    out_dir/maps, lidarseg, panoptic -> source/...   symlinks: the devkit opens these folders by name
    out_dir/<version>/*.json                  every source table, with these rows changed:
        sample_data        augmented camera rows -> "samples/<CHANNEL>/<name>" (the new image, under out_dir)
                           plus "source_filename"; every other row -> "source/" + filename
        lidarseg, panoptic, map (any "filename") -> "source/" + filename
        instance, sample_annotation            + one row each per inserted object
        category, attribute, visibility        + rows for names/tokens the source lacks
    out_dir/samples/<CHANNEL>/...             the augmented images (written by the batch, not here)

One link instead of copies: nothing of the source is duplicated or ever opened for writing, and the
tables tell at a glance which files are new. Moving ``out_dir`` keeps it valid; moving the source
needs the link updated (``ln -sfn NEW out_dir/source``). Tokens of new rows are md5 hashes of
(sample token, object index, seed), so the same run gives the same tables.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from streetaug.augment.core import InputError, atomic_path

from .nuscenes_format import VISIBILITY_LEVELS, new_token

SOURCE_LINK = "source"
# Source folders the devkit looks for under its dataroot itself (not through a table's filename):
# NuScenesMap reads maps/expansion/, NuScenes counts the files in lidarseg/<version>/ and panoptic/<version>/.
FOLDER_LINKS = ("maps", "lidarseg", "panoptic")


@dataclass(frozen=True)
class InsertedObject:
    """One inserted object as a nuScenes annotation (global frame, as ``sample_annotation``).

    Attributes:
        sample_token: the sample it was inserted into.
        object_index: its index among the sample's inserted objects.
        category: nuScenes category name, e.g. ``vehicle.car``.
        attribute: nuScenes attribute name (e.g. ``vehicle.parked``) or None.
        translation: [x, y, z] box centre, global frame, metres.
        size: [w, l, h] metres.
        rotation: [w, x, y, z] box -> global.
        visibility_token: "1".."4" (nuScenes visibility bins, over all cameras).
        seed: the batch seed (part of the tokens).
        num_lidar_pts: points of the (augmented) keyframe LiDAR sweep inside the box.
        instance_key: the instance it belongs to when it is one annotation of a track through several samples
            (e.g. ``"<scene token>/<track index>"``); objects of one key become one ``instance`` whose
            annotations are chained by ``prev``/``next`` in sample order. None: its own one-annotation instance.
    """

    sample_token: str
    object_index: int
    category: str
    attribute: str | None
    translation: Sequence[float]
    size: Sequence[float]
    rotation: Sequence[float]
    visibility_token: str
    seed: int = 0
    num_lidar_pts: int = 0
    instance_key: str | None = None

    @property
    def annotation_token(self) -> str:
        return new_token("sample_annotation", self.seed, self.sample_token, self.object_index)

    @property
    def instance_token(self) -> str:
        if self.instance_key is not None:
            return new_token("instance", self.seed, "track", self.instance_key)
        return new_token("instance", self.seed, self.sample_token, self.object_index)


def link_source(out_dir: str | Path, source_dataroot: str | Path) -> None:
    """Create ``out_dir/source`` (-> the source dataroot) and ``out_dir/maps`` etc. (-> source/maps, ...).

    Raises:
        InputError: ``out_dir`` and the source overlap, or ``out_dir/source`` points elsewhere.
    """
    src = Path(source_dataroot).resolve()
    out = Path(out_dir).resolve()
    if out == src or src in out.parents or out in src.parents:
        raise InputError(f"--out {out_dir}: must lie outside the source dataset {src} and not contain it "
                         "(the source is never written to); choose another output folder")
    out.mkdir(parents=True, exist_ok=True)
    link = out / SOURCE_LINK
    if not link.is_symlink():
        if link.exists():
            raise InputError(f"{link}: exists and is not the link to the source dataset; remove it or use a new --out")
        try:
            os.symlink(src, link, target_is_directory=True)
        except FileExistsError:  # another shard made it meanwhile
            pass
    if link.resolve() != src:
        raise InputError(f"{link}: links to {link.resolve()}, not to this run's source {src}; "
                         "use the same --dataroot to resume, or a new --out")
    for name in FOLDER_LINKS:
        folder = out / name
        if (src / name).is_dir() and not folder.is_symlink() and not folder.exists():
            try:
                os.symlink(Path(SOURCE_LINK) / name, folder, target_is_directory=True)
            except FileExistsError:
                pass


def write_augmented_tables(
    source_dataroot: str | Path,
    version: str,
    out_dir: str | Path,
    augmented_files: dict[str, str],
    objects: Sequence[InsertedObject],
    augmented_lidarseg: dict[str, str] | None = None,
    num_lidar_pts: dict[str, int] | None = None,
) -> Path:
    """Write ``out_dir/<version>/*.json``: the source tables with the augmented images and inserted objects.

    Args:
        source_dataroot: the source dataset root (holds ``<version>/``).
        augmented_files: ``sample_data`` token -> new file (image, LiDAR sweep) relative to ``out_dir``.
        objects: the inserted objects (new ``instance`` + ``sample_annotation`` rows).
        augmented_lidarseg: LiDAR ``sample_data`` token -> new lidarseg labels file relative to ``out_dir``.
        num_lidar_pts: source annotation token -> its new ``num_lidar_pts`` (points now on an inserted object).

    Returns:
        The table folder. Tables are written into a temporary folder that replaces the old one at the end.

    Raises:
        InputError: a token of ``augmented_files`` is not a sample_data row, or an object's sample is unknown.
    """
    src_tables = Path(source_dataroot) / version
    out_dir = Path(out_dir)
    final = out_dir / version
    tmp = out_dir / f".{version}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    changed = _changed_tables(src_tables, augmented_files, objects, augmented_lidarseg or {}, num_lidar_pts or {})
    for path in sorted(src_tables.glob("*.json")):
        name = path.stem
        if name in changed:
            _write_rows(tmp / path.name, changed[name])
        else:
            shutil.copyfile(path, tmp / path.name)
    for name, rows in changed.items():  # tables the source lacks (e.g. an empty attribute table)
        if not (tmp / f"{name}.json").exists():
            _write_rows(tmp / f"{name}.json", rows)
    old = out_dir / f".{version}.old-{os.getpid()}"
    if final.exists():
        os.replace(final, old)
    os.replace(tmp, final)
    shutil.rmtree(old, ignore_errors=True)
    return final


def _load(src_tables: Path, name: str) -> list[dict]:
    path = src_tables / f"{name}.json"
    if not path.is_file():
        return []
    return json.loads(path.read_text())


def _changed_tables(src_tables: Path, augmented_files: dict[str, str], objects: Sequence[InsertedObject],
                    augmented_lidarseg: dict[str, str], num_lidar_pts: dict[str, int]) -> dict:
    """Table name -> new rows, for every table that differs from the source."""
    out: dict[str, list[dict]] = {}
    for path in sorted(src_tables.glob("*.json")):
        if path.stem in ("sample_data", "sample_annotation", "instance", "category", "attribute", "visibility"):
            continue
        rows = json.loads(path.read_text())
        if isinstance(rows, list) and any(isinstance(r, dict) and r.get("filename") for r in rows):
            out[path.stem] = [_relinked(r) for r in rows]
    if augmented_lidarseg:
        out["lidarseg"] = [
            {**r, "filename": augmented_lidarseg[r["sample_data_token"]], "source_filename": r["filename"]}
            if r.get("sample_data_token") in augmented_lidarseg else _relinked(r)
            for r in _load(src_tables, "lidarseg")
        ]

    sample_data = []
    unused = dict(augmented_files)
    for r in _load(src_tables, "sample_data"):
        new = unused.pop(r["token"], None)
        if new is None:
            sample_data.append(_relinked(r))
        else:
            sample_data.append({**r, "filename": str(new), "source_filename": r["filename"]})
    if unused:
        raise InputError(f"{src_tables / 'sample_data.json'}: no sample_data rows with tokens "
                         f"{', '.join(sorted(unused)[:5])} (augmented images refer to them)")
    out["sample_data"] = sample_data

    categories = _load(src_tables, "category")
    attributes = _load(src_tables, "attribute")
    visibility = _load(src_tables, "visibility")
    category_token = {c["name"]: c["token"] for c in categories}
    attribute_token = {a["name"]: a["token"] for a in attributes}
    visibility_tokens = {v["token"] for v in visibility}
    samples = {s["token"] for s in _load(src_tables, "sample")}
    instances = _load(src_tables, "instance")
    annotations = [{**a, "num_lidar_pts": num_lidar_pts[a["token"]]} if a["token"] in num_lidar_pts else a
                   for a in _load(src_tables, "sample_annotation")]
    new_instances: dict[str, dict] = {}  # instance token -> its row (a track's annotations: one instance)
    last_of: dict[str, dict] = {}  # instance token -> its latest annotation row so far
    sample_order = {s["token"]: i for i, s in enumerate(_samples_in_time_order(src_tables))}
    objects = sorted(objects, key=lambda o: (sample_order.get(o.sample_token, len(sample_order)), o.object_index))
    for obj in objects:
        if obj.sample_token not in samples:
            raise InputError(f"{src_tables / 'sample.json'}: inserted object refers to unknown sample "
                             f"{obj.sample_token}")
        if obj.category not in category_token:
            row = {"token": new_token("category", obj.category), "name": obj.category,
                   "description": "added by streetaug (inserted objects)"}
            if categories and all("index" in c for c in categories):
                row["index"] = max(c["index"] for c in categories) + 1
            categories.append(row)
            category_token[obj.category] = row["token"]
        attribute_tokens = []
        if obj.attribute:
            if obj.attribute not in attribute_token:
                row = {"token": new_token("attribute", obj.attribute), "name": obj.attribute,
                       "description": "added by streetaug (inserted objects)"}
                attributes.append(row)
                attribute_token[obj.attribute] = row["token"]
            attribute_tokens = [attribute_token[obj.attribute]]
        if obj.visibility_token not in visibility_tokens:
            level, description = VISIBILITY_LEVELS[obj.visibility_token]
            visibility.append({"token": obj.visibility_token, "level": level, "description": description})
            visibility_tokens.add(obj.visibility_token)
        ann, inst = obj.annotation_token, obj.instance_token
        if inst not in new_instances:
            new_instances[inst] = {"token": inst, "category_token": category_token[obj.category],
                                   "nbr_annotations": 0, "first_annotation_token": ann, "last_annotation_token": ann}
        chain = new_instances[inst]
        chain["nbr_annotations"] += 1
        chain["last_annotation_token"] = ann
        previous = last_of.get(inst)
        if previous is not None:
            previous["next"] = ann
        last_of[inst] = annotation = {
            "token": ann, "sample_token": obj.sample_token, "instance_token": inst,
            "visibility_token": obj.visibility_token, "attribute_tokens": attribute_tokens,
            "translation": [float(v) for v in obj.translation], "size": [float(v) for v in obj.size],
            "rotation": [float(v) for v in obj.rotation], "prev": previous["token"] if previous else "", "next": "",
            "num_lidar_pts": int(obj.num_lidar_pts), "num_radar_pts": 0,
        }
        annotations.append(annotation)
    instances.extend(new_instances.values())
    out.update(category=categories, attribute=attributes, visibility=visibility, instance=instances,
               sample_annotation=annotations)
    return out


def _samples_in_time_order(src_tables: Path) -> list[dict]:
    """The ``sample`` rows by timestamp (a track's annotations are chained in time)."""
    return sorted(_load(src_tables, "sample"), key=lambda s: (s.get("timestamp", 0), s["token"]))


def _relinked(row: dict) -> dict:
    """The row with its file reached through the source link."""
    if not row.get("filename"):
        return row
    return {**row, "filename": f"{SOURCE_LINK}/{row['filename']}"}


def _write_rows(path: Path, rows: list[dict]) -> None:
    """A JSON list, one row per line (compact and diffable)."""
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write("[\n")
        for i, row in enumerate(rows):
            f.write(json.dumps(row, sort_keys=True) + (",\n" if i + 1 < len(rows) else "\n"))
        f.write("]\n")


__all__ = ["InsertedObject", "SOURCE_LINK", "link_source", "write_augmented_tables"]
