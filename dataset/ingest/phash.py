"""Difference hash (dHash) for near-duplicate frames.

Eight lines of OpenCV rather than a dependency: dHash is the standard cheap perceptual hash
(Krawetz), robust to re-encoding and small brightness changes, and this keeps it on the same
resize path as the rest of ingest.
"""

from __future__ import annotations

import cv2
import numpy as np


def dhash(rgb: np.ndarray) -> int:
    """64-bit difference hash of an RGB uint8 HxWx3 image: left-right gradient signs on a 9x8 grid."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    small = cv2.resize(gray, (9, 8), interpolation=cv2.INTER_AREA).astype(np.int16)
    bits = (small[:, 1:] > small[:, :-1]).ravel()
    return int(np.packbits(bits).view(">u8")[0])


def hamming(a: int, b: int) -> int:
    """Number of differing bits (0 = same picture, ≤ ~5 = near duplicate, ~32 = unrelated)."""
    return (a ^ b).bit_count()
