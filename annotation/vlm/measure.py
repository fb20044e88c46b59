"""Image figures the heuristic prefilter decides on: sharpness and text lines (captions, watermarks).

All figures are measured on the gray frame shrunk to at most ANALYSIS_WIDTH pixels wide, so
that thresholds mean the same at 720p and at 4K; smaller frames are measured as they are
(upscaling would make every small frame look blurry).

Text lines are found the classic way: strong horizontal intensity steps (the vertical strokes
of glyphs) closed horizontally into line blobs, kept when wide, of text height, dense in
strokes and with many separate strokes. Limits: text of low contrast (steps under
_STROKE_STEP gray levels) or
overlaid on busy texture is often missed or found only in parts; regular high-contrast
patterns (barcodes, railings, keyboards) can pass for text.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

ANALYSIS_WIDTH = 640
_TILES = 8  # the sharpness grid is _TILES x _TILES
_STROKE_STEP = 80.0  # gray levels across one pixel that count as a glyph stroke edge
_MIN_STROKE_DENSITY = 0.12
_MIN_STROKES = 6
_BAND_ZONE = 0.30  # captions live in the top/bottom 30 % of the frame height
_BAND_ROW_COVER = 0.15  # a caption row has text over at least 15 % of the width
_CORNER_ZONE = (0.30, 0.20)  # a corner is the outer 30 % of the width x 20 % of the height

Box = tuple[int, int, int, int]  # x, y, width, height in analysis-image pixels


@dataclass(frozen=True)
class FrameFigures:
    """Measured figures of one frame (analysis resolution; fractions in [0, 1])."""

    laplacian_var: float  # variance of the Laplacian over the whole frame
    laplacian_var_p90: float  # 90th percentile of the per-tile variance: how sharp the sharpest parts are
    brightness: float  # mean gray / 255
    contrast: float  # std of gray / 255
    text_area_fraction: float  # frame area inside detected text lines
    caption_band_fraction: float  # frame height made of caption rows in the top/bottom bands
    corner_text_count: float  # text lines confined to a corner (watermarks, logos), not on caption rows

    def as_metrics(self) -> dict[str, float]:
        return {name: float(value) for name, value in self.__dict__.items()}


def analysis_gray(rgb: np.ndarray) -> np.ndarray:
    """RGB uint8 HxWx3 → gray uint8 at most ANALYSIS_WIDTH wide (aspect kept)."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    height, width = gray.shape
    if width <= ANALYSIS_WIDTH:
        return gray
    size = (ANALYSIS_WIDTH, max(1, round(height * ANALYSIS_WIDTH / width)))
    return cv2.resize(gray, size, interpolation=cv2.INTER_AREA)


def measure_frame(rgb: np.ndarray) -> FrameFigures:
    """All figures of an RGB uint8 HxWx3 frame."""
    gray = analysis_gray(rgb)
    laplacian_var, laplacian_var_p90 = sharpness(gray)
    boxes = text_lines(gray)
    band_fraction, caption_rows = caption_rows_of(boxes, gray.shape)
    corners = corner_boxes(boxes, caption_rows, gray.shape)
    return FrameFigures(
        laplacian_var=laplacian_var,
        laplacian_var_p90=laplacian_var_p90,
        brightness=float(gray.mean()) / 255.0,
        contrast=float(gray.std()) / 255.0,
        text_area_fraction=sum(w * h for _, _, w, h in boxes) / gray.size,
        caption_band_fraction=band_fraction,
        corner_text_count=float(len(corners)),
    )


def sharpness(gray: np.ndarray) -> tuple[float, float]:
    """(variance of the Laplacian, its 90th percentile over a tile grid) of a gray image."""
    laplacian = cv2.Laplacian(gray, cv2.CV_32F)
    height, width = laplacian.shape
    th, tw = max(1, height // _TILES), max(1, width // _TILES)
    rows, cols = height // th, width // tw
    tiles = laplacian[: rows * th, : cols * tw].reshape(rows, th, cols, tw)
    return float(laplacian.var()), float(np.percentile(tiles.var(axis=(1, 3)), 90))


def text_lines(gray: np.ndarray) -> list[Box]:
    """Bounding boxes (x, y, w, h) of text-like lines in a gray uint8 image."""
    height, width = gray.shape
    step = np.abs(cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3)) / 4.0  # ≈ gray levels per pixel
    strokes = (step > _STROKE_STEP).astype(np.uint8)
    # Wide enough to join the glyphs of a line, too flat to join neighbouring lines.
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (max(3, width // 40), 3))
    lines = cv2.morphologyEx(strokes, cv2.MORPH_CLOSE, kernel)
    count, _, stats, _ = cv2.connectedComponentsWithStats(lines, connectivity=4)
    boxes: list[Box] = []
    for x, y, w, h, _ in stats[1:count]:
        if not height / 60 <= h <= height / 5 or w < 2 * h:
            continue
        inside = strokes[y : y + h, x : x + w]
        separate_strokes = np.count_nonzero(np.diff(inside.max(axis=0).astype(np.int8)) == 1)
        if inside.mean() >= _MIN_STROKE_DENSITY and separate_strokes >= _MIN_STROKES:
            boxes.append((int(x), int(y), int(w), int(h)))
    return boxes


def caption_rows_of(boxes: list[Box], shape: tuple[int, int]) -> tuple[float, np.ndarray]:
    """(fraction of the height that is caption rows, boolean row mask) for text boxes in an image of ``shape``."""
    height, width = shape
    cover = np.zeros(height, dtype=np.float64)
    for _, y, w, h in boxes:
        cover[y : y + h] += w / width
    zone = np.zeros(height, dtype=bool)
    band = round(height * _BAND_ZONE)
    zone[:band] = True
    zone[height - band :] = True
    rows = zone & (cover >= _BAND_ROW_COVER)
    return float(rows.mean()), rows


def corner_boxes(boxes: list[Box], caption_rows: np.ndarray, shape: tuple[int, int]) -> list[Box]:
    """Boxes inside a corner zone that are not part of a caption row."""
    height, width = shape
    zone_w, zone_h = width * _CORNER_ZONE[0], height * _CORNER_ZONE[1]
    found = []
    for x, y, w, h in boxes:
        if caption_rows[y : y + h].any():
            continue
        in_columns = x + w <= zone_w or x >= width - zone_w
        in_rows = y + h <= zone_h or y >= height - zone_h
        if in_columns and in_rows:
            found.append((x, y, w, h))
    return found
