"""The bundled sample scenes: procedural streets rendered, scanned and written as a nuScenes dataset.

Owns the street generator (geometry, materials, annotated objects), its renderer (embree, sun and sky),
the LiDAR and lidarseg simulation, the nuScenes tables of the generated scenes and the ground-truth light
they were rendered with. Entry points: :func:`make_sample_scenes` (``streetaug make-samples``: one keyframe per
scene) and :func:`make_sequence_scene` (``streetaug make-samples --sequence [--sweeps]``: the ego driving through
keyframes and sweeps); same arguments on the same machine give byte-identical files.
"""

from .ground_truth import GroundTruthScene, ground_truth_light, read_ground_truth
from .make import CAMERA_RIGS, SAMPLE_SCENES, choose_exposure, make_sample_scenes
from .render import SkyParams, StreetRenderer
from .sequence import SEQUENCE_SCENE, SEQUENCE_VERSION, SequenceSpec, SequenceWorld, make_sequence_scene
from .street import StreetParams, StreetScene, build_street

__all__ = [
    "CAMERA_RIGS", "GroundTruthScene", "SAMPLE_SCENES", "SEQUENCE_SCENE", "SEQUENCE_VERSION", "SequenceSpec",
    "SequenceWorld", "SkyParams", "StreetParams", "StreetRenderer", "StreetScene", "build_street", "choose_exposure",
    "ground_truth_light", "make_sample_scenes", "make_sequence_scene", "read_ground_truth",
]
