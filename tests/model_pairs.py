"""Random-dot stereo pairs with known disparity for the model tests."""

from __future__ import annotations

import numpy as np


def random_dot_pair(height: int, width: int, disparity: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left, right RGB uint8 H×W×3, gt float32 H×W): a smooth random texture, the right view the
    left shifted by ``disparity`` whole pixels (left x matches right x − d)."""
    import cv2

    rng = np.random.default_rng(seed)
    d = int(round(disparity))
    base = rng.uniform(0, 255, (height // 2, (width + d) // 2 + 1, 3)).astype(np.float32)
    texture = cv2.resize(base, (width + d + 2, height), interpolation=cv2.INTER_LINEAR)
    texture = np.clip(texture, 0, 255).astype(np.uint8)
    left = np.ascontiguousarray(texture[:, :width])
    right = np.ascontiguousarray(texture[:, d: d + width])
    return left, right, np.full((height, width), float(d), np.float32)
