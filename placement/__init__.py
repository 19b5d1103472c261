"""Where inserted objects go: candidates in a camera's view, filtered by the placement rules, and their labels.

Owns the rules (drivable area from the map, lidarseg or the LiDAR ground; clearance from annotated boxes,
LiDAR obstacles and non-drivable classes; distance; in view and visible enough on the renderer's scene
depth; mutual clearance), the local ground plane under each object, the labels of inserted objects
(``labels.json`` contract), an independent re-check of final placements (``audit``) and a bird's-eye
explanation (``explain``). Imports only the core, ``datasets`` and ``assets``; :func:`place_objects`
takes the objects (assets or :class:`ObjectBox` sizes) and returns placements naming them by index.
"""

from .audit import AUDITED_RULES, audit_placements
from .candidates import CameraAzimuthRange, camera_azimuth_range, object_transforms
from .config import PlacementConfig
from .drivable import DrivableArea, drivable_area_for_sample
from .explain import draw_placement_bev
from .ground import GroundPlane, LocalGroundFitter
from .labels import bbox_from_mask, object_label, placement_label_fields
from .place import RULE_ORDER, ObjectBox, Placeable, Placement, PlacementResult, place_objects
from .scene import PlacementScene, scene_depth

__all__ = [
    "AUDITED_RULES", "CameraAzimuthRange", "DrivableArea", "GroundPlane", "LocalGroundFitter", "ObjectBox",
    "Placeable", "Placement", "PlacementConfig", "PlacementResult", "PlacementScene", "RULE_ORDER",
    "audit_placements", "bbox_from_mask", "camera_azimuth_range", "draw_placement_bev", "drivable_area_for_sample",
    "object_label", "object_transforms", "place_objects", "placement_label_fields", "scene_depth",
]
