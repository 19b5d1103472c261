"""L1's sun-visibility decision: the annotated objects' shadows, the cameras of one instant, night (issue 16.5).

Unit tests on synthetic evidence (the decision rule of :mod:`streetaug.augment.lighting.parametric`), then the
real dev scene (``../shared/data/nuscenes-seq``, scene-0916, overcast throughout: grey sky, wet road, no hard
shadow; checked by eye) and the one-north keyframe (sunny, hard shadows). The bounds on the real data are the
ones measured by ``benchmarks/bench_sun_shadows.py`` (``benchmarks/results/sun_shadows.json``) with a margin.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from streetaug.augment.core import luminance
from streetaug.augment.lighting import parametric as P
from streetaug.augment.lighting.sky import sky_horizontal_irradiance, sun_horizontal_irradiance, sun_visibility

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
SEQ = SHARED / "nuscenes-seq"
REAL = SHARED / "nuscenes-real"
REAL_SAMPLE = "ca9a282c9e77460f8360f564131a8af5"
needs_scenes = pytest.mark.skipif(not (SEQ / "v1.0-mini").is_dir() or not (REAL / "v1.0-mini").is_dir(),
                                  reason=f"real nuScenes dev data (nuscenes-seq, nuscenes-real) not found under {SHARED}")


def _evidence(contrasts=None, tokens=None, ground=None, cloud_sky=None, elevation_deg=48.0) -> P.L1Evidence:
    """L1 evidence with the model's constants at a sun ``elevation_deg`` up and the given image evidence."""
    sun_up = np.array([0.0, np.cos(np.radians(elevation_deg)), np.sin(np.radians(elevation_deg))])
    e_sun = float(luminance(sun_horizontal_irradiance(sun_up, 3.0, 0.0)))
    e0 = float(luminance(sky_horizontal_irradiance(sun_up, 3.0, 0.0)))
    e1 = float(luminance(sky_horizontal_irradiance(sun_up, 3.0, 1.0)))
    boxes = None
    if contrasts is not None:
        c = [float(x) for x in contrasts]
        boxes = {"objects": len(c), "contrast": max(c), "lit": 0.05, "per_object_contrast": c,
                 "per_object_lit": [0.05] * len(c),
                 "per_object_token": list(tokens) if tokens is not None else [f"box{i}" for i in range(len(c))]}
    sky = None if cloud_sky is None else {"blue_red": 1.0, "median_lum": 0.5}
    return P.L1Evidence(e_sun, e0, e1, ground, sky, None, None, cloud_sky, boxes)


def _ground(contrast: float, median: float = 0.02) -> dict:
    """A bimodal ground record: lit / shadow classes ``contrast`` apart around ``median``."""
    lit, shadow = median * np.sqrt(contrast), median / np.sqrt(contrast)
    return {"pixels": 5000, "median": median, "lit": lit, "shadow": shadow, "contrast": contrast, "otsu_eta": 0.85,
            "shadow_fraction": 0.4, "bimodal": True}


# --- the rule on synthetic evidence -------------------------------------------------------------------------

@pytest.mark.parametrize("contrasts, verdict, k", [
    ([], "unknown", 0),
    ([1.2, 1.1], "unknown", 0),  # too few objects to say "no sun"
    ([4.0], "sun", 1),  # one object, its shadow 4x darker than the road around it
    ([1.2, 1.0, 1.4], "no_sun", 0),
    ([3.0, 1.1, 1.0, 1.2, 1.0, 0.9], "no_sun", 1),  # 1 of 6: a canopy's shade, not the sun
    ([3.0, 3.5, 1.0, 1.0], "sun", 2),
    ([2.0, 2.2, 1.9], "no_sun", 0),  # ambient occlusion beside a parked car, not a sun shadow
])
def test_object_shadow_verdict(contrasts, verdict, k):
    v, n, kk, hard = P.object_shadow_verdict(contrasts)
    assert (v, n, kk) == (verdict, len(contrasts), k)
    if v == "sun":
        assert hard == pytest.approx(np.median([c for c in contrasts if c >= P.OBJECT_SHADOW_MIN_CONTRAST]))
    else:
        assert hard is None


def test_sun_shadows_give_a_visible_sun_from_their_median_contrast():
    ev = _evidence([5.0, 1.0, 6.0, 1.1])
    cloud, source, note = P.cloud_from_evidence(ev)
    assert source == "object_shadows" and "2 of 4" in note
    assert cloud == pytest.approx(P.cloud_from_contrast(5.5, ev.e_sun, ev.e_sky0, ev.e_sky1))
    assert sun_visibility(cloud) > 0.8  # 5.5x at 48 deg is nearly the clear-sky contrast (5.55)


