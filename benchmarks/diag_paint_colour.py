"""Where does an inserted car's colour cast come from?  Issue #20's white balance / chroma diagnosis.

Usage::

    nice python benchmarks/diag_paint_colour.py                                  # neutral grey paint
    nice python benchmarks/diag_paint_colour.py --paint 0.05,0.12,0.45 --keyframes 0,20   # a saturated blue
    nice python benchmarks/diag_paint_colour.py --palette --n-objects 3     # the benchmark's cars, per material
    nice python benchmarks/diag_paint_colour.py --real                      # the real cars: car / background

Procedural cars of one paint (default a neutral grey, solid) are inserted into real scene-0916 images through
the pipeline's library API (``insert_into_sample``, as ``bench_realism.py``); every ``render_insertion`` call is
captured.  Per car it compares, as linear chromaticity (r/g, b/g; level-free) and as CIELAB a*, b* of the
contract's LDR (what the realism benchmark measures):

* ``road``: the photo's ground 0.7-4 m around the car's footprint (scene depth unprojected; what the photo's
  camera made of the asphalt next to the car: real grey things near it should look like this);
* ``env_down``: the car's local environment looking down (``E(-up) / pi``: the ground the light model shows it);
* ``env_up`` / ``env_side``: what a grey Lambertian facing up / sideways towards the camera receives
  (``E(n) + sun``);
* ``sky``: the local map's upper hemisphere (mean radiance); ``sky_photo`` / ``sky_env_there``: the photo's
  unclipped pixels without depth in its upper half and the local map in the same directions;
* ``airlight``: the veil's airlight colour (:func:`~streetaug.augment.render.veil.estimate_veil`) and its share
  ``haze`` at the car's depth;
* ``paint_pred``: the paint's base colour x ``env_side`` / ``env_up`` irradiance (Lambertian prediction);
* ``paint_render``: the rendered side paint's radiance before the veil, blur, noise and JPEG;
* ``paint_final``: the final composite's side paint pixels.

``--palette``: the realism benchmark's cars (``select_assets`` with the location) and its mask (the projected 3D
box's hull): per material (``background`` where no part of the car is hit) the hull's share and mean CIELAB, and
the car's own pixels alone.  ``--real``: the benchmark's real cars, their hull split into ``car`` (the scene depth
puts the pixel inside the box grown by 0.3 m) and ``background``.

Stages of the chain a cast can enter: the light (env vs road), the shading (render vs prediction), the camera
look (final vs render).  Pictures are written nowhere (shared data); ``--out`` gets the per-car JSON.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEQ = (ROOT / ".." / "shared" / "data" / "nuscenes-seq").resolve()
GREY_ALBEDO = 0.25
KEYS = ("road", "env_down", "env_up", "env_side", "sky", "sky_photo", "sky_env_there", "airlight", "paint_pred",
        "paint_render", "paint_final")


@functools.lru_cache(maxsize=None)
def _benchmark(name: str):
    """Another script of ``benchmarks/`` as a module (the folder is not a package), loaded once."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def chroma_of(rgb_lin: np.ndarray) -> list[float]:
    """(r/g, b/g) of a linear RGB (3,)."""
    g = max(float(rgb_lin[1]), 1e-12)
    return [float(rgb_lin[0]) / g, float(rgb_lin[2]) / g]


def lab_of_linear(rgb_lin: np.ndarray, ev: float) -> list[float]:
    """CIELAB (L, a, b) of a linear radiance (3,) through the contract's camera response."""
    from streetaug.augment.core import hdr_to_ldr
    from streetaug.augment.evaluation.realism import srgb_to_lab

    return srgb_to_lab(hdr_to_ldr(np.asarray(rgb_lin, np.float64), ev)[None].astype(np.float32))[0].tolist()


