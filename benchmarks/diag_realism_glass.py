"""Glass and lamps of inserted cars against real ones: L* of windscreen, rear window, side glass and headlamp patches.

Usage::

    nice python benchmarks/diag_realism_glass.py --tag glass_after --stride 8 --seeds 0,1,2
    nice python benchmarks/diag_realism_glass.py --tag glass_before --code-root /tmp/before --stride 8 --seeds 0,1,2

Reuses ``bench_realism.py``: its renders (``--render-only`` per seed, cached in ``/tmp/realism/cache_<tag>_seed<k>``,
``--code-root`` another checkout), its car selection (:func:`image_cars`: real ``vehicle.car`` at 10-40 m, fully
visible; inserted cars at 10-40 m, visible >= 0.8) and its size matching (box height bins, per seed).

Patches are drawn in the 3D box's frame (x forward along its length, y left, z up; a, b, c its half length, width,
height), the same for a real and an inserted car, so a gap is how the inserted car's glass (its shape, where it
sits, how it reflects) differs from real cars': the windscreen's middle (a band sloping from (0.26 a, 0.46 c) to
(0.06 a, 0.75 c), |y| < 0.45 b), the rear window's (from (-0.47 a, 0.79 c) to (-0.62 a, 0.50 c)), the side glass
on the side facing the camera (x -0.35..0.2 a, z 0.45..0.75 c at |y| = b) and both headlamps (front face,
|y| 0.55..0.85 b, z -0.12..0.08 c).  A patch counts when the camera sees its face at least 17 deg off grazing (the
headlamps within 45 deg of head-on) and it covers >= 6 pixels outside nearer boxes; per car the median CIELAB L*
of its pixels.  Prints, per patch, the
inserted and real medians pooled over the seeds and the gap's mean +- std over seeds; writes
``benchmarks/results/realism_glass_<tag>.json``; ``--crops DIR`` writes the inserted cars' crops (PNG, outside the
repository: real images).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MIN_PATCH_PX = 6
MIN_VIEW_COS = 0.3  # the patch's face seen at least ~17 deg off grazing
# The headlamps: seen within ~45 deg of head-on (the box's front face stands ahead of a rounded nose's corners:
# from the side, the far lamp's patch fell beside the car).
MIN_VIEW_COS_PATCH = {"headlamp": 0.7}


def _bench():
    spec = importlib.util.spec_from_file_location("bench_realism", ROOT / "benchmarks" / "bench_realism.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _grid(p0: np.ndarray, e_s: np.ndarray, e_t: np.ndarray, n: int = 7) -> np.ndarray:
    """(n * n, 3) points p0 + s e_s + t e_t, s, t in [0, 1]."""
    s, t = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    return p0 + s.reshape(-1, 1) * e_s + t.reshape(-1, 1) * e_t


def patches_box(wlh: np.ndarray, camera_box: np.ndarray) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Patches of a car box of size ``wlh`` (nuScenes width, length, height, m), in its frame: name -> list of
    (points (M, 3), outward unit normal (3,)); the side glass on the side of ``camera_box`` (the camera centre in
    the box frame)."""
    a, b, c = 0.5 * wlh[1], 0.5 * wlh[0], 0.5 * wlh[2]
    ws0, ws1 = np.array([0.26 * a, 0.0, 0.46 * c]), np.array([0.06 * a, 0.0, 0.75 * c])
    rw0, rw1 = np.array([-0.47 * a, 0.0, 0.79 * c]), np.array([-0.62 * a, 0.0, 0.50 * c])
    across = np.array([0.0, 0.9 * b, 0.0])

    def sloped(p0, p1, sign):
        d = p1 - p0
        n = np.array([d[2], 0.0, -d[0]]) * sign
        return _grid(p0 - 0.5 * across, across, d), n / np.linalg.norm(n)

    side = 1.0 if camera_box[1] > 0 else -1.0
    out = {"windscreen": [sloped(ws0, ws1, 1.0 if ws1[0] < ws0[0] else -1.0)],
           "rear_window": [sloped(rw0, rw1, -1.0 if rw1[0] < rw0[0] else 1.0)],
           "side_glass": [(_grid(np.array([-0.35 * a, side * b, 0.45 * c]), np.array([0.55 * a, 0.0, 0.0]),
                                 np.array([0.0, 0.0, 0.30 * c])), np.array([0.0, side, 0.0]))],
           "headlamp": [(_grid(np.array([a, s * 0.55 * b, -0.12 * c]), np.array([0.0, s * 0.30 * b, 0.0]),
                               np.array([0.0, 0.0, 0.20 * c])), np.array([1.0, 0.0, 0.0])) for s in (1.0, -1.0)]}
    # Orient the sloped normals outwards: the windscreen faces forwards and up, the rear window backwards and up.
    for name, sign in (("windscreen", 1.0), ("rear_window", -1.0)):
        pts, n = out[name][0]
        out[name] = [(pts, n if n[0] * sign > 0 else -n)]
    return out