def test_no_object_shadows_overrule_a_bimodal_ground():
    """A lit/shadow split of the ground with no sun shadow on several objects is albedo (grass, wet road)."""
    ground = _ground(10.0)
    alone = P.cloud_from_evidence(_evidence(ground=ground))
    assert alone[1] == "ground_contrast" and sun_visibility(alone[0]) > 0.9  # the ground alone reads as sun
    cloud, source, _ = P.cloud_from_evidence(_evidence([1.3, 1.1, 0.9, 1.6], ground=ground, cloud_sky=0.95))
    assert source == "no_object_shadows" and cloud == pytest.approx(0.95)
    cloud, source, _ = P.cloud_from_evidence(_evidence([1.3, 1.1, 0.9], ground=ground))  # no sky colour
    assert source == "no_object_shadows" and cloud == 1.0


def test_no_object_shadows_cap_the_sun_a_blue_sky_claims():
    ev = _evidence([1.3, 1.1, 0.9, 1.2], cloud_sky=0.0)
    cloud, _, _ = P.cloud_from_evidence(ev)
    floor = P.cloud_from_contrast(P.OBJECT_SHADOW_MIN_CONTRAST, ev.e_sun, ev.e_sky0, ev.e_sky1)
    assert cloud == pytest.approx(floor) and 0.2 < cloud < 0.8
    # the cap is physical: at that cover the model's sun would draw shadows of exactly the threshold contrast
    vis = sun_visibility(cloud)
    e_sky = (1 - cloud) * ev.e_sky0 + cloud * ev.e_sky1
    assert 1 + ev.e_sun * vis / e_sky == pytest.approx(P.OBJECT_SHADOW_MIN_CONTRAST, rel=0.1)


def test_without_objects_the_old_ranking_holds():
    assert P.cloud_from_evidence(_evidence(cloud_sky=0.3))[:2] == (0.3, "sky_colour")
    assert P.cloud_from_evidence(_evidence())[:2] == (0.5, "assumed")
    night = replace(_evidence([5.0]), e_sun=0.0)
    assert P.cloud_from_evidence(night)[1] == "night"


def _vi(channel: str, ev: P.L1Evidence):
    """A stand-in for :class:`..parametric.ViewInputs` with what :func:`shared_cloud` reads."""
    return SimpleNamespace(view=SimpleNamespace(channel=channel), evidence=ev)


def test_shared_cloud_judges_the_objects_of_all_views_together():
    # each camera alone: 1 sun shadow among 4 objects (25 %) -> sun; together 2 of 12 (17 %) -> no sun
    views = [_vi(f"CAM_{i}", _evidence([3.0, 1.0, 1.1, 1.2], tokens=[f"{i}a", f"{i}b", f"{i}c", f"{i}d"],
                                       cloud_sky=0.9)) for i in range(2)]
    views.append(_vi("CAM_2", _evidence([1.0, 1.1, 1.2, 0.9], tokens=["2a", "2b", "2c", "2d"], cloud_sky=1.0)))
    assert P.cloud_from_evidence(views[0].evidence)[1] == "object_shadows"
    cloud, note, record = P.shared_cloud(views)
    assert "no sun shadow on 10 of 12" in note and cloud == pytest.approx(0.9)  # median sky colour
    assert set(record) == {"object_shadows", "no_object_shadows"}


def test_shared_cloud_counts_an_object_seen_twice_once():
    a = _vi("CAM_FRONT", _evidence([4.0, 1.0, 1.0], tokens=["car", "x", "y"]))
    b = _vi("CAM_FRONT_LEFT", _evidence([4.5, 1.0], tokens=["car", "z"]))
    cloud, note, _ = P.shared_cloud([a, b])
    assert "1 of 4" in note  # car, x, y, z; the car's strongest contrast 4.5
    assert cloud == pytest.approx(P.cloud_from_contrast(4.5, a.evidence.e_sun, a.evidence.e_sky0, a.evidence.e_sky1))


def test_shared_cloud_pools_views_too_poor_alone():
    views = [_vi(f"CAM_{i}", _evidence([1.2], tokens=[f"t{i}"])) for i in range(3)]
    assert all(P.object_shadow_verdict([1.2])[0] == "unknown" for _ in views)
    cloud, note, _ = P.shared_cloud(views)
    assert cloud == 1.0 and "3 of 3" in note