def lab_neutral_level(rgb_lin: np.ndarray, ev: float, level_ldr: float = 0.5) -> list[float]:
    """CIELAB of ``rgb_lin``'s chromaticity scaled to a mid-grey level (so a*, b* compare across levels)."""
    from streetaug.augment.core import ldr_to_hdr, luminance

    rgb = np.asarray(rgb_lin, np.float64)
    target = float(ldr_to_hdr(np.array(level_ldr), ev))
    return lab_of_linear(rgb * target / max(float(luminance(rgb)), 1e-12), ev)


def road_ring(image: np.ndarray, K: np.ndarray, depth_m: np.ndarray, T: np.ndarray, extent_xy: np.ndarray,
              ev: float) -> np.ndarray | None:
    """Mean linear RGB (3,) of the photo's ground 0.7-4 m outside the car's footprint, or None."""
    from streetaug.augment.core import ldr_uint8_to_hdr

    H, W = depth_m.shape
    ys, xs = np.mgrid[0:H:2, 0:W:2]
    z = depth_m[ys, xs]
    ok = np.isfinite(z) & (z > 0) & (z < 80)
    ys, xs, z = ys[ok], xs[ok], z[ok]
    p = np.stack([(xs + 0.5 - K[0, 2]) / K[0, 0] * z, (ys + 0.5 - K[1, 2]) / K[1, 1] * z, z], 1)
    q = (p - T[:3, 3]) @ T[:3, :3]  # object frame
    out_x = np.maximum(np.abs(q[:, 0]) - extent_xy[0], 0.0)
    out_y = np.maximum(np.abs(q[:, 1]) - extent_xy[1], 0.0)
    dist = np.hypot(out_x, out_y)
    sel = (np.abs(q[:, 2]) < 0.15) & (dist > 0.7) & (dist < 4.0)
    if sel.sum() < 50:
        return None
    rgb = ldr_uint8_to_hdr(image[ys[sel], xs[sel]], ev).astype(np.float64)
    return np.median(rgb, axis=0)


