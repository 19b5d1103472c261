"""``OUTDIR/tracks_sheet.png`` (``--tracks``): each inserted track through time, one row per track.

Each row shows up to ``max_frames`` of the track's rendered keyframes (evenly spread over its span, time
left to right): a crop around its 2D box in the camera that shows most of it at that keyframe, with the
keyframe index and camera. Keyframes where no camera shows it are a grey "hidden" cell, so a track that
pops in or out is visible at a glance. Thumbnails only: nothing here is used as data.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from ..core import read_image_rgb, write_image_rgb
from .row import LogRow
from .tracks import SceneTracks

SHEET_FILE = "tracks_sheet.png"


def _crop(image: np.ndarray, bbox: list[float], size: int) -> np.ndarray:
    """A square crop of ``image`` around ``bbox`` [x0, y0, x1, y1] (grown by 60 %, >= 96 px), resized to ``size``."""
    x0, y0, x1, y1 = bbox
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    half = max(1.6 * 0.5 * max(x1 - x0, y1 - y0), 48.0)
    H, W = image.shape[:2]
    a, b = int(max(cx - half, 0)), int(min(cx + half, W))
    c, d = int(max(cy - half, 0)), int(min(cy + half, H))
    crop = image[c:d, a:b]
    if crop.size == 0:
        return np.full((size, size, 3), 64, np.uint8)
    scale = size / max(crop.shape[:2])
    crop = cv2.resize(crop, (max(1, int(crop.shape[1] * scale)), max(1, int(crop.shape[0] * scale))),
                      interpolation=cv2.INTER_AREA)
    cell = np.full((size, size, 3), 32, np.uint8)
    oy, ox = (size - crop.shape[0]) // 2, (size - crop.shape[1]) // 2
    cell[oy:oy + crop.shape[0], ox:ox + crop.shape[1]] = crop
    return cell


def _caption(cell: np.ndarray, text: str) -> None:
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.35, 1)
    cell[: th + 6, : tw + 6] //= 3
    cv2.putText(cell, text, (3, th + 3), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (255, 255, 255), 1, cv2.LINE_AA)


def track_views(out_dir: Path, rows: list[LogRow]) -> dict[tuple[str, str], tuple[float, str, list[float], str]]:
    """(track key, sample token) -> (visible fraction x box area, image, bbox_2d, camera) of the camera showing
    it best."""
    best: dict[tuple[str, str], tuple[float, str, list[float], str]] = {}
    for row in rows:
        if row.status != "ok" or not row.image or len(row.files) < 2:
            continue
        path = out_dir / row.files[1]
        if not path.is_file():
            continue
        for obj in json.loads(path.read_text()).get("objects", []):
            if not obj.get("track") or not obj.get("bbox_2d"):
                continue
            x0, y0, x1, y1 = obj["bbox_2d"]
            score = float(obj.get("visible_fraction", 1.0)) * (x1 - x0) * (y1 - y0)
            key = (obj["track"], row.sample_token)
            if key not in best or score > best[key][0]:
                best[key] = (score, row.image, obj["bbox_2d"], row.camera)
    return best


def track_sheet(out_dir: Path, rows: list[LogRow], scenes: list[SceneTracks], max_tracks: int = 8,
                max_frames: int = 10, size: int = 128) -> Path | None:
    """Write ``out_dir/tracks_sheet.png`` for the first ``max_tracks`` tracks that were rendered somewhere."""
    rendered = {r.sample_token for r in rows if r.done}
    views = track_views(out_dir, rows)
    lines = []
    for scene in scenes:
        for track in scene.tracks:
            key = f"{scene.scene_token}/{track.track_index}"
            frames = [s for s in track.sample_tokens if s in rendered]
            if not any((key, s) in views for s in frames):
                continue
            picks = [frames[int(i)] for i in np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames)))
                                                       .round().astype(int))]
            cells = []
            for s in picks:
                k = scene.sample_tokens.index(s)
                if (key, s) in views:
                    _, image, bbox, camera = views[(key, s)]
                    cell = _crop(read_image_rgb(out_dir / image), bbox, size)
                    _caption(cell, f"t{k} {camera.replace('CAM_', '')}")
                else:
                    cell = np.full((size, size, 3), 96, np.uint8)
                    _caption(cell, f"t{k} hidden")
                cells.append(cell)
            label = np.zeros((size, size, 3), np.uint8)
            for j, text in enumerate([scene.scene_name or scene.scene_token[:8], f"track {track.track_index}",
                                      track.motion, f"{track.speed_mps:.1f} m/s", f"{len(track.sample_tokens)} kf"]):
                cv2.putText(label, text, (4, 18 + 20 * j), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                            cv2.LINE_AA)
            lines.append([label, *cells])
            if len(lines) >= max_tracks:
                break
        if len(lines) >= max_tracks:
            break
    if not lines:
        return None
    width = max(len(line) for line in lines)
    sheet = np.zeros((len(lines) * size, width * size, 3), np.uint8)
    for r, line in enumerate(lines):
        for c, cell in enumerate(line):
            sheet[r * size:(r + 1) * size, c * size:(c + 1) * size] = cell
    path = out_dir / SHEET_FILE
    write_image_rgb(path, sheet)
    return path


__all__ = ["SHEET_FILE", "track_sheet", "track_views"]