def test_bimodal_ground_without_a_sun_scales_from_its_median():
    ev = _evidence(ground=_ground(9.0, median=0.02))
    cloud, scale, _, _ = P.solve_l1(ev, cloud=1.0, cloud_note="overcast given")
    assert scale == pytest.approx(np.pi * 0.02 / (P.GROUND_ALBEDO * ev.e_sky1))
    _, scale_sun, _, notes = P.solve_l1(ev, cloud=0.0)
    assert "scale from the sunlit ground" in notes
    assert scale_sun == pytest.approx(np.pi * 0.02 * 3.0 / (P.GROUND_ALBEDO * (ev.e_sun + ev.e_sky0)))


# --- the real dev scene ---------------------------------------------------------------------------------------

SEQ_KEYFRAMES = (0, 20, 40)


@pytest.fixture(scope="module")
def scenes():
    """The one-north sample and scene-0916 keyframes 0, 20, 40 with their L1 estimates (each camera alone;
    all cameras pooled)."""
    from streetaug.augment.lighting.api import estimate_lighting, estimate_sample_lighting
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(str(SEQ), "v1.0-mini")
    tokens = reader.sample_tokens("scene-0916")
    samples = [("sunny", NuScenesReader(str(REAL), "v1.0-mini").sample(REAL_SAMPLE))]
    samples += [("overcast", reader.sample(tokens[k])) for k in SEQ_KEYFRAMES]
    out = []
    for label, s in samples:
        cams = sorted(s.cameras)
        alone = {c: estimate_lighting(s.cameras[c], s.location, "L1", lidar=s.lidar, boxes=s.boxes) for c in cams}
        pooled = estimate_sample_lighting(s, cams, "L1")
        out.append((label, s, alone, pooled))
    return out


@needs_scenes
def test_cameras_estimated_together_report_one_sun(scenes):
    for _, s, _, pooled in scenes:
        vis = {c: e.sun_visibility for c, e in pooled.per_view.items()}
        assert len(vis) == len(s.cameras) and max(vis.values()) - min(vis.values()) < 1e-12, vis
        clouds = {e.fit.cloud_cover for e in pooled.per_view.values()}
        assert len(clouds) == 1
        suns = [np.asarray(s.cameras[c].T_global_from_cam)[:3, :3] @ e.sun_dir_cam
                for c, e in pooled.per_view.items() if e.sun_dir_cam is not None]
        assert suns and all(np.allclose(d, suns[0], atol=1e-6) for d in suns)  # one ephemeris sun


@needs_scenes
def test_pooled_decision_matches_the_sky(scenes):
    """Measured: pooled calls 42/42 samples right (bench); per camera alone 19-22 % of the overcast views still
    get vis >= 0.3 (was ~45 %) -- here <= 40 % of the 18 overcast views."""
    alone_sun = []
    for label, _, alone, pooled in scenes:
        vis = pooled.per_view[next(iter(pooled.per_view))].sun_visibility
        if label == "sunny":
            assert vis >= 0.3, pooled.reason
        else:
            assert vis < 0.1, pooled.reason
            alone_sun += [e.sun_visibility >= 0.3 for e in alone.values()]
    assert len(alone_sun) == 18 and np.mean(alone_sun) <= 0.4


@needs_scenes
def test_pooled_sun_does_not_move_over_an_overcast_scene(scenes):
    vis = [pooled.sun_visibility for label, _, _, pooled in scenes if label == "overcast"]
    assert max(vis) - min(vis) < 0.05


@needs_scenes
def test_a_real_view_at_local_midnight_has_no_sun(scenes):
    from streetaug.augment.lighting.api import estimate_lighting, estimate_views_lighting

    _, s, _, _ = scenes[0]  # the sunny one-north keyframe, with hard shadows in its images
    t = dt.datetime.fromtimestamp(s.cameras["CAM_FRONT"].timestamp_us / 1e6, dt.timezone.utc)
    midnight_sg = dt.datetime(t.year, t.month, t.day, 16, 0, tzinfo=dt.timezone.utc)  # 00:00 at UTC+8
    shift = int((midnight_sg - t).total_seconds() * 1e6)
    views = [replace(v, timestamp_us=v.timestamp_us + shift) for _, v in sorted(s.cameras.items())]
    one = estimate_lighting(views[0], s.location, "L1", lidar=s.lidar, boxes=s.boxes)
    assert one.sun_dir_cam is None and one.sun_visibility == 0.0 and "below the horizon" in one.reason
    together = estimate_views_lighting(views, s.location, "L1", lidar=s.lidar, boxes=s.boxes)
    assert all(e.sun_visibility == 0.0 and e.sun_dir_cam is None for e in together.per_view.values())
