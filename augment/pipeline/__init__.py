"""The insertion pipeline: the stages wired together, sample -> placement -> lighting -> render -> labels.

It owns the per-sample context computed once and shared by the stages (:mod:`.context`: each camera's
LiDAR points, its one dense scene depth, the sample's lighting), the placement for the cameras of a sample
(:mod:`.place`), rendering several objects into one image (:mod:`.objects`), one camera of a sample
(:mod:`.view`), all cameras of a sample (:mod:`.sample`: :func:`insert_into_sample`, :func:`insert_into_view`),
the image form of ``streetaug insert`` (:mod:`.image`), the contract's output files (:mod:`.outputs`),
``streetaug insert`` from files to files (:mod:`.files`) and the inserted objects in the LiDAR sweep
(:mod:`.lidar`). Options and typed results live in :mod:`.options`
and :mod:`.results`.
"""

from .context import SampleContext, ViewContext, scene_depth, scene_depth_for_view
from .files import check_image_input, insert_image_to_files, insert_view_to_files, read_depth_map
from .image import insert_into_image
from .lidar import SampleSweep, SweepInsertion, insert_into_sweep, insert_placements_into_sweep
from .options import InsertOptions, item_seed, render_settings
from .outputs import LABELS_SCHEMA, labels_document, write_insert_outputs
from .place import SamplePlacement, place_in_sample, place_in_view
from .results import InsertResult, SampleInsertResult
from .sample import insert_into_sample, insert_into_view, insert_placed_into_sample, sample_lighting, \
    shared_sample_lighting

__all__ = [
    "InsertOptions", "InsertResult", "LABELS_SCHEMA", "SampleContext", "SampleInsertResult", "SamplePlacement",
    "SampleSweep", "SweepInsertion", "ViewContext", "check_image_input", "insert_image_to_files",
    "insert_into_image", "insert_into_sample", "insert_placed_into_sample", "insert_into_sweep", "insert_into_view", "insert_placements_into_sweep",
    "insert_view_to_files", "item_seed", "labels_document", "place_in_sample", "place_in_view", "read_depth_map",
    "render_settings", "sample_lighting", "shared_sample_lighting", "scene_depth", "scene_depth_for_view", "write_insert_outputs",
]
