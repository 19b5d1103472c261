"""Lamps and cabin light of the procedural car (issue #20): a lamp's reflector behind its lens mirrors the
environment; the lens is clear, the reflector a near mirror; the cabin's light is the sky seen through its windows
(their solid angle from the seats x the pane's transmission), not a guess."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from streetaug.augment.assets import car_body as cb
from streetaug.augment.assets.car_body import BODY_WEIGHTS
from streetaug.augment.assets.procedural import procedural_car
from streetaug.augment.assets.validate import face_normals
from streetaug.augment.core.raycast import RayScene
from streetaug.augment.render import foreground
from streetaug.augment.render.brdf import BRDFParams, mirror_albedo
from streetaug.augment.render.insert import INTERIOR_SKY_FRACTION
from streetaug.augment.render.surface import SurfaceHits


class _Queue:
    def __init__(self, n: int) -> None:
        self.radiance = np.zeros((n, 4))
        self.added = 0

    def add(self, idx, *args) -> None:
        self.added += len(idx)


def test_a_reflector_behind_its_lens_mirrors_the_environment():
    """Metal seen through glass: tp^2 x its mirror albedo x the map at the mirror direction (was the cabin light)."""
    m = 3
    theta = np.radians([0.0, 30.0, 60.0])
    v = np.stack([np.sin(theta), np.zeros(m), np.cos(theta)], axis=1)
    params = BRDFParams.uniform(m, base_color=(0.85, 0.85, 0.86), metallic=1.0, roughness=0.1)
    surf = SurfaceHits(normal=np.tile([0.0, 0.0, 1.0], (m, 1)), geometric_normal=np.tile([0.0, 0.0, 1.0], (m, 1)),
                       front=np.ones(m, bool), material=np.full(m, cb.REFLECTOR), params=params, opacity=np.ones(m),
                       emission=np.zeros((m, 3)))
    sky = 2.0
    ctx = SimpleNamespace(env=SimpleNamespace(pyramid=[np.full((16, 32, 3), sky, np.float32)]),
                          R_cam_from_obj=np.eye(3), interior_rgb=np.full(3, 0.01), bounce=None)
    tp = np.full((m, 3), 0.8)
    queue = _Queue(m)
    foreground._shade_hits(ctx, surf, np.zeros((m, 3)), v, np.zeros(m, int), tp, np.arange(m), queue, inside_glass=True)
    expected = tp * tp * mirror_albedo(v[:, 2], params, np.ones(m)) * sky
    np.testing.assert_allclose(queue.radiance[:, :3], expected, rtol=1e-6)
    assert queue.added == 0  # not through the (occluded) full shading: the lens would block its own light


def test_lamp_lens_is_clear_and_its_reflector_a_near_mirror():
    for seed in range(4):
        mats = procedural_car(seed).materials
        lens, reflector = mats[cb.HEADLIGHT], mats[cb.REFLECTOR]
        assert float(np.mean(lens.base_color)) * lens.opacity < 0.1, lens  # the lens's own diffuse (was 0.24)
        assert reflector.roughness <= 0.1 and reflector.metallic == 1.0, reflector


def _cosine_dirs(normal: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    u1, u2 = rng.random((2, m))
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    t = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(normal, t)
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    return (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b + np.sqrt(1.0 - u1)[:, None] * normal


GROUND_TO_SKY = 0.15  # the street's radiance over the sky's (albedo ~0.15 under the sky's irradiance)


def cabin_irradiance_fraction(car, normal: np.ndarray, faces_of, n_points: int = 40, n_rays: int = 300,
                              seed: int = 0) -> float:
    """Mean over interior points (faces ``faces_of(M, n)``) of the irradiance on a surface of unit ``normal``
    through the windows, over the sky's horizontal irradiance ``pi L`` (uniform sky L; the ground at
    GROUND_TO_SKY L): ``1/pi int T cos dw``, T the renderer's transmission ``(1 - opacity) sqrt(tint) (1 - F)``
    of the glass the ray leaves by (F the pane Fresnel at its incidence), 0 where the car itself is in the way."""
    from streetaug.augment.render.brdf import mirror_fresnel

    rng = np.random.default_rng(seed)
    V, F, M = car.vertices, car.faces, car.face_material
    fn, area = face_normals(V, F)
    scene = RayScene(V, F)
    cand = np.flatnonzero(faces_of(M, fn))
    picks = rng.choice(cand, n_points, p=area[cand] / area[cand].sum())
    origins = np.repeat(V[F[picks]].mean(axis=1) + 0.01 * fn[picks], n_rays, axis=0)
    d = np.concatenate([_cosine_dirs(np.asarray(normal, float), n_rays, rng) for _ in picks])
    first = scene.intersect(origins, d)
    slot = M[np.maximum(first.face, 0)]
    t = np.zeros(len(d))
    for s in (cb.GLASS, cb.GLASS_REAR):
        sel = first.hit & (slot == s)
        mat = car.materials[s]
        p = BRDFParams.uniform(int(sel.sum()), base_color=mat.base_color, roughness=mat.roughness, specular=mat.specular)
        cos_g = np.abs(np.einsum("ij,ij->i", fn[first.face[sel]], d[sel]))
        t[sel] = (1.0 - mat.opacity) * np.sqrt(np.mean(mat.base_color)) * (1.0 - mirror_fresnel(cos_g, p)[:, 1])
    out = scene.intersect(origins + (first.t[:, None] + 1e-3) * d, d)
    radiance = np.where(d[:, 2] > 0.0, 1.0, GROUND_TO_SKY)
    return float(np.mean(t * ~out.hit * radiance))


def test_cabin_light_is_the_sky_through_the_windows():
    """INTERIOR_SKY_FRACTION x interior_shading(n) fits the windows' transmitted irradiance on seat cushions (n up:
    shading 1.5) and backrests (n forward: 1.0), over the body types by their weights, within 10 %."""
    fit = []
    for body, w in BODY_WEIGHTS.items():
        car = procedural_car(2, body)
        up = cabin_irradiance_fraction(car, np.array([0.0, 0.0, 1.0]), lambda M, n: (M == cb.INTERIOR) & (n[:, 2] > 0.9))
        fwd = cabin_irradiance_fraction(car, np.array([1.0, 0.0, 0.0]), lambda M, n: (M == cb.INTERIOR) & (n[:, 0] > 0.8))
        s_up, s_fwd = foreground.interior_shading(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), foreground.OBJECT_UP)
        fit.append((w, (s_up * up + s_fwd * fwd) / (s_up**2 + s_fwd**2)))  # least squares of c x shading
    c = sum(w * f for w, f in fit) / sum(w for w, _ in fit)
    assert abs(INTERIOR_SKY_FRACTION / c - 1.0) < 0.10, (INTERIOR_SKY_FRACTION, c, fit)
