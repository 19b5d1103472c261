"""Box sizes per nuScenes category, measured from a dataset's annotations (``sample_annotation.json``).

nuScenes keeps one size per instance (an annotator sizes the object once), so the statistics are over
instances: each instance contributes the median size of its boxes. The result is a plain dict per
category; :mod:`streetaug.augment.assets.class_sizes` turns it into the table procedural assets draw from.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from .errors import DatasetError
from .tables import read_table_rows, size_field


def instance_sizes(table_dir: str | Path) -> dict[str, list[np.ndarray]]:
    """Category name -> list of per-instance sizes (3,) [w, l, h] metres, with the box count per instance.

    Reads ``category.json``, ``instance.json`` and ``sample_annotation.json`` of one version folder.
    Each entry is ``np.array([w, l, h, n_boxes])``.

    Raises:
        DatasetError: a table is missing or a row lacks the fields used.
    """
    table_dir = Path(table_dir)
    categories = {r["token"]: r["name"] for r in read_table_rows(table_dir / "category.json")}
    instance_category = {}
    for i, r in enumerate(read_table_rows(table_dir / "instance.json")):
        if r.get("category_token") not in categories:
            raise DatasetError(f"{table_dir / 'instance.json'}: row {i}: field 'category_token' "
                               f"{r.get('category_token')!r} is not in category.json")
        instance_category[r["token"]] = categories[r["category_token"]]
    per_instance: dict[str, list[np.ndarray]] = {}
    for i, r in enumerate(read_table_rows(table_dir / "sample_annotation.json")):
        if r.get("instance_token") not in instance_category:
            raise DatasetError(f"{table_dir / 'sample_annotation.json'}: row {i}: field 'instance_token' "
                               f"{r.get('instance_token')!r} is not in instance.json")
        wlh = size_field(r.get("size"), f"{table_dir / 'sample_annotation.json'}: row {i}: field 'size'")
        per_instance.setdefault(r["instance_token"], []).append(wlh)
    out: dict[str, list[np.ndarray]] = {}
    for token, sizes in per_instance.items():
        size = np.median(np.stack(sizes), axis=0)
        out.setdefault(instance_category[token], []).append(np.r_[size, len(sizes)])
    return out


def measure_box_sizes(table_dirs: Iterable[str | Path]) -> dict[str, dict]:
    """Per-category size statistics over every instance of the given version folders.

    Returns:
        category -> {"n_instances", "n_boxes", "mean_wlh", "std_wlh", "min_wlh", "max_wlh"} (lists of 3
        floats, metres, [w, l, h]; std is the population std over instances, 0 for a single instance).
    """
    pooled: dict[str, list[np.ndarray]] = {}
    for d in table_dirs:
        for category, rows in instance_sizes(d).items():
            pooled.setdefault(category, []).extend(rows)
    stats = {}
    for category, rows in sorted(pooled.items()):
        a = np.stack(rows)
        wlh = a[:, :3]
        stats[category] = {
            "n_instances": int(len(a)), "n_boxes": int(a[:, 3].sum()),
            "mean_wlh": np.round(wlh.mean(0), 3).tolist(), "std_wlh": np.round(wlh.std(0), 3).tolist(),
            "min_wlh": np.round(wlh.min(0), 3).tolist(), "max_wlh": np.round(wlh.max(0), 3).tolist(),
        }
    return stats


__all__ = ["instance_sizes", "measure_box_sizes"]
