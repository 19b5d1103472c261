"""Is there lateral chromatic aberration in the real camera images worth matching? (issue #20, the camera look)

Lateral chromatic aberration magnifies the red and blue images slightly against the green one about the optical
centre, so edges far from the centre show colour fringes. Per image and channel (red, blue) this finds the radial
magnification ``s`` (about the image centre) that best aligns the channel's gradients with the green channel's in
the outer annulus (radius > ``OUTER`` of the corner radius): the normalised gradient correlation over a grid of
scales, refined by a parabola through the best three. ``(s - 1) * corner radius`` is the colour fringe at the image
corner in pixels (the correction that aligns the channel; the aberration itself has the opposite sign).

A self-check first: a known magnification injected into one real image must be recovered (the estimator's
resolution), then the real images of every camera are measured.

Usage: ``python benchmarks/diag_chromatic_aberration.py [--dataroot ../shared/data/nuscenes-seq] [--every 8]
[--out benchmarks/results/chromatic_aberration.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT / ".." / "shared" / "data").resolve()
OUTER = 0.45  # annulus: radius above this share of the corner radius (where lateral CA is largest)
SCALES = np.linspace(0.996, 1.004, 33)  # +-0.4 %: +-3.7 px at a 1600x900 image's corner


def magnify(channel: np.ndarray, s: float, cx: float, cy: float) -> np.ndarray:
    """``channel`` (H, W) float32 magnified by ``s`` about (cx, cy) px (bilinear, edges reflected)."""
    h, w = channel.shape
    M = np.array([[s, 0.0, cx * (1.0 - s)], [0.0, s, cy * (1.0 - s)]], np.float32)
    return cv2.warpAffine(channel, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _gradients(channel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return cv2.Sobel(channel, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(channel, cv2.CV_32F, 0, 1, ksize=3)


def aligning_scale(image_bgr: np.ndarray, channel: int, scales: np.ndarray = SCALES) -> tuple[float, float]:
    """(s, contrast): the magnification of ``channel`` (0 blue, 2 red) about the image centre that best aligns its
    gradients with green's in the outer annulus, and the correlation's range over ``scales`` (how well posed)."""
    f = image_bgr.astype(np.float32)
    h, w = f.shape[:2]
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    yy, xx = np.mgrid[0:h, 0:w]
    radius = np.hypot(xx - cx, yy - cy)
    outer = radius > OUTER * radius.max()
    gx, gy = _gradients(f[..., 1])
    gx, gy = gx[outer], gy[outer]
    g_norm = np.sqrt(np.sum(gx * gx + gy * gy))
    corr = np.empty(len(scales))
    for i, s in enumerate(scales):
        cx_, cy_ = _gradients(magnify(f[..., channel], float(s), cx, cy))
        cx_, cy_ = cx_[outer], cy_[outer]
        corr[i] = np.sum(cx_ * gx + cy_ * gy) / (np.sqrt(np.sum(cx_ * cx_ + cy_ * cy_)) * g_norm + 1e-12)
    i = int(np.argmax(corr))
    s = float(scales[i])
    if 0 < i < len(scales) - 1:
        a, b, c = corr[i - 1:i + 2]
        denominator = a - 2.0 * b + c
        if denominator < 0:
            s += 0.5 * (a - c) / denominator * float(scales[1] - scales[0])
    return s, float(corr.max() - corr.min())


def corner_radius_px(image: np.ndarray) -> float:
    h, w = image.shape[:2]
    return float(np.hypot((w - 1) / 2.0, (h - 1) / 2.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataroot", type=Path, default=SHARED / "nuscenes-seq")
    ap.add_argument("--every", type=int, default=8, help="every N-th image of each camera")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "chromatic_aberration.json")
    args = ap.parse_args()
    cameras = sorted(p for p in (args.dataroot / "samples").glob("CAM_*") if p.is_dir())
    if not cameras:
        raise SystemExit(f"{args.dataroot}/samples: no CAM_* folders (the real scene; see ../shared/data/README.md)")
    t0 = time.perf_counter()

    probe = cv2.imread(str(sorted(cameras[0].glob("*.jpg"))[0]))
    r_corner = corner_radius_px(probe)
    injected = {"red": 1.0010, "blue": 0.9995}  # about +0.9 / -0.46 px at the corner
    shifted = probe.astype(np.float32)
    h, w = probe.shape[:2]
    shifted[..., 2] = magnify(shifted[..., 2], injected["red"], (w - 1) / 2.0, (h - 1) / 2.0)
    shifted[..., 0] = magnify(shifted[..., 0], injected["blue"], (w - 1) / 2.0, (h - 1) / 2.0)
    shifted = np.clip(np.rint(shifted), 0, 255).astype(np.uint8)
    check = {}
    for name, ch in (("red", 2), ("blue", 0)):
        s, _ = aligning_scale(shifted, ch)
        base, _ = aligning_scale(probe, ch)
        # The found correction undoes the injected magnification on top of the image's own.
        check[name] = {"injected_corner_px": (injected[name] - 1.0) * r_corner,
                       "recovered_corner_px": -(s - base) * r_corner}
        print(f"self-check {name}: injected {check[name]['injected_corner_px']:+.3f} px at the corner, "
              f"recovered {check[name]['recovered_corner_px']:+.3f} px")

    per_camera = {}
    for cam in cameras:
        rows = []
        for path in sorted(cam.glob("*.jpg"))[::args.every]:
            img = cv2.imread(str(path))
            rc = corner_radius_px(img)
            (sr, qr), (sb, qb) = aligning_scale(img, 2), aligning_scale(img, 0)
            rows.append({"image": path.name, "red_corner_px": (sr - 1.0) * rc, "blue_corner_px": (sb - 1.0) * rc,
                         "red_contrast": qr, "blue_contrast": qb})
        red = np.array([r["red_corner_px"] for r in rows])
        blue = np.array([r["blue_corner_px"] for r in rows])
        per_camera[cam.name] = {"n": len(rows), "red_corner_px_median": float(np.median(red)),
                                "blue_corner_px_median": float(np.median(blue)),
                                "largest_abs_corner_px": float(np.max(np.abs(np.r_[red, blue]))), "rows": rows}
        print(f"{cam.name:16s} n {len(rows):2d}  fringe at the corner: red {np.median(red):+.3f} px, "
              f"blue {np.median(blue):+.3f} px (largest |.| {per_camera[cam.name]['largest_abs_corner_px']:.3f})")
    result = {"what": __doc__.splitlines()[0], "dataroot": str(args.dataroot), "every": args.every,
              "outer_annulus": OUTER, "scales": [float(SCALES[0]), float(SCALES[-1]), len(SCALES)],
              "self_check": check, "per_camera": per_camera, "wall_s": time.perf_counter() - t0}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(args.out)
    print(f"wrote {args.out} ({result['wall_s']:.0f} s)")


if __name__ == "__main__":
    main()
