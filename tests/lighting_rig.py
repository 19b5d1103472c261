"""The small pinhole camera the lighting tests look through: 96 x 64 px, focal 60 px, 1.5 m above the volume's
origin, looking along the volume's +x (camera x right, y down, z forward -> volume x forward, y left, z up)."""

from __future__ import annotations

import numpy as np

W, H, F = 96, 64, 60.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
CENTRE = np.array([0.0, 0.0, 1.5])
R_VOL_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
T_VOL_FROM_CAM = np.eye(4)
T_VOL_FROM_CAM[:3, :3], T_VOL_FROM_CAM[:3, 3] = R_VOL_FROM_CAM, CENTRE
