"""Realism check: can inserted cars be told from real cars of the same size in the same images?

Pure functions on car crops (no I/O, no pipeline):

* crops: a car's projected 3D box plus a margin that includes the ground under it (:func:`extract_crop`),
  with the box's image hull and, per pixel, the ground distance outside the box's footprint;
* features per crop (:func:`crop_features`): colour and contrast in CIELAB, sharpness, noise level, shadow
  darkness under the car;
* a real-vs-inserted classifier on fixed-size descriptors (:func:`crop_descriptor`: HOG + Lab histogram +
  the scalar features), cross-validated with folds grouped by image or keyframe (:func:`classifier_accuracy`);
  0.5 = indistinguishable;
* per-feature gaps between the two sets (:func:`feature_gaps`) and size matching (:func:`size_matched`).

Frames: the box frame is nuScenes' (x forward = length, y left = width, z up = height, origin at the box
centre); the camera frame is OpenCV's (x right, y down, z forward); pixel centres at integer coordinates.
Images are sRGB uint8; luma is Rec.709 Y' in 0..255 of the sRGB values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from ..core import box_corners_cam, box_rect_px, project_points

FEATURE_NAMES = ("L_mean", "L_std", "a_mean", "b_mean", "chroma_mean", "rms_contrast", "laplacian_sharpness",
                 "edge_sharpness", "noise_sigma", "shadow_darkness", "saturated_fraction")

@dataclass(frozen=True)
class CarCrop:
    """One car cut out of an image.

    Attributes:
        rgb: (h, w, 3) uint8 sRGB crop.
        car_mask: (h, w) bool, inside the projected 3D box (its image hull).
        ground_dist_m: (h, w) float32 distance (m) on the box's ground plane from the footprint rectangle
            (0 inside it), NaN where the pixel's ray does not meet the ground in front of the camera.
        exclude_mask: (h, w) bool pixels covered by other cars' boxes (kept out of the ground statistics).
        window: (x0, y0, x1, y1) crop window in the image, pixels (x1, y1 exclusive).
        box_height_px: height of the projected box's 2D bounding rectangle, pixels.
        distance_m: distance from the camera to the box centre, metres.
    """

    rgb: np.ndarray
    car_mask: np.ndarray
    ground_dist_m: np.ndarray
    exclude_mask: np.ndarray
    window: tuple[int, int, int, int]
    box_height_px: float
    distance_m: float


# ----------------------------------------------------------------------------- geometry

def box_in_image(K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray, width: int, height: int,
                 min_depth_m: float = 0.5) -> bool:
    """True when all 8 corners are in front of the camera and project inside the image."""
    corners = box_corners_cam(T_cam_from_box, wlh)
    if np.any(corners[:, 2] < min_depth_m):
        return False
    uv, _ = project_points(K, corners)
    return bool(np.all((uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)))


def crop_window(rect_px: np.ndarray, width: int, height: int, side_margin: float = 0.15,
                top_margin: float = 0.1, bottom_margin: float = 0.35) -> tuple[int, int, int, int]:
    """The crop window around a box rectangle: margins as fractions of the rectangle's height (the bottom
    one larger, so the ground under and in front of the car is in the crop), clipped to the image."""
    x0, y0, x1, y1 = rect_px
    h = y1 - y0
    win = (int(np.floor(x0 - side_margin * h)), int(np.floor(y0 - top_margin * h)),
           int(np.ceil(x1 + side_margin * h)) + 1, int(np.ceil(y1 + bottom_margin * h)) + 1)
    return max(win[0], 0), max(win[1], 0), min(win[2], width), min(win[3], height)


def hull_mask(points_px: np.ndarray, window: tuple[int, int, int, int]) -> np.ndarray:
    """(h, w) bool: inside the convex hull of ``points_px`` (N, 2), in the window's pixels."""
    x0, y0, x1, y1 = window
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    hull = cv2.convexHull(np.round((points_px - [x0, y0]) * 16).astype(np.int32))
    cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def ground_points_box(K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray,
                      window: tuple[int, int, int, int]) -> np.ndarray:
    """(h, w, 2) float64: for each window pixel, the box-frame x/y (m) where its camera ray meets the plane of
    the box's bottom face; NaN when the ray meets it behind the camera or not at all (sky, above the horizon)."""
    x0, y0, x1, y1 = window
    u, v = np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float))
    rays_cam = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(K).T  # (h, w, 3), z = 1
    R, t = T_cam_from_box[:3, :3], T_cam_from_box[:3, 3]
    rays_box = rays_cam @ R  # R^T d: ray directions in the box frame
    origin_box = -R.T @ t  # the camera centre in the box frame
    z_ground = -0.5 * wlh[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (z_ground - origin_box[2]) / rays_box[..., 2]
    hit = origin_box[:2] + s[..., None] * rays_box[..., :2]
    return np.where((np.isfinite(s) & (s > 0))[..., None], hit, np.nan)


def ground_distance_map(K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray,
                        window: tuple[int, int, int, int]) -> np.ndarray:
    """(h, w) float32: for each window pixel, where its camera ray meets the plane of the box's bottom face,
    the distance (m) from the footprint rectangle (0 inside); NaN when the ray meets it behind the camera
    or not at all (sky, above the horizon)."""
    hit = ground_points_box(K, T_cam_from_box, wlh, window)
    half = 0.5 * np.array([wlh[1], wlh[0]])
    outside = np.maximum(np.abs(hit) - half, 0.0)
    return np.hypot(outside[..., 0], outside[..., 1]).astype(np.float32)  # NaN stays NaN


def yaw_to_ray_deg(T_cam_from_box: np.ndarray) -> float:
    """Angle (deg, 0..90) between a box's heading (its x axis) and the camera ray to its centre, both in the
    box's ground plane: 0 = seen end-on (front or back), 90 = seen side-on."""
    up = T_cam_from_box[:3, 2]
    heading, ray = T_cam_from_box[:3, 0], T_cam_from_box[:3, 3]
    h, r = heading - (heading @ up) * up, ray - (ray @ up) * up
    c = abs(h @ r) / max(np.linalg.norm(h) * np.linalg.norm(r), 1e-12)
    return float(np.degrees(np.arccos(np.clip(c, 0.0, 1.0))))


def extract_crop(image: np.ndarray, K: np.ndarray, T_cam_from_box: np.ndarray, wlh: np.ndarray,
                 other_boxes: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> CarCrop:
    """Cut a car out of ``image`` (H, W, 3) by its projected 3D box (see :class:`CarCrop`).

    Args:
        T_cam_from_box: (4, 4) box frame -> camera frame; wlh: (3,) box width, length, height (m).
        other_boxes: (T_cam_from_box, wlh) of the other cars in the image, whose hulls are kept out of the
            ground statistics (a neighbour's body is not road).
    """
    H, W = image.shape[:2]
    rect = box_rect_px(K, T_cam_from_box, wlh)
    window = crop_window(rect, W, H)
    x0, y0, x1, y1 = window
    corners_px, _ = project_points(K, box_corners_cam(T_cam_from_box, wlh))
    exclude = np.zeros((y1 - y0, x1 - x0), bool)
    for T_other, wlh_other in other_boxes:
        corners = box_corners_cam(T_other, wlh_other)
        if np.all(corners[:, 2] > 0.5):
            exclude |= hull_mask(project_points(K, corners)[0], window)
    return CarCrop(image[y0:y1, x0:x1].copy(), hull_mask(corners_px, window),
                   ground_distance_map(K, T_cam_from_box, wlh, window), exclude, window,
                   float(rect[3] - rect[1]), float(np.linalg.norm(T_cam_from_box[:3, 3])))


# ----------------------------------------------------------------------------- features

def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) CIELAB (D65; L 0..100) of sRGB uint8 (or float 0..1) values."""
    x = rgb.astype(np.float32) / 255.0 if rgb.dtype == np.uint8 else rgb.astype(np.float32)
    return cv2.cvtColor(x.reshape(-1, 1, 3), cv2.COLOR_RGB2Lab).reshape(x.shape)


def luma(rgb: np.ndarray) -> np.ndarray:
    """(h, w) float32 Rec.709 luma of sRGB values, 0..255."""
    x = rgb.astype(np.float32)
    return 0.2126 * x[..., 0] + 0.7152 * x[..., 1] + 0.0722 * x[..., 2]


def colour_stats(lab: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Mean and spread of CIELAB inside ``mask``: L_mean, L_std, a_mean, b_mean, chroma_mean (sqrt(a^2+b^2))."""
    px = lab[mask]
    chroma = np.hypot(px[:, 1], px[:, 2])
    return {"L_mean": float(px[:, 0].mean()), "L_std": float(px[:, 0].std()), "a_mean": float(px[:, 1].mean()),
            "b_mean": float(px[:, 2].mean()), "chroma_mean": float(chroma.mean())}


def rms_contrast(y: np.ndarray, mask: np.ndarray) -> float:
    """RMS contrast inside ``mask``: std of luma over its mean (dimensionless)."""
    v = y[mask]
    return float(v.std() / max(v.mean(), 1e-6))


def laplacian_sharpness(y: np.ndarray, mask: np.ndarray) -> float:
    """Variance of the 3x3 Laplacian of luma inside ``mask`` over the variance of luma there (1/px^2 scale:
    blur lowers it, contrast alone does not change it)."""
    lap = cv2.Laplacian(y.astype(np.float32), cv2.CV_32F, ksize=1)
    inner = _eroded(mask, 1)
    return float(lap[inner].var() / max(y[inner].var(), 1e-6))


def edge_sharpness(y: np.ndarray, mask: np.ndarray, top_fraction: float = 0.1) -> float:
    """Steepness of the strongest edges: the mean Sobel gradient magnitude of the ``top_fraction`` strongest
    pixels inside ``mask`` over the luma range there (5th-95th percentile); ~ 1 / edge width (1/px)."""
    gx = cv2.Sobel(y.astype(np.float32), cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(y.astype(np.float32), cv2.CV_32F, 0, 1, ksize=3) / 8.0
    inner = _eroded(mask, 1)
    g = np.hypot(gx, gy)[inner]
    strong = np.sort(g)[-max(int(top_fraction * g.size), 1):]
    lo, hi = np.percentile(y[inner], [5, 95])
    return float(strong.mean() / max(hi - lo, 1.0))


def noise_sigma(y: np.ndarray, mask: np.ndarray, flat_fraction: float = 0.5) -> float:
    """Noise standard deviation of luma (0..255) inside ``mask`` (Immerkaer 1996): the mean absolute response
    of the Laplacian-difference kernel [[1,-2,1],[-2,4,-2],[1,-2,1]] times sqrt(pi/2)/6, over the
    ``flat_fraction`` of the pixels with the weakest gradient (edges and texture excluded)."""
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    yf = y.astype(np.float32)
    response = np.abs(cv2.filter2D(yf, cv2.CV_32F, kernel, borderType=cv2.BORDER_REFLECT))
    grad = np.hypot(cv2.Sobel(yf, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(yf, cv2.CV_32F, 0, 1, ksize=3))
    inner = _eroded(mask, 2)
    g = grad[inner]
    flat = g <= np.quantile(g, flat_fraction)
    return float(np.sqrt(np.pi / 2) / 6.0 * response[inner][flat].mean())


def shadow_darkness(y: np.ndarray, ground_dist_m: np.ndarray, car_mask: np.ndarray,
                    exclude_mask: np.ndarray | None = None, under_m: tuple[float, float] = (0.0, 0.4),
                    around_m: tuple[float, float] = (1.2, 3.0), min_pixels: int = 12) -> float:
    """How much darker the ground just under the car is than the ground around it: 1 - median luma of the
    ground ``under_m`` from the footprint over that ``around_m`` from it (0 = no shadow, -> 1 = black).

    Only ground pixels outside the box's hull are used (where the box hides the ground, the pixel is the car),
    and outside ``exclude_mask``. NaN when either ring has fewer than ``min_pixels`` pixels.
    """
    free = ~car_mask if exclude_mask is None else ~(car_mask | exclude_mask)
    d = np.where(free, ground_dist_m, np.nan)
    with np.errstate(invalid="ignore"):
        under = y[(d >= under_m[0]) & (d < under_m[1])]
        around = y[(d >= around_m[0]) & (d < around_m[1])]
    if under.size < min_pixels or around.size < min_pixels:
        return float("nan")
    return float(1.0 - np.median(under) / max(np.median(around), 1e-6))


def crop_features(crop: CarCrop) -> dict[str, float]:
    """The scalar features of one crop (:data:`FEATURE_NAMES`), all measured inside the box hull except
    the shadow darkness (ground around the car)."""
    y = luma(crop.rgb)
    mask = crop.car_mask
    out = colour_stats(srgb_to_lab(crop.rgb), mask)
    out["rms_contrast"] = rms_contrast(y, mask)
    out["laplacian_sharpness"] = laplacian_sharpness(y, mask)
    out["edge_sharpness"] = edge_sharpness(y, mask)
    out["noise_sigma"] = noise_sigma(y, mask)
    out["shadow_darkness"] = shadow_darkness(y, crop.ground_dist_m, mask, crop.exclude_mask)
    out["saturated_fraction"] = float(np.mean(np.any((crop.rgb[mask] <= 2) | (crop.rgb[mask] >= 253), axis=-1)))
    return out


def _eroded(mask: np.ndarray, px: int) -> np.ndarray:
    """``mask`` eroded by ``px`` pixels (the mask itself when erosion would leave fewer than 16 pixels)."""
    inner = cv2.erode(mask.astype(np.uint8), np.ones((2 * px + 1, 2 * px + 1), np.uint8)).astype(bool)
    return inner if inner.sum() >= 16 else mask


# ----------------------------------------------------------------------------- classifier

_HOG = cv2.HOGDescriptor((64, 64), (16, 16), (8, 8), (8, 8), 9)


def crop_descriptor(crop: CarCrop, features: dict[str, float] | None = None, size: int = 64,
                    bins: int = 8, car_only: bool = False) -> np.ndarray:
    """(D,) float32 fixed-length descriptor of a crop resized to ``size`` x ``size``: HOG of luma (1764
    values for 64 px), a normalised ``bins``-per-channel CIELAB histogram inside the hull (3 * bins) and the
    scalar features (NaN kept: the classifier imputes).  ``car_only``: the HOG sees the box's hull only
    (the pixels outside it set to the hull's mean colour), so the surroundings (a parked car's verge
    against an inserted car's road) do not tell the two apart."""
    rgb = crop.rgb
    if car_only and crop.car_mask.any():
        rgb = np.where(crop.car_mask[..., None], rgb, rgb[crop.car_mask].mean(axis=0)).astype(np.uint8)
    rgb = cv2.resize(rgb, (size, size), interpolation=cv2.INTER_AREA)
    y = np.clip(luma(rgb), 0, 255).astype(np.uint8)
    hog = _HOG.compute(y).ravel() if size == 64 else cv2.HOGDescriptor((size, size), (16, 16), (8, 8), (8, 8),
                                                                       9).compute(y).ravel()
    lab = srgb_to_lab(crop.rgb)[crop.car_mask]
    ranges = ((0, 100), (-60, 60), (-60, 60))
    hist = np.concatenate([np.histogram(lab[:, c], bins=bins, range=ranges[c])[0] / max(len(lab), 1)
                           for c in range(3)])
    features = crop_features(crop) if features is None else features
    scalars = np.array([features[n] for n in FEATURE_NAMES])
    return np.concatenate([hog, hist, scalars]).astype(np.float32)


def grouped_folds(labels: np.ndarray, groups: Sequence, n_splits: int = 5, seed: int = 0):
    """Train/test index pairs of a stratified K-fold in which no group (image or keyframe) is split between
    train and test (sklearn ``StratifiedGroupKFold``, shuffled by ``seed``)."""
    from sklearn.model_selection import StratifiedGroupKFold

    cv = StratifiedGroupKFold(n_splits=n_splits, shuffle=True, random_state=seed)
    return list(cv.split(np.zeros(len(labels)), np.asarray(labels), np.asarray(groups)))


def classifier_accuracy(X: np.ndarray, labels: np.ndarray, groups: Sequence, n_splits: int = 5, seed: int = 0,
                        C: float = 0.05) -> dict:
    """Grouped cross-validated accuracy of a real-vs-inserted classifier (impute NaN by the median, standardise,
    L2 logistic regression with inverse strength ``C``).

    Args:
        X: (N, D) descriptors; labels: (N,) 0 real / 1 inserted; groups: (N,) image or keyframe ids.
    Returns:
        ``{"accuracy_mean", "accuracy_std", "fold_accuracy": [...], "n_splits"}`` (0.5 = indistinguishable).
    """
    from sklearn.impute import SimpleImputer
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    labels = np.asarray(labels)
    scores = []
    for train, test in grouped_folds(labels, groups, n_splits, seed):
        model = make_pipeline(SimpleImputer(strategy="median", keep_empty_features=True), StandardScaler(),
                              LogisticRegression(C=C, max_iter=2000))
        model.fit(X[train], labels[train])
        scores.append(float(np.mean(model.predict(X[test]) == labels[test])))
    return {"accuracy_mean": float(np.mean(scores)), "accuracy_std": float(np.std(scores)),
            "fold_accuracy": scores, "n_splits": n_splits}


# ----------------------------------------------------------------------------- set comparison

def feature_gaps(inserted: Sequence[dict[str, float]], real: Sequence[dict[str, float]],
                 names: Sequence[str] = FEATURE_NAMES) -> dict[str, dict[str, float]]:
    """Per feature: the inserted and real medians, their difference, and the standardised mean difference
    (Cohen's d: mean difference over the pooled standard deviation; |d| < 0.2 small, > 0.8 large). NaN
    values are left out."""
    out = {}
    for n in names:
        a = np.array([f[n] for f in inserted], float)
        b = np.array([f[n] for f in real], float)
        a, b = a[np.isfinite(a)], b[np.isfinite(b)]
        if len(a) < 2 or len(b) < 2:
            out[n] = {"inserted_median": float("nan"), "real_median": float("nan"), "median_gap": float("nan"),
                      "standardised_gap": float("nan"), "n_inserted": int(len(a)), "n_real": int(len(b))}
            continue
        pooled = np.sqrt(((len(a) - 1) * a.var(ddof=1) + (len(b) - 1) * b.var(ddof=1)) / (len(a) + len(b) - 2))
        out[n] = {"inserted_median": float(np.median(a)), "real_median": float(np.median(b)),
                  "median_gap": float(np.median(a) - np.median(b)),
                  "standardised_gap": float((a.mean() - b.mean()) / max(pooled, 1e-12)),
                  "n_inserted": int(len(a)), "n_real": int(len(b))}
    return out


def size_matched(heights_a: np.ndarray, heights_b: np.ndarray, bin_edges: Sequence[float],
                 rng: np.random.Generator, max_each: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Indices into two sets such that both have the same count in every height bin (the smaller bin count;
    seeded random choice), optionally capped to ``max_each`` per set keeping the bins' proportions.

    Args:
        heights_a, heights_b: (Na,), (Nb,) projected box heights, pixels. bin_edges: increasing edges
            (values outside are dropped).
    """
    edges = np.asarray(bin_edges, float)
    bin_a, bin_b = np.digitize(heights_a, edges), np.digitize(heights_b, edges)
    counts = np.array([min(np.sum(bin_a == k), np.sum(bin_b == k)) for k in range(1, len(edges))])
    if max_each is not None and counts.sum() > max_each:
        counts = np.floor(counts * max_each / counts.sum()).astype(int)
    pick_a, pick_b = [], []
    for k, n in zip(range(1, len(edges)), counts):
        if n:
            pick_a.append(rng.choice(np.flatnonzero(bin_a == k), n, replace=False))
            pick_b.append(rng.choice(np.flatnonzero(bin_b == k), n, replace=False))
    if not pick_a:
        return np.zeros(0, int), np.zeros(0, int)
    return np.sort(np.concatenate(pick_a)), np.sort(np.concatenate(pick_b))
