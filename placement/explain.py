"""Bird's-eye-view picture of a placement attempt (for ``insert --explain``).

The view is centred on the camera, north (global +y) up, east (global +x) right. Drawn: the drivable
area (grey) and its source, lane centre lines (brown, when the map has lanes), LiDAR points (white),
annotated boxes (blue), the camera and its viewing direction (yellow), the sampled region (camera field
of view between the minimum and maximum distance, olive outline), every candidate coloured by the
rule that rejected it (see ``RULE_COLORS_RGB``; "unused" = passed the checks made, not needed), placed
objects (green, with their heading and class). The legend counts the rejections per rule, then, per class
and zone the candidates were drawn for, which rules rejected how many of them (``pedestrian/sidewalk:
surface 310, lidar_obstacles 12``), and why a class could not be placed.
"""

from __future__ import annotations

import cv2
import numpy as np

from streetaug.datasets.sample import CameraView, Sample

from .candidates import camera_azimuth_range
from .place import PlacementResult

LANE_COLOR_RGB = (150, 120, 40)

RULE_COLORS_RGB: dict[str, tuple[int, int, int]] = {
    "": (0, 255, 0),  # passed and chosen
    "unused": (0, 140, 0),  # passed, not needed
    "surface": (120, 0, 0),
    "annotated_boxes": (255, 0, 0),
    "distance": (255, 128, 0),
    "lidar_obstacles": (255, 255, 0),
    "lidarseg": (255, 0, 255),
    "in_view": (160, 0, 255),
    "corners_unoccluded": (255, 160, 160),
    "mutual_collision": (0, 255, 255),
}


def class_rule_lines(result: PlacementResult) -> list[str]:
    """Legend lines: per ``class/zone`` the candidates were drawn for, the rules that rejected them (most
    first), then each class that could not be placed with the reason."""
    lines = []
    classes = np.asarray(result.candidate_class, dtype=object)
    rejected = np.asarray(result.rejected_by, dtype=object)
    if len(classes) == len(rejected):
        for name in dict.fromkeys(classes.tolist()):
            rules, counts = np.unique(rejected[(classes == name) & (rejected != "") & (rejected != "unused")],
                                      return_counts=True)
            order = np.argsort(-counts, kind="stable")
            lines.append(f"{name}: " + (", ".join(f"{rules[i]} {counts[i]}" for i in order) or "no rejection"))
    lines += [f"not placed: {reason}" for reason in result.class_reasons.values()]
    return lines


def draw_placement_bev(
    sample: Sample, view: CameraView, result: PlacementResult, size_px: int = 800, m_per_px: float = 0.125
) -> np.ndarray:
    """(size_px, size_px, 3) uint8 RGB bird's-eye view of ``result`` around ``view``'s camera."""
    img = np.zeros((size_px, size_px, 3), np.uint8)
    cam_xy = view.T_global_from_cam[:2, 3]
    half = size_px / 2.0

    def to_px(xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.round(np.c_[half + (xy[:, 0] - cam_xy[0]) / m_per_px, half - (xy[:, 1] - cam_xy[1]) / m_per_px]).astype(np.int32)

    area = result.drivable
    if area is not None and area.region is not None:
        for poly in getattr(area.region, "geoms", [area.region]):
            cv2.fillPoly(img, [to_px(np.asarray(poly.exterior.coords)[:, :2])], (70, 70, 70))
            for hole in poly.interiors:
                cv2.fillPoly(img, [to_px(np.asarray(hole.coords)[:, :2])], (0, 0, 0))
    elif area is not None and area.grid is not None:
        H, W = area.grid.shape
        iy, ix = np.nonzero(area.grid)
        centres = area.grid_origin_xy + (np.c_[ix, iy] + 0.5) * area.resolution_m
        q = to_px(centres)
        ok = (q[:, 0] >= 0) & (q[:, 0] < size_px) & (q[:, 1] >= 0) & (q[:, 1] < size_px)
        img[q[ok, 1], q[ok, 0]] = (70, 70, 70)
        r = max(int(np.ceil(area.resolution_m / m_per_px / 2)), 1)
        img = cv2.dilate(img, np.ones((2 * r + 1, 2 * r + 1), np.uint8))
    lanes = sample.lanes
    if lanes is not None and len(lanes.points_xy):
        q = to_px(lanes.points_xy)
        ok = (q[:, 0] >= 0) & (q[:, 0] < size_px) & (q[:, 1] >= 0) & (q[:, 1] < size_px)
        img[q[ok, 1], q[ok, 0]] = LANE_COLOR_RGB
    lidar = sample.lidar
    if lidar is not None:
        q = to_px(lidar.points_global[:, :2])
        ok = (q[:, 0] >= 0) & (q[:, 0] < size_px) & (q[:, 1] >= 0) & (q[:, 1] < size_px)
        img[q[ok, 1], q[ok, 0]] = (200, 200, 200)
    for b in sample.boxes:
        cv2.polylines(img, [to_px(b.corners()[[0, 1, 5, 4], :2])], True, (60, 120, 255), 1)
    for xy, rule in zip(to_px(result.candidates_xy), result.rejected_by):
        cv2.circle(img, (int(xy[0]), int(xy[1])), 1, RULE_COLORS_RGB.get(str(rule), (128, 128, 128)), -1)
    for p in result.placements:
        cv2.polylines(img, [to_px(p.box.corners()[[0, 1, 5, 4], :2])], True, (0, 255, 0), 2)
        a, b = to_px(np.stack([p.box.center[:2], p.box.center[:2] + 0.6 * p.wlh[1] * p.T_global_from_object[:2, 0]]))
        cv2.arrowedLine(img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), (0, 255, 0), 1, tipLength=0.3)
        if p.cluster_of < 0:
            cv2.putText(img, p.detection_class, (int(a[0]) + 4, int(a[1]) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                        (0, 255, 0), 1)
    if result.config is not None:  # the sampled region: camera field of view x [min, max] distance
        fov = camera_azimuth_range(view)
        az = np.linspace(fov.heading_rad - fov.right_rad, fov.heading_rad + fov.left_rad, 64)
        ring = np.c_[np.cos(az), np.sin(az)]
        wedge = np.concatenate([cam_xy + result.config.min_distance_m * ring,
                                cam_xy + result.config.max_distance_m * ring[::-1]])
        cv2.polylines(img, [to_px(wedge)], True, (120, 110, 0), 1)
    c = to_px(cam_xy)[0]
    fwd = view.T_global_from_cam[:2, 2]
    tip = to_px(cam_xy + 5.0 * fwd / max(np.linalg.norm(fwd), 1e-9))[0]
    cv2.arrowedLine(img, (int(c[0]), int(c[1])), (int(tip[0]), int(tip[1])), (255, 220, 0), 2)
    y = 14
    for name, count in result.report.items():
        cv2.putText(img, f"{name}: {count}", (6, y), cv2.FONT_HERSHEY_SIMPLEX, 0.4, RULE_COLORS_RGB[name], 1)
        y += 14
    if area is not None:
        cv2.putText(img, f"road: {area.source} ({area.confidence} confidence)", (6, y + 4),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, (200, 200, 200), 1)
        y += 18
    for line in class_rule_lines(result):
        cv2.putText(img, line[:110], (6, y + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (220, 220, 220), 1)
        y += 13
    if result.reason:
        cv2.putText(img, result.reason[:110], (6, size_px - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (255, 255, 255), 1)
    return img
