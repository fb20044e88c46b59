"""Frame defects the prefilter should catch, for demo videos: a burnt-in caption, a blur.

The default (heuristic) prefilter answers only the quality questions, so a demo of clean frames
never shows it decide; the demo's videos end with a few frames spoilt this way instead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import cv2
import numpy as np

from dataset.synthetic.records import SyntheticFrame, SyntheticVideo

_CAPTION_BAND = 0.14  # of the frame height, at the bottom
_CAPTION_LINES = ("SUBSCRIBE FOR MORE ILLUSIONS", "www.example-channel.tv  episode 12")
_BLUR_SIGMA = 1 / 160  # of the frame width: far softer than any camera shake the prefilter keeps


def caption(rgb: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) with two lines of white text on a darkened band along the bottom."""
    out = rgb.copy()
    height, width = out.shape[:2]
    band = int(height * _CAPTION_BAND)
    out[height - band:] = (out[height - band:] * 0.25).astype(np.uint8)
    for k, line in enumerate(_CAPTION_LINES):
        cv2.putText(out, line, (int(width * 0.05), height - band + int(band * (0.42 + 0.45 * k))),
                    cv2.FONT_HERSHEY_SIMPLEX, max(0.4, height / 900), (255, 255, 255), max(1, height // 300),
                    cv2.LINE_AA)
    return out


def blur(rgb: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) Gaussian-blurred by σ = width / 160 pixels."""
    return cv2.GaussianBlur(rgb, (0, 0), rgb.shape[1] * _BLUR_SIGMA)


DEFECT_FRAMES = 2  # spoilt frames at the end of a video
DEFECTS: dict[str, Callable[[np.ndarray], np.ndarray]] = {"caption": caption, "blur": blur}


def spoil_last_frames(video: SyntheticVideo) -> tuple[SyntheticVideo, dict[int, str]]:
    """``video`` with its last DEFECT_FRAMES frames spoilt (one captioned, then one blurred, both
    views), and which defect each spoilt frame index has."""
    n = len(video.frames)
    defects = {n - 2: "caption", n - 1: "blur"}
    frames = [_spoil(f, defects[f.index]) if f.index in defects else f for f in video.frames]
    return replace(video, frames=frames), defects


def _spoil(frame: SyntheticFrame, defect: str) -> SyntheticFrame:
    apply = DEFECTS[defect]
    return replace(frame, left=apply(frame.left), right=apply(frame.right))
