"""The channel layout of the light volume's per-voxel parameters (shared by both backends of :mod:`.volume`).

A voxel holds ``N_CHANNELS`` floats: its RGB radiance (``CH_COLOR``), the axis of its directional lobe
(``CH_AXIS``), its lobe width (``CH_SIGMA``: the lobe is exp(-(1 - cos) / sigma^2)) and its opacity (``CH_ALPHA``).
"""

N_CHANNELS = 8
CH_COLOR, CH_AXIS, CH_SIGMA, CH_ALPHA = slice(0, 3), slice(3, 6), 6, 7