def patch_lstar(image: np.ndarray, K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray,
                nearer: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, float]:
    """Median L* per visible patch of one car (name -> value; a patch missing when not seen)."""
    from streetaug.augment.core.camera import box_corners_cam, project_points
    from streetaug.augment.evaluation.realism import hull_mask, srgb_to_lab

    H, W = image.shape[:2]
    R, t = T_cam_from_box[:3, :3], T_cam_from_box[:3, 3]
    camera_box = -R.T @ t
    out = {}
    for name, parts in patches_box(wlh, camera_box).items():
        values = []
        for pts, n in parts:
            centre = pts.mean(axis=0)
            to_cam = camera_box - centre
            if n @ to_cam < MIN_VIEW_COS_PATCH.get(name, MIN_VIEW_COS) * np.linalg.norm(to_cam):
                continue
            uv, _ = project_points(K, pts @ R.T + t)
            if np.isnan(uv).any():
                continue
            x0, y0 = np.floor(uv.min(axis=0)).astype(int)
            x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 1
            win = (max(x0, 0), max(y0, 0), min(x1, W), min(y1, H))
            if win[2] - win[0] < 2 or win[3] - win[1] < 2:
                continue
            mask = hull_mask(uv, win)
            for T_o, wlh_o in nearer:
                corners = box_corners_cam(T_o, wlh_o)
                if np.all(corners[:, 2] > 0.5):
                    mask &= ~hull_mask(project_points(K, corners)[0], win)
            if mask.sum() < MIN_PATCH_PX:
                continue
            lab = srgb_to_lab(image[win[1]:win[3], win[0]:win[2]])
            values.append(lab[..., 0][mask])
        if values:
            out[name] = float(np.median(np.concatenate(values)))
    return out


def seed_cars(bench, args, cache: Path, crops_dir: Path | None) -> tuple[list[dict], list[dict]]:
    """(real, inserted): per size-matched car of one seed's cache, its patch L* (dict) and box height."""
    import cv2

    from streetaug.augment.core.camera import box_rect_px
    from streetaug.augment.evaluation.realism import extract_crop, size_matched
    from streetaug.datasets.nuscenes import NuScenesReader

    reader = NuScenesReader(args.dataroot, args.version)
    cars = {0: [], 1: []}
    for token in bench.keyframe_tokens(reader, args.stride):
        doc = json.loads((cache / f"{token}.json").read_text())
        sample = reader.sample(token)
        for c in args.cameras.split(","):
            view = sample.cameras[c]
            real, inserted, others_real, others_all = bench.image_cars(reader, sample, view, doc[c])
            augmented = cv2.imread(str(cache / f"{token}_{c}.png"))[:, :, ::-1] if inserted else None
            for label, image, group, others in ((0, view.image, real, others_real), (1, augmented, inserted, others_all)):
                for T, wlh in group:
                    dist = np.linalg.norm(T[:3, 3])
                    nearer = [(T2, w2) for T2, w2 in others
                              if not np.allclose(T2, T) and np.linalg.norm(T2[:3, 3]) < dist - 0.5]
                    rect = box_rect_px(view.K, T, wlh)
                    cars[label].append({"L": patch_lstar(image, view.K, T, wlh, nearer), "height_px":
                                        float(rect[3] - rect[1]), "distance_m": float(dist), "image": f"{token}_{c}"})
                    if crops_dir is not None and label == 1:
                        crop = extract_crop(image, view.K, T, wlh)
                        name = f"{cache.name}_{token[:8]}_{c}_{len(cars[1])}.png"
                        cv2.imwrite(str(crops_dir / name), np.ascontiguousarray(crop.rgb[:, :, ::-1]))
    h_r = np.array([x["height_px"] for x in cars[0]])
    h_i = np.array([x["height_px"] for x in cars[1]])
    pick_r, pick_i = size_matched(h_r, h_i, bench.HEIGHT_BINS_PX, np.random.default_rng(args.seed), args.max_per_class)
    return [cars[0][k] for k in pick_r], [cars[1][k] for k in pick_i]