def photo_sky(image: np.ndarray, K: np.ndarray, depth_m: np.ndarray, envmap: np.ndarray,
              ev: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Median linear RGB (3,) of the photo's unclipped sky pixels (no depth) and of the car's local map in
    the same directions, or None when the photo shows too little sky."""
    from streetaug.augment.core import ldr_uint8_to_hdr
    from streetaug.augment.render.shade import lookup_envmap

    H, W = depth_m.shape
    ys, xs = np.mgrid[0:H // 2:4, 0:W:4]
    px = image[ys, xs]
    sel = ~np.isfinite(depth_m[ys, xs]) & (px.max(axis=-1) < 245) & (px.min(axis=-1) > 10)
    if sel.sum() < 200:
        return None
    d = np.stack([(xs[sel] + 0.5 - K[0, 2]) / K[0, 0], (ys[sel] + 0.5 - K[1, 2]) / K[1, 1], np.ones(sel.sum())], 1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    photo = ldr_uint8_to_hdr(px[sel], ev).astype(np.float64)
    env = lookup_envmap(envmap, d)
    return np.median(photo, axis=0), np.median(env, axis=0)


def car_colour(cap: dict) -> dict | None:
    """Per-stage colour of one captured insertion (see the module docstring), or None when too small."""
    from streetaug.augment.core import camera_envmap_directions, equirect_solid_angles, ldr_uint8_to_hdr
    from streetaug.augment.render.environment import environment_tables
    from streetaug.augment.render.sampling import lookup_irradiance
    from streetaug.augment.render.surface import prepare_asset
    from streetaug.augment.render.veil import estimate_veil

    ins, K, T, light, ev = cap["ins"], cap["K"], cap["T"], cap["light"], cap["ev"]
    if ins.coverage_px < 400 or ins.footprint is None or ins.footprint.object_box is None:
        return None
    prep = prepare_asset(cap["asset"])
    names = [m.name for m in prep.asset.materials]
    up = T[:3, 2] / np.linalg.norm(T[:3, 2])
    to_cam = -T[:3, 3] - (-T[:3, 3] @ up) * up
    side = to_cam / np.linalg.norm(to_cam)
    env = environment_tables(light.envmap)

    def E(n):
        e = lookup_irradiance(env.irradiance, n[None])[0]
        if light.sun is not None:
            e = e + max(float(n @ light.sun.direction), 0.0) * np.asarray(light.sun.irradiance_rgb)
        return e

    out: dict = {"distance_m": float(np.linalg.norm(T[:3, 3])), "visible_px": float(ins.visible_px)}
    extent = np.abs(np.asarray(prep.asset.vertices)[:, :2]).max(axis=0)
    road = road_ring(cap["image"], K, cap["depth"], T, extent, ev)
    rgb = {"road": road, "env_down": E(-up) / np.pi, "env_up": GREY_ALBEDO * E(up) / np.pi,
           "env_side": GREY_ALBEDO * E(side) / np.pi}
    d = camera_envmap_directions(*light.envmap.shape[:2]).reshape(-1, 3)
    w = equirect_solid_angles(*light.envmap.shape[:2]).reshape(-1) * (d @ up > 0.05)
    rgb["sky"] = (light.envmap.reshape(-1, 3).astype(np.float64) * w[:, None]).sum(0) / w.sum()
    sky_px = photo_sky(cap["image"], K, cap["depth"], light.envmap, ev)
    if sky_px is not None:
        rgb["sky_photo"], rgb["sky_env_there"] = sky_px
    veil = estimate_veil(cap["image"], cap["depth"], ev)
    rgb["airlight"] = np.asarray(veil.airlight_rgb, np.float64)
    out["haze"] = float(veil.haze_at(np.array([np.linalg.norm(T[:3, 3])]))[0])
    # side paint pixels
    box = ins.footprint.object_box
    ys, xs = np.mgrid[box.slices]
    ys, xs = ys.ravel(), xs.ravel()
    mat, n_obj = _benchmark("diag_paint_level").pixel_hits(prep, K, T, ys, xs)
    R = T[:3, :3]
    sel = (mat == names.index("paint")) & (np.abs(n_obj[:, 2]) < 0.35) & (ins.mask[ys, xs] > 0.99)
    if sel.sum() < 30:
        return None
    base = prep.base_color[names.index("paint")]
    n_cam = n_obj[sel] @ R.T
    E_px = lookup_irradiance(env.irradiance, n_cam)
    if light.sun is not None:
        E_px = E_px + np.clip(n_cam @ light.sun.direction, 0, None)[:, None] * np.asarray(light.sun.irradiance_rgb)
    rgb["paint_pred"] = (base * E_px / np.pi).mean(axis=0)
    rgb["paint_render"] = ins.object_radiance[ys[sel], xs[sel]].astype(np.float64).mean(axis=0)
    rgb["paint_final"] = ldr_uint8_to_hdr(ins.image[ys[sel], xs[sel]], ev).astype(np.float64).mean(axis=0)
    for k, v in rgb.items():
        if v is None:
            continue
        out[k] = {"rgb": np.asarray(v).tolist(), "rg_bg": chroma_of(v), "lab": lab_of_linear(v, ev),
                  "lab_mid": lab_neutral_level(v, ev)}
    return out


def hull_parts(cap: dict) -> dict | None:
    """Share of the car's box hull (the realism benchmark's mask) per material (``background``: no hit) and
    each part's mean CIELAB a*, b*, chroma in the final composite, plus the whole hull's means."""
    from streetaug.augment.evaluation.realism import box_corners_cam, hull_mask, project_points, srgb_to_lab
    from streetaug.augment.render.surface import prepare_asset

    ins, K, T = cap["ins"], cap["K"], cap["T"]
    if ins.visible_px < 400 or ins.visible_px < 0.8 * ins.coverage_px:
        return None
    prep = prepare_asset(cap["asset"])
    names = [m.name for m in prep.asset.materials] + ["background"]
    v = np.asarray(prep.asset.vertices)
    lo, hi = v.min(axis=0), v.max(axis=0)
    T_box = T.copy()
    T_box[:3, 3] = T[:3, :3] @ (0.5 * (lo + hi)) + T[:3, 3]
    size = hi - lo
    wlh = np.array([size[1], size[0], size[2]])
    corners = box_corners_cam(T_box, wlh)
    if np.any(corners[:, 2] < 1.0):
        return None
    uv = project_points(K, corners)[0]
    H, W = ins.image.shape[:2]
    x0, y0 = max(int(np.floor(uv[:, 0].min())), 0), max(int(np.floor(uv[:, 1].min())), 0)
    x1, y1 = min(int(np.ceil(uv[:, 0].max())) + 1, W), min(int(np.ceil(uv[:, 1].max())) + 1, H)
    if x1 - x0 < 10 or y1 - y0 < 10 or x0 == 0 or y0 == 0 or x1 == W or y1 == H:
        return None
    mask = hull_mask(uv, (x0, y0, x1, y1))
    ys, xs = np.nonzero(mask)
    ys, xs = ys + y0, xs + x0
    hit_mat, _ = _benchmark("diag_paint_level").pixel_hits(prep, K, T, ys, xs)
    mat = np.where((hit_mat >= 0) & (ins.mask[ys, xs] > 0.5), hit_mat, len(names) - 1)
    lab = srgb_to_lab(ins.image[ys, xs][None])[0].astype(np.float64)
    lab0 = srgb_to_lab(cap["image"][ys, xs][None])[0].astype(np.float64)
    out = {"paint": prep.asset.name.split("-")[-1], "n_px": int(len(xs)),
           "hull": [float(lab[:, 1].mean()), float(lab[:, 2].mean()), float(np.hypot(lab[:, 1], lab[:, 2]).mean())],
           "hull_before": [float(lab0[:, 1].mean()), float(lab0[:, 2].mean())], "parts": {}}
    for m in np.unique(mat):
        s = mat == m
        out["parts"][names[m]] = [float(s.mean()), float(lab[s, 0].mean()), float(lab[s, 1].mean()),
                                  float(lab[s, 2].mean()), float(np.hypot(lab[s, 1], lab[s, 2]).mean())]
    return out


def real_cars(args) -> list[dict]:
    """The benchmark's real cars (:func:`bench_realism.image_cars`) in the chosen keyframes / cameras: their box
    hull split into ``car`` (the scene depth puts the pixel inside the box grown by 0.3 m) and ``background``."""
    from streetaug.augment.evaluation.realism import box_corners_cam, hull_mask, project_points, srgb_to_lab
    from streetaug.augment.pipeline.context import scene_depth_for_view
    from streetaug.datasets.nuscenes import NuScenesReader

    bench = _benchmark("bench_realism")
    reader = NuScenesReader(args.dataroot, args.version)
    tokens = reader.sample_tokens()
    out = []
    for k in (int(x) for x in args.keyframes.split(",")):
        sample = reader.sample(tokens[k])
        for c in args.cameras.split(","):
            view = sample.cameras[c]
            real, *_ = bench.image_cars(reader, sample, view, [])
            if not real:
                continue
            depth = scene_depth_for_view(sample, view)
            image, K = view.image, view.K
            for T, wlh in real:
                uv = project_points(K, box_corners_cam(T, wlh))[0]
                x0, y0 = int(np.floor(uv[:, 0].min())), int(np.floor(uv[:, 1].min()))
                x1, y1 = int(np.ceil(uv[:, 0].max())) + 1, int(np.ceil(uv[:, 1].max())) + 1
                ys, xs = np.nonzero(hull_mask(uv, (x0, y0, x1, y1)))
                ys, xs = ys + y0, xs + x0
                z = depth[ys, xs]
                p = np.stack([(xs + 0.5 - K[0, 2]) / K[0, 0] * z, (ys + 0.5 - K[1, 2]) / K[1, 1] * z, z], 1)
                q = (p - T[:3, 3]) @ T[:3, :3]
                half = 0.5 * np.array([wlh[1], wlh[0], wlh[2]]) + 0.3
                inside = np.all(np.abs(q) <= half, axis=1) & np.isfinite(z)
                lab = srgb_to_lab(image[ys, xs][None])[0].astype(np.float64)
                parts = {}
                for name, s in (("car", inside), ("background", ~inside)):
                    if s.any():
                        parts[name] = [float(s.mean()), float(lab[s, 0].mean()), float(lab[s, 1].mean()),
                                       float(lab[s, 2].mean()), float(np.hypot(lab[s, 1], lab[s, 2]).mean())]
                out.append({"paint": "real", "n_px": int(len(xs)), "parts": parts, "hull_before": [0.0, 0.0],
                            "hull": [float(lab[:, 1].mean()), float(lab[:, 2].mean()),
                                     float(np.hypot(lab[:, 1], lab[:, 2]).mean())], "keyframe": k})
    return out


def report_parts(cars: list[dict]) -> None:
    """Median hull a*, b*, chroma, and per part its mean share and mean a*, b* (contribution share x b*)."""
    hull = np.array([c["hull"] for c in cars])
    before = np.array([c["hull_before"] for c in cars])
    print(f"{len(cars)} cars: hull median a* {np.median(hull[:, 0]):.2f} b* {np.median(hull[:, 1]):.2f} chroma "
          f"{np.median(hull[:, 2]):.2f}; mean a* {hull[:, 0].mean():.2f} b* {hull[:, 1].mean():.2f}; the same hull "
          f"before insertion: a* {np.median(before[:, 0]):.2f} b* {np.median(before[:, 1]):.2f}")
    body = []
    for c in cars:
        parts = {n: v for n, v in c["parts"].items() if n != "background"}
        w = np.array([v[0] for v in parts.values()])
        if w.sum() > 0:
            body.append([float((np.array([v[k] for v in parts.values()]) * w).sum() / w.sum()) for k in (2, 3, 4)])
    if body:
        body = np.array(body)
        print(f"  the car's own pixels (every part but the background): median a* {np.median(body[:, 0]):.2f} "
              f"b* {np.median(body[:, 1]):.2f} C {np.median(body[:, 2]):.2f}; mean a* {body[:, 0].mean():.2f} "
              f"b* {body[:, 1].mean():.2f} C {body[:, 2].mean():.2f}")
    names = sorted({n for c in cars for n in c["parts"]})
    rows = []
    for n in names:
        share = np.array([c["parts"].get(n, [0.0] * 5)[0] for c in cars])
        have = [c["parts"][n] for c in cars if n in c["parts"]]
        v = np.array(have)
        w = v[:, 0]
        L, a, b, C = [float((v[:, k] * w).sum() / w.sum()) for k in (1, 2, 3, 4)]
        rows.append((float(share.mean()), n, L, a, b, C))
    print(f"  {'part':18s} {'share':>6s} {'L*':>6s} {'a*':>6s} {'b*':>6s} {'C':>6s} {'share*b':>8s} {'share*a':>8s}")
    for share, n, L, a, b, C in sorted(rows, reverse=True):
        print(f"  {n:18s} {share:6.3f} {L:6.1f} {a:6.2f} {b:6.2f} {C:6.2f} {share * b:8.3f} {share * a:8.3f}")
    fam = {}
    for c in cars:
        fam.setdefault(c["paint"], []).append(c["hull"])
    print("  by paint: " + ", ".join(f"{k} {len(v)}: b* {np.mean([h[1] for h in v]):.2f} "
                                   f"C {np.mean([h[2] for h in v]):.2f}" for k, v in sorted(fam.items())))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--paint", default="0.2,0.2,0.2", help="Linear RGB of the paint (solid).")
    p.add_argument("--metallic", type=float, default=0.0)
    p.add_argument("--keyframes", default="0,10,20,30,40", help="Keyframe indices of the scene.")
    p.add_argument("--cameras", default="CAM_FRONT,CAM_BACK,CAM_FRONT_LEFT,CAM_BACK_RIGHT")
    p.add_argument("--n-objects", type=int, default=2)
    p.add_argument("--dataroot", default=str(SEQ))
    p.add_argument("--version", default="v1.0-mini")
    p.add_argument("--palette", action="store_true",
                   help="The benchmark's cars (select_assets, the location's paints and plates): report the box "
                        "hull's colour per material instead.")
    p.add_argument("--real", action="store_true", help="The real cars' hulls (car / background by the scene depth).")
    p.add_argument("--out", default="/tmp/diag_paint_colour.json")
    args = p.parse_args(argv)

    if args.real:
        cars = real_cars(args)
        report_parts(cars)
        Path(args.out).write_text(json.dumps({"cars": cars}, default=float))
        return
    import streetaug.augment.pipeline as pipeline
    import streetaug.augment.pipeline.objects as pipeline_objects
    from streetaug.augment.assets.procedural import procedural_car
    from streetaug.augment.assets.select import select_assets
    from streetaug.datasets.nuscenes import NuScenesReader

    captured: list[dict] = []
    render = pipeline_objects.render_insertion

    def capture(image, K, depth_m, light, asset, T, **kw):
        ins = render(image, K, depth_m, light, asset, T, **kw)
        captured.append(dict(K=K, light=light, asset=asset, T=T, ins=ins, ev=kw.get("ev", 0.0), image=image,
                             depth=depth_m))
        return ins

    pipeline_objects.render_insertion = capture
    paint = tuple(float(x) for x in args.paint.split(",")) + (args.metallic,)
    reader = NuScenesReader(args.dataroot, args.version)
    tokens = reader.sample_tokens()
    cams = args.cameras.split(",")
    cars = []
    for k in (int(x) for x in args.keyframes.split(",")):
        sample = reader.sample(tokens[k])
        if args.palette:
            assets = {c: select_assets(pipeline.item_seed(0, "asset", tokens[k], c), args.n_objects,
                                       location=sample.location) for c in cams}
        else:
            assets = {c: [procedural_car(1000 * k + 10 * j + i, paint=paint) for i in range(args.n_objects)]
                      for j, c in enumerate(cams)}
        captured.clear()
        pipeline.insert_into_sample(sample, [sample.cameras[c] for c in cams], assets,
                                    pipeline.InsertOptions(seed=0, n_objects=args.n_objects))
        measure = hull_parts if args.palette else car_colour
        cars += [r | {"keyframe": k} for r in map(measure, captured) if r is not None]
    if args.palette:
        report_parts(cars)
        Path(args.out).write_text(json.dumps({"cars": cars}, default=float))
        return
    print(f"paint {paint}: {len(cars)} cars; medians over cars: r/g, b/g (linear) | Lab a*, b* at the level | "
          f"a*, b* of the chromaticity at LDR 0.5")
    for key in KEYS:
        have = [c[key] for c in cars if key in c]
        if not have:
            continue
        rg = np.median([h["rg_bg"] for h in have], axis=0)
        lab = np.median([h["lab"] for h in have], axis=0)
        mid = np.median([h["lab_mid"] for h in have], axis=0)
        print(f"  {key:13s} n={len(have):3d}  r/g {rg[0]:.3f} b/g {rg[1]:.3f} | L {lab[0]:5.1f} a {lab[1]:5.2f} "
              f"b {lab[2]:5.2f} | mid a {mid[1]:5.2f} b {mid[2]:5.2f}")
    print(f"  haze at the car: median {np.median([c['haze'] for c in cars]):.3f}")
    Path(args.out).write_text(json.dumps({"paint": paint, "cars": cars}, default=float))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
