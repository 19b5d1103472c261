"""The lower body and the windows of a procedural car (issue #20: lower bodies and windows too dark)."""

import numpy as np
import pytest

from streetaug.augment.assets import car_body as cb
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.render.surface import prepare_asset

K = np.array([[1200.0, 0.0, 450.0], [0.0, 1200.0, 300.0], [0.0, 0.0, 1.0]])


def _bottom_band_materials(seed: int, body: str, yaw_deg: float, dist_m: float = 10.0) -> np.ndarray:
    """Material slots seen in the lowest 30 % of the car's image rows, camera 1.6 m above the ground."""
    car = procedural_car(seed, body)
    prep = prepare_asset(car)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    R = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    t = np.array([0.0, 1.6, dist_m])
    ys, xs = np.mgrid[0:600, 0:900]
    rays = np.stack([(xs.ravel() + 0.5 - K[0, 2]) / K[0, 0], (ys.ravel() + 0.5 - K[1, 2]) / K[1, 1],
                     np.ones(xs.size)], 1)
    hits = prep.scene.intersect(np.tile(-R.T @ t, (xs.size, 1)), rays @ R)
    rows = ys.ravel()[hits.hit]
    y0, y1 = rows.min(), rows.max()
    band = rows >= y0 + 0.7 * (y1 - y0)
    return prep.face_material[hits.face[hits.hit]][band]


@pytest.mark.parametrize("body", ["sedan", "hatchback", "suv"])
def test_lower_body_is_mostly_not_black_trim(body):
    # Black trim along the whole sill and up to the bumper line made 28-32 % of this band black from the side
    # and left 4-9 % of it painted from the front three-quarter view; real cars' bumpers and sills are mostly
    # body-coloured (the black is the tyres, the arches, a lower lip and the dark underside).
    side = _bottom_band_materials(4, body, 100.0)
    assert np.mean(side == cb.TRIM) < 0.25
    assert np.mean(np.isin(side, [cb.PAINT, cb.PAINT_LOWER])) > 0.2
    front = _bottom_band_materials(4, body, 150.0)
    assert np.mean(np.isin(front, [cb.PAINT, cb.PAINT_LOWER])) > 0.15


def test_clear_glass_reflects_both_faces_of_its_pane():
    # A window is one surface in the mesh: its reflection must be the pane's (both faces, ~5.4 % for the clear
    # front glass at normal incidence), not one face's 4 % (UE4 specular 0.5); dark privacy glass hides the
    # second face (~4.1 %).
    from streetaug.augment.assets.procedural import pane_specular

    for seed in range(6):
        car = procedural_car(seed)
        front = car.materials[cb.GLASS]
        assert 0.050 < 0.08 * front.specular < 0.058, front.specular
        rear = car.materials[cb.GLASS_REAR]
        assert 0.040 <= 0.08 * rear.specular <= 0.08 * front.specular + 1e-9
    assert pane_specular(np.zeros(3), 0.0) == pytest.approx(0.5)  # a black pane: its front face alone
    assert 0.08 * pane_specular(np.ones(3), 0.0) == pytest.approx(0.04 + 0.04 * 0.96**2)