PATCHES = ("windscreen", "rear_window", "side_glass", "headlamp")


def _medians(cars: list[dict]) -> dict[str, dict]:
    out = {}
    for p in PATCHES:
        v = np.array([c["L"][p] for c in cars if p in c["L"]])
        out[p] = {"median": float(np.median(v)) if v.size else None, "n": int(v.size)}
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tag", required=True)
    p.add_argument("--code-root", default=str(ROOT))
    p.add_argument("--stride", type=int, default=8)
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--n-objects", type=int, default=3)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--crops", default=None, help="Write the inserted cars' crops here (outside the repository).")
    a = p.parse_args(argv)
    if a.crops and Path(a.crops).resolve().is_relative_to(ROOT):
        raise SystemExit("--crops: real images must not be written into the repository")
    bench = _bench()
    common = ["--tag", a.tag, "--code-root", a.code_root, "--stride", str(a.stride), "--n-objects", str(a.n_objects)]
    bench.main(common + ["--seeds", a.seeds, "--render-only"])  # cached renders per seed
    crops_dir = Path(a.crops) if a.crops else None
    if crops_dir:
        crops_dir.mkdir(parents=True, exist_ok=True)
    per_seed, pooled = [], {0: [], 1: []}
    for s in a.seeds.split(","):
        args = bench.parse_args(common + ["--seed", s])
        real, inserted = seed_cars(bench, args, Path(f"/tmp/realism/cache_{a.tag}_seed{int(s)}"), crops_dir)
        pooled[0] += real
        pooled[1] += inserted
        m_r, m_i = _medians(real), _medians(inserted)
        per_seed.append({"seed": int(s), "n_real": len(real), "n_inserted": len(inserted), "real": m_r,
                         "inserted": m_i,
                         "gap": {k: (None if m_i[k]["median"] is None or m_r[k]["median"] is None
                                     else m_i[k]["median"] - m_r[k]["median"]) for k in PATCHES}})
    m_r, m_i = _medians(pooled[0]), _medians(pooled[1])
    summary = {}
    print(f"{a.tag} (code {a.code_root}): {len(pooled[0])} real vs {len(pooled[1])} inserted cars over seeds {a.seeds}")
    print(f"  {'patch':12s} {'inserted':>9s} {'real':>9s} {'gap':>7s}  gap over seeds   n_ins/n_real")
    for k in PATCHES:
        g = np.array([d["gap"][k] for d in per_seed if d["gap"][k] is not None], float)
        gap = None if m_i[k]["median"] is None or m_r[k]["median"] is None else m_i[k]["median"] - m_r[k]["median"]
        summary[k] = {"inserted_median": m_i[k]["median"], "real_median": m_r[k]["median"], "gap_pooled": gap,
                      "gap_seed_mean": float(g.mean()) if g.size else None,
                      "gap_seed_std": float(g.std()) if g.size else None, "n_inserted": m_i[k]["n"],
                      "n_real": m_r[k]["n"]}
        fmt = lambda v: "   nan" if v is None else f"{v:9.2f}"  # noqa: E731
        print(f"  {k:12s} {fmt(m_i[k]['median'])} {fmt(m_r[k]['median'])} {fmt(gap)}  "
              f"{g.mean() if g.size else np.nan:+6.2f} +- {g.std() if g.size else np.nan:4.2f}   "
              f"{m_i[k]['n']}/{m_r[k]['n']}")
    commit = bench.subprocess.run(["git", "-C", a.code_root, "rev-parse", "--short", "HEAD"], capture_output=True,
                                  text=True).stdout.strip()
    out = Path(a.out) / f"realism_glass_{a.tag}.json"
    out.write_text(json.dumps({"tag": a.tag, "code_root": a.code_root, "commit": commit, "stride": a.stride,
                               "seeds": a.seeds, "n_objects": a.n_objects, "patches": summary,
                               "per_seed": per_seed}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
