"""The sun on the real nuScenes keyframe agrees with the shadows visible in its CAM_FRONT image.

The image (scene-0061, Singapore one-north, 2018-07-24 03:28 UTC) shows the parked truck on the left
casting its shadow forward and to the right onto the road, i.e. away from the camera: the sun must be
high, behind the camera and on its left.  Independently of any image analysis, the ephemeris path
must say exactly that.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from streetaug.augment.lighting.sun import sun_direction_camera, sun_direction_global

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "nuscenes-real"
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"


@pytest.mark.skipif(not (REAL / "v1.0-mini").is_dir(), reason=f"real nuScenes excerpt not found at {REAL}")
def test_sun_behind_left_and_high_as_the_shadows_show():
    from streetaug.datasets.nuscenes import NuScenesReader

    sample = NuScenesReader(REAL, "v1.0-mini").sample(REAL_SAMPLE)
    view = sample.cameras["CAM_FRONT"]
    pos = sun_direction_global(sample.location, view.timestamp_us)
    assert pos.elevation_deg == pytest.approx(58.8, abs=0.5)
    assert pos.azimuth_deg == pytest.approx(51.7, abs=1.0)  # north-east, near-noon in July at 1.3 deg N
    d_cam = sun_direction_camera(view, sample.location)
    assert d_cam[2] < -0.3 and d_cam[1] < -0.7 and d_cam[0] < -0.1  # behind, up, left
    # Shadows on the ground run along -sun projected on the ground: forward (+z) and right (+x).
    shadow_dir = -d_cam[[0, 2]]
    assert shadow_dir[1] > 0 and shadow_dir[0] > 0
    assert np.degrees(np.arctan2(shadow_dir[0], shadow_dir[1])) == pytest.approx(29, abs=10)
