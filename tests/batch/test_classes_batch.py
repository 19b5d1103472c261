"""Every nuScenes detection class on real photographs: placed by its rule, labelled as nuScenes labels it, rendered
inside its box.

Needs ``../shared/data`` (real scene-0916 and the scene-0061 keyframe; skips without them). The batch renders
the real keyframe's CAM_FRONT at draft quality (the labels and tables are tested here; the shading in tests/render).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import SHARED_DATA, devkit
from streetaug.augment.assets.categories import DETECTION_CLASSES
from streetaug.augment.assets.class_sizes import read_class_sizes
from streetaug.augment.assets.classes import CLASS_CATEGORIES, procedural_object
from streetaug.augment.batch import BatchConfig, RunOptions, read_log, run_batch
from streetaug.augment.core import transform_points
from streetaug.augment.pipeline import InsertOptions
from streetaug.augment.pipeline.sample import insert_into_sample
from streetaug.datasets.nuscenes import NuScenesReader
from streetaug.placement.audit import audit_placements
from streetaug.placement.class_rules import read_class_rules
from streetaug.placement.place import ObjectBox, place_objects

SEQ = SHARED_DATA / "nuscenes-seq"
REAL = SHARED_DATA / "nuscenes-real"
pytestmark = pytest.mark.skipif(not (SEQ / "v1.0-mini" / "sample.json").is_file()
                                or not (REAL / "v1.0-mini" / "sample.json").is_file(),
                                reason=f"{SEQ} / {REAL} (real nuScenes scenes) not present")
DETECTION_NAME = {"human.pedestrian.adult": "pedestrian", "human.pedestrian.child": "pedestrian"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("classes") / "out"
    config = BatchConfig(dataroot=str(REAL.resolve()), version="v1.0-mini", cameras=("CAM_FRONT",), quality="draft",
                         level="L1", seed=5, n_objects=6, classes=",".join(DETECTION_CLASSES))
    summary = run_batch(config, out, RunOptions(workers=1, progress=False, contact_sheet=0))
    return out, summary


def test_the_real_scene_takes_objects_of_many_classes_with_their_attributes(run):
    out, summary = run
    rows = read_log(out / "augment_log.jsonl")
    objects = [o for r in rows if r.status == "ok" for o in r.objects or ()]
    categories = {o.category for o in objects}
    assert len(categories) >= 4, categories
    assert summary["objects_per_category"] == {c: sum(o.category == c for o in objects) for c in categories}
    rules = read_class_rules()
    for o in objects:
        mode = rules.for_category(o.category).attribute
        if mode == "vehicle":
            assert o.attribute in ("vehicle.parked", "vehicle.moving")
        elif mode == "parked":
            assert o.attribute == "vehicle.parked"
        elif mode == "asset":
            assert o.attribute in ("cycle.with_rider", "cycle.without_rider", "pedestrian.moving",
                                   "pedestrian.standing")
        else:
            assert o.attribute is None


def test_devkit_detection_loader_reads_every_inserted_class(run):
    """The evaluation's own ground-truth loader (scene-0061 is in mini_train): each inserted box keeps the
    detection class of its category and an attribute the benchmark accepts for it."""
    from nuscenes.eval.common.loaders import load_gt
    from nuscenes.eval.detection.data_classes import DetectionBox
    from nuscenes.eval.detection.utils import category_to_detection_name

    out, _ = run
    nusc = devkit().NuScenes(version="v1.0-mini", dataroot=str(out), verbose=False)
    ours = {o.box_global["translation"][0]: o for r in read_log(out / "augment_log.jsonl") if r.status == "ok" for o in r.objects or ()}
    gt = load_gt(nusc, "mini_train", DetectionBox)
    found = set()
    for token in gt.sample_tokens:
        for box in gt[token]:
            mine = [o for x, o in ours.items() if abs(x - box.translation[0]) < 1e-4]
            if not mine:
                continue
            o = mine[0]
            assert box.detection_name == category_to_detection_name(o.category)
            assert box.attribute_name == (o.attribute or "")
            found.add(box.detection_name)
    assert len(found) >= 3, found


def test_every_class_places_on_the_real_street_without_a_rule_violation():
    """Scene-0916 (narrow Singapore street, raster map, no lidarseg): each class at its nuScenes mean size in
    CAM_BACK of its middle keyframe; every placement (cluster members included) passes the audit."""
    from streetaug.placement.scene import scene_depth

    reader = NuScenesReader(SEQ, "v1.0-mini")
    tokens = reader.sample_tokens()[20:21]
    sizes = read_class_sizes()
    placed = {}
    for token in tokens:
        sample = reader.sample(token)
        for channel in ("CAM_BACK",):
            view = sample.cameras[channel]
            depth_m = scene_depth(sample, view)
            for cls in DETECTION_CLASSES:
                category = CLASS_CATEGORIES[cls][0][0]
                r = place_objects(sample, view, [ObjectBox(sizes[category].mean_wlh, category)],
                                  np.random.default_rng(1), depth_m=depth_m)
                audits = audit_placements(sample, view, r.placements, r.drivable, r.config)
                bad = [(p.detection_class, p.zone, {k for k, v in a.passed.items() if not v})
                       for p, a in zip(r.placements, audits) if not a.ok]
                assert not bad, bad
                placed[cls] = placed.get(cls, 0) + len(r.placements)
                if not r.placements:
                    assert cls in r.class_reasons
    assert sum(v > 0 for v in placed.values()) >= 6, placed
    for cls in ("car", "pedestrian", "traffic_cone", "barrier"):
        assert placed[cls] > 0, placed


@pytest.mark.parametrize("cls", ["bicycle", "pedestrian", "traffic_cone"])
def test_rendered_pixels_lie_inside_the_projected_box(cls):
    """>= 99.5 % of an inserted object's alpha lies inside the convex hull of its projected 3D box (thin
    bicycle frames and spokes, a pedestrian's limbs, a cone's base)."""
    reader = NuScenesReader(REAL, "v1.0-mini")
    sample = reader.sample(reader.sample_tokens()[0])
    view = sample.cameras["CAM_FRONT"]
    asset = procedural_object(cls, 11)
    result = insert_into_sample(sample, [view], {"CAM_FRONT": [asset]},
                                InsertOptions(quality="draft", level="L1", seed=2))
    placements = [p for p in result.placements if p.cluster_of < 0]
    if not placements:
        pytest.skip(f"no {cls} placement in this view ({result.skipped_reason})")
    mask = result.views["CAM_FRONT"].mask
    hull = np.zeros(mask.shape, np.uint8)
    for p in result.placements:  # a cone's line: every member's box
        corners = transform_points(view.T_cam_from_global, p.box.corners())
        uv = corners @ view.K.T
        uv = uv[:, :2] / uv[:, 2:3]
        cv2.fillConvexPoly(hull, cv2.convexHull(np.round(uv).astype(np.int32)), 1)
    hull = cv2.dilate(hull, np.ones((3, 3), np.uint8))  # the hull's edge pixels (pixel-centre rounding)
    inside = float((mask * hull).sum() / max(mask.sum(), 1e-9))
    assert mask.sum() > 20 and inside >= 0.995, (cls, inside, float(mask.sum()))
