"""Aligning an affine-invariant monocular disparity to a metric one: one scale and shift per image.

Pure numpy. Monocular networks (Depth Anything V2) give disparity up to an unknown affine map, so
every comparison with pixels first fits ``s·mono + t`` to a reference: the stereo disparity (no
ground truth: the simplest post fusion, Eq. 3's objective solved globally) or the ground truth on
valid non-illusion pixels (the paper's "+ align" rows).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

AlignRule = Literal["lsq", "median"]
ALIGN_RULES: tuple[AlignRule, ...] = ("lsq", "median")


def fit_scale_shift(mono: np.ndarray, target: np.ndarray, mask: np.ndarray,
                    rule: AlignRule = "lsq") -> tuple[float, float]:
    """(s, t) such that ``s·mono + t`` approximates ``target`` on ``mask`` (bool HxW).

    ``lsq``: least squares. ``median``: the authors' variant — medians matched and scales from the
    mean absolute deviation about them, robust to outliers. Non-finite pixels are left out; with
    fewer than two usable pixels, or a constant ``mono``, the shift alone is fitted (s = 0 gives
    the target's typical value everywhere rather than a division by zero).
    """
    usable = mask & np.isfinite(mono) & np.isfinite(target)
    x = mono[usable].astype(np.float64)
    y = target[usable].astype(np.float64)
    if x.size == 0:
        raise ValueError("no pixels to align on: the alignment mask is empty")
    if rule == "median":
        mx, my = np.median(x), np.median(y)
        dx = np.mean(np.abs(x - mx))
        if dx == 0:
            return 0.0, float(my)
        s = np.mean(np.abs(y - my)) / dx
        return float(s), float(my - s * mx)
    if rule != "lsq":
        raise ValueError(f"unknown alignment rule {rule!r}; use one of {', '.join(ALIGN_RULES)}")
    var = x.var()
    if x.size < 2 or var == 0:
        return 0.0, float(y.mean())
    s = ((x - x.mean()) * (y - y.mean())).mean() / var
    return float(s), float(y.mean() - s * x.mean())


def align(mono: np.ndarray, target: np.ndarray, mask: np.ndarray, rule: AlignRule = "lsq") -> np.ndarray:
    """``mono`` (float HxW, relative) mapped to the units of ``target`` by :func:`fit_scale_shift`;
    float32 HxW."""
    s, t = fit_scale_shift(mono, target, mask, rule)
    return (s * mono.astype(np.float64) + t).astype(np.float32)
