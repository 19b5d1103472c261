"""Reading the ground-truth lighting of the generated sample scenes back, for accuracy tests.

``ground_truth/<scene>/lighting.json`` (written by :mod:`.make`) holds the sun and sky parameters the
images were rendered with and the exposure k; :func:`ground_truth_light` rebuilds the exact distant
light (analytic sky + sun) in a camera's frame on the image's radiometric scale, comparable with
``streetaug predict-light``'s ``envmap_camera.exr`` (sky dome only: below the horizon it is the sky
model's uniform ground, not the street's buildings).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from streetaug.augment.io import InputError, read_json
from streetaug.augment.lighting.light import DistantLight
from streetaug.augment.lighting.sky import make_sky_light


def read_ground_truth(dataroot: str | Path, scene_name: str) -> dict:
    """The parsed ``lighting.json`` of a generated scene."""
    path = Path(dataroot) / "ground_truth" / scene_name / "lighting.json"
    gt = read_json(path)
    if gt.get("schema") != "streetaug.sample_lighting/1":
        raise InputError(f"{path}: field 'schema' is {gt.get('schema')!r}, expected 'streetaug.sample_lighting/1'")
    return gt


def ground_truth_light(dataroot: str | Path, scene_name: str, channel: str = "CAM_FRONT",
                       height: int = 128, width: int = 256) -> DistantLight:
    """Distant light (camera-frame equirect envmap (height, width, 3) + sun) of ``channel`` in a generated scene,
    on the image's radiometric scale (x exposure k)."""
    gt = read_ground_truth(dataroot, scene_name)
    cams = gt["cameras"]
    if channel not in cams:
        raise InputError(f"ground truth of {scene_name}: no camera {channel!r}; have {sorted(cams)}")
    sky = gt["sky"]
    light = make_sky_light(
        np.array(cams[channel]["sun_direction_camera"]), np.array(cams[channel]["up_direction_camera"]),
        turbidity=sky["turbidity"], cloud_cover=sky["cloud_cover"], ground_albedo=sky["ground_albedo"],
        height=height, width=width, scale=gt["exposure_k"],
    )
    if light.sun is not None:
        light = replace(light, sun=replace(light.sun, half_angle_rad=float(np.radians(gt["sun"]["half_angle_deg"]))))
    return light
