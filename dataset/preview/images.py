"""2D renders for people: colourised disparity (with a colour bar), error maps, holes,
anaglyph, mask outlines.

Pure numpy/OpenCV on RGB uint8 HxWx3 images; PNG encoding at the end. Used by the sample pages,
and by anything else that shows a disparity (the model's predictions, evaluation reports).
"""

from __future__ import annotations

import cv2
import numpy as np

from core.formats.masks import cv_mask
from dataset.preview.cloud import HIGHLIGHT_RGB

COLORMAP = cv2.COLORMAP_TURBO
NO_VALUE_RGB = (40, 40, 40)
ERROR_COLORMAP = cv2.COLORMAP_INFERNO  # black (no error) → yellow (max_px and beyond)
ERROR_NO_VALUE_RGB = (70, 130, 180)  # steel blue: no ground truth there; not a colour INFERNO has
COLORBAR_TEXT_RGB = (255, 255, 255)
HOLE_RGB = (0, 255, 0)  # lime: no natural image region has it, and it stands apart from the masks' colours
HOLE_ALPHA = 0.7
ILLUSION_RGB = HIGHLIGHT_RGB  # one colour for the illusion in 2D and 3D
SUPPORT_RGB = (0, 200, 255)


def value_range(*maps: np.ndarray) -> tuple[float, float]:
    """(min, max) of the finite values of all ``maps`` together; (0, 1) when there are none."""
    finite = [m[np.isfinite(m)] for m in maps]
    values = np.concatenate(finite) if finite else np.zeros(0)
    if not values.size:
        return 0.0, 1.0
    return float(values.min()), float(values.max())


def colorize(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """A float HxW map (a disparity in px, say) as RGB uint8 HxWx3 through the TURBO colour map,
    ``lo`` → blue, ``hi`` → red; non-finite values dark grey."""
    return _apply(values, lo, hi, COLORMAP, NO_VALUE_RGB)


def colorize_error(err_px: np.ndarray, max_px: float) -> np.ndarray:
    """An error map (float HxW, px; |prediction − truth|) as RGB uint8 HxWx3 through INFERNO,
    0 → black, ``max_px`` and more → yellow; non-finite (no ground truth) steel blue."""
    if not (np.isfinite(max_px) and max_px > 0):
        raise ValueError(f"max_px must be a finite number > 0, got {max_px}")
    return _apply(np.abs(np.asarray(err_px, np.float32)), 0.0, float(max_px), ERROR_COLORMAP, ERROR_NO_VALUE_RGB)


def colorbar_stops(count: int = 11) -> list[str]:
    """``count`` evenly spaced colours of the colour map, low to high, as CSS hex strings."""
    rgb = _lut(np.linspace(0, 255, count), COLORMAP).reshape(-1, 3)
    return [f"#{r:02x}{g:02x}{b:02x}" for r, g, b in rgb]


def add_colorbar(image: np.ndarray, lo: float, hi: float, *, unit: str = "px", error: bool = False) -> np.ndarray:
    """``image`` (RGB uint8 HxWx3, made by :func:`colorize`, or by :func:`colorize_error` when
    ``error``) with a vertical colour bar on its right, ``hi`` at the top and ``lo`` at the bottom,
    both labelled in ``unit``: a figure that can be read without the page around it."""
    height = image.shape[0]
    bar_width = max(8, height // 24)
    levels = np.linspace(255, 0, height).reshape(-1, 1).repeat(bar_width, axis=1)
    bar = _lut(levels, ERROR_COLORMAP if error else COLORMAP)
    scale = max(0.35, height / 800)
    thickness = max(1, round(scale * 2))
    texts = (f"{hi:.3g} {unit}", f"{lo:.3g} {unit}")
    sizes = [cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thickness)[0] for text in texts]
    labels = np.zeros((height, max(width for width, _ in sizes) + 8, 3), np.uint8)
    for text, y in zip(texts, (sizes[0][1] + 4, height - 6), strict=True):
        cv2.putText(labels, text, (4, y), cv2.FONT_HERSHEY_SIMPLEX, scale, COLORBAR_TEXT_RGB, thickness, cv2.LINE_AA)
    return np.concatenate([image, np.zeros((height, 4, 3), np.uint8), bar, labels], axis=1)


def _apply(values: np.ndarray, lo: float, hi: float, colormap: int, no_value: tuple[int, int, int]) -> np.ndarray:
    finite = np.isfinite(values)
    span = hi - lo if hi > lo else 1.0
    rgb = _lut(np.clip((np.where(finite, values, lo) - lo) / span * 255.0, 0, 255), colormap)
    rgb[~finite] = no_value
    return rgb


def _lut(levels: np.ndarray, colormap: int) -> np.ndarray:
    """Levels 0..255 (float, any 2-D shape) through an OpenCV colour map, as RGB uint8."""
    return cv2.cvtColor(cv2.applyColorMap(np.asarray(levels).round().astype(np.uint8), colormap), cv2.COLOR_BGR2RGB)


def blend(image: np.ndarray, mask: np.ndarray, rgb: tuple[int, int, int], alpha: float) -> np.ndarray:
    """``image`` with the pixels of ``mask`` (bool HxW) mixed towards ``rgb`` by ``alpha``."""
    out = image.copy()
    out[mask] = np.round((1 - alpha) * image[mask] + alpha * np.array(rgb)).astype(np.uint8)
    return out


def anaglyph(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Red-cyan anaglyph: the left view in the red channel, the right in green and blue."""
    out = right.copy()
    out[..., 0] = left[..., 0]
    return out


def outline(image: np.ndarray, masks: dict[str, np.ndarray]) -> np.ndarray:
    """``image`` with each mask's contours drawn: ``illusion_*`` magenta, others (support) cyan."""
    out = np.ascontiguousarray(image.copy())
    thickness = max(2, round(max(image.shape[:2]) / 320))
    # Illusions last: a support ring's inner edge runs along its illusion, which should stay visible.
    for name, mask in sorted(masks.items(), key=lambda item: (item[0].startswith("illusion"), item[0])):
        contours, _ = cv2.findContours(cv_mask(mask), cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        color = ILLUSION_RGB if name.startswith("illusion") else SUPPORT_RGB
        cv2.drawContours(out, contours, -1, color, thickness, lineType=cv2.LINE_AA)
    return out


def shrink(image: np.ndarray, width: int) -> np.ndarray:
    """``image`` scaled down to ``width`` px wide (kept as is when already narrower)."""
    height, current = image.shape[:2]
    if current <= width:
        return image
    return cv2.resize(image, (width, max(1, round(height * width / current))), interpolation=cv2.INTER_AREA)


def encode_png(image: np.ndarray) -> bytes:
    """RGB uint8 HxWx3 → PNG bytes."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()
