"""The objects to insert: triangle meshes in metres with PBR materials, a canonical box and a nuScenes category.

Owns the :class:`Asset` type, the loader of untrusted glTF/GLB, OBJ and PLY files (references checked
first), mesh validation, the asset-name -> category mapping, the procedural cars (body, wheels, paint) and
the choice of assets for a run. Imports only the core.
"""

from .asset import Asset, Material
from .categories import NUSCENES_OBJECT_CATEGORIES, category_for_asset
from .loader import list_assets, load_asset
from .procedural import paint_palette, procedural_car, procedural_car_variants
from .select import load_asset_options, select_assets
from .validate import ValidationReport, validate_asset, validate_asset_report

__all__ = [
    "Asset", "Material", "NUSCENES_OBJECT_CATEGORIES", "ValidationReport", "category_for_asset", "list_assets",
    "load_asset", "load_asset_options", "paint_palette", "procedural_car", "procedural_car_variants",
    "select_assets", "validate_asset", "validate_asset_report",
]
