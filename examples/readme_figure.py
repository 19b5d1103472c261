"""Make the README's result picture from the bundled sample scenes (before | after crops).

    .venv/bin/python examples/readme_figure.py            # writes examples/readme/result.jpg
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from streetaug.augment.assets.select import select_assets  # noqa: E402
from streetaug.augment.core import write_image_rgb  # noqa: E402
from streetaug.augment.pipeline import InsertOptions, insert_into_view, item_seed  # noqa: E402
from streetaug.datasets.bundled import BUNDLED_VERSION, bundled_dataroot  # noqa: E402
from streetaug.datasets.nuscenes import NuScenesReader  # noqa: E402

# (scene, seed, crop rows, crop cols) chosen to show cars in sun and in building shadow.
PANELS = [("sample-sunny", 1, (380, 680), (150, 950)), ("sample-lowsun", 1, (430, 730), (100, 900))]
OUT = Path(__file__).with_name("readme") / "result.jpg"


def main() -> None:
    reader = NuScenesReader(bundled_dataroot(), BUNDLED_VERSION)
    rows = []
    for scene, seed, (y0, y1), (x0, x1) in PANELS:
        sample = reader.sample(reader.sample_tokens(scene)[0])
        view = sample.cameras["CAM_FRONT"]
        assets = select_assets(item_seed(seed, "asset", sample.token, view.channel), 2)
        result = insert_into_view(sample, view, assets, InsertOptions(seed=seed, n_objects=2))
        before, after = view.image[y0:y1, x0:x1], result.image[y0:y1, x0:x1]
        gap = np.full((y1 - y0, 8, 3), 255, np.uint8)
        rows.append(np.hstack([before, gap, after]))
        rows.append(np.full((8, rows[-1].shape[1], 3), 255, np.uint8))
    figure = np.vstack(rows[:-1])
    figure = cv2.resize(figure, None, fx=0.75, fy=0.75, interpolation=cv2.INTER_AREA)
    write_image_rgb(OUT, figure, jpeg_quality=88)
    print(f"wrote {OUT} ({figure.shape[1]}x{figure.shape[0]})")


if __name__ == "__main__":
    main()
