"""The bundled sample scenes: procedural streets rendered, scanned and written as a nuScenes dataset.

Owns the street generator (geometry, materials, annotated objects), its renderer (embree, sun and sky),
the LiDAR and lidarseg simulation, the nuScenes tables of the generated scenes and the ground-truth light
they were rendered with. Entry point: :func:`make_sample_scenes` (``streetaug make-samples``); same
arguments on the same machine give byte-identical files.
"""

from .ground_truth import GroundTruthScene, ground_truth_light, read_ground_truth
from .make import CAMERA_RIGS, SAMPLE_SCENES, choose_exposure, make_sample_scenes
from .render import SkyParams, StreetRenderer
from .street import StreetParams, StreetScene, build_street

__all__ = [
    "CAMERA_RIGS", "GroundTruthScene", "SAMPLE_SCENES", "SkyParams", "StreetParams", "StreetRenderer", "StreetScene",
    "build_street", "choose_exposure", "ground_truth_light", "make_sample_scenes", "read_ground_truth",
]
