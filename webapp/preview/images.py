"""2D renders of a sample for people: colourised disparity, holes, anaglyph, mask outlines.

Pure numpy/OpenCV on RGB uint8 HxWx3 images; PNG encoding at the end.
"""

from __future__ import annotations

import cv2
import numpy as np

from dataset.formats.masks import cv_mask
from webapp.preview.cloud import HIGHLIGHT_RGB

COLORMAP = cv2.COLORMAP_TURBO
NO_VALUE_RGB = (40, 40, 40)
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
    """A float HxW map as RGB through the TURBO colour map, ``lo`` → blue, ``hi`` → red;
    non-finite values dark grey."""
    finite = np.isfinite(values)
    span = hi - lo if hi > lo else 1.0
    levels = np.clip((np.where(finite, values, lo) - lo) / span * 255.0, 0, 255).round().astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(levels, COLORMAP), cv2.COLOR_BGR2RGB)
    rgb[~finite] = NO_VALUE_RGB
    return rgb


def colorbar_stops(count: int = 11) -> list[str]:
    """``count`` evenly spaced colours of the colour map, low to high, as CSS hex strings."""
    levels = np.linspace(0, 255, count).round().astype(np.uint8).reshape(-1, 1)
    rgb = cv2.cvtColor(cv2.applyColorMap(levels, COLORMAP), cv2.COLOR_BGR2RGB).reshape(-1, 3)
    return [f"#{r:02x}{g:02x}{b:02x}" for r, g, b in rgb]


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
