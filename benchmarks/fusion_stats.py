"""The fusion benchmark's per-frame record and its intervals: pure functions, no training, no rendering.

Every method is scored frame by frame and region by region (EPE in pixels and bad-2 in percent over the
region's pixels with a finite ground truth, and the count of those pixels), so a figure is the mean over
frames, as ``model.evaluate`` reports it, and any comparison can be re-drawn from the record. Frames of one
scene are alike (a camera moving through one room), so the unit of evidence is the scene, not the frame:
intervals come from a bootstrap over scenes and, where several networks were trained, over training seeds
too (both resampled with replacement, independently; the statistic is always the pooled ratio of sums, so
a scene with more frames weighs more, as it does in the mean).

Two kinds of per-pixel comparison need the predictions themselves, not the per-frame means, and are
recorded per frame as sums: the oracle gate (per pixel the better of a stereo map and the GT-aligned mono,
its headroom ``e_stereo - min(e_stereo, e_mono)``) and a network's gate's capture of that headroom,
Σ(e_stereo - e_fused) / Σ max(0, e_stereo - e_mono) over its own stereo branch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

BAD_PX = 2.0  # bad-2: a pixel is bad when its error exceeds 2 px
REPLICATES = 10_000  # bootstrap draws: the 2.5 % and 97.5 % quantiles move by < 0.002 px between draws of this size
LEVEL = 0.95


def frame_errors(prediction: np.ndarray, disparity: np.ndarray) -> np.ndarray:
    """Absolute error (px) of a float HxW ``prediction`` against the HxW ground truth ``disparity``; a
    non-finite prediction counts as 0 px, as ``model.evaluate`` counts it."""
    prediction = np.where(np.isfinite(prediction), prediction, 0.0)
    return np.abs(prediction.astype(np.float64) - disparity.astype(np.float64))


def region_figures(errors: np.ndarray, where: np.ndarray) -> dict[str, float]:
    """EPE (px), bad-2 (%) and the pixel count of ``errors`` over the bool mask ``where`` (NaN figures,
    0 pixels, when it is empty)."""
    pixels = int(np.count_nonzero(where))
    if not pixels:
        return {"epe": float("nan"), "bad2": float("nan"), "pixels": 0}
    chosen = errors[where]
    return {"epe": float(chosen.mean()), "bad2": float(100.0 * np.mean(chosen > BAD_PX)), "pixels": pixels}


def gate_sums(stereo: np.ndarray, fused: np.ndarray | None, mono: np.ndarray, where: np.ndarray) -> dict[str, float]:
    """Over ``where``, from per-pixel errors (px) of a stereo map, the fused map built on it (None: only
    the oracle) and the GT-aligned mono: ``oracle`` Σ min(e_stereo, e_mono), ``headroom`` Σ max(0, e_stereo
    - e_mono) (what a perfect gate would gain) and, with ``fused``, ``gain`` Σ(e_stereo - e_fused)."""
    s, m = stereo[where], mono[where]
    sums = {"oracle": float(np.minimum(s, m).sum()), "headroom": float(np.maximum(0.0, s - m).sum())}
    if fused is not None:
        sums["gain"] = float((s - fused[where]).sum())
    return sums


def bootstrap_ratio(numerator: np.ndarray, denominator: np.ndarray, scenes: Sequence[int], *,
                    replicates: int = REPLICATES, seed: int = 0) -> dict[str, float]:
    """The pooled ratio Σ numerator / Σ denominator over (K seeds, F frames) arrays, with its LEVEL
    interval from a bootstrap over seeds and over the frames' ``scenes`` (F scene ids): each draw resamples
    both with replacement. Entries where either array is NaN are left out. ``{"value", "low", "high"}``."""
    num, den = np.atleast_2d(np.asarray(numerator, np.float64)), np.atleast_2d(np.asarray(denominator, np.float64))
    if num.shape != den.shape or num.shape[1] != len(scenes):
        raise ValueError(f"numerator {num.shape}, denominator {den.shape} and {len(scenes)} scenes do not match")
    keep = np.isfinite(num) & np.isfinite(den)
    num, den = np.where(keep, num, 0.0), np.where(keep, den, 0.0)
    labels, index = np.unique(np.asarray(scenes), return_inverse=True)
    by_scene_num = np.zeros((num.shape[0], len(labels)))
    by_scene_den = np.zeros_like(by_scene_num)
    np.add.at(by_scene_num.T, index, num.T)
    np.add.at(by_scene_den.T, index, den.T)
    total = by_scene_den.sum()
    if total == 0:
        return {"value": float("nan"), "low": float("nan"), "high": float("nan")}
    rng = np.random.default_rng(seed)
    k, s = by_scene_num.shape
    seed_weights = rng.multinomial(k, np.full(k, 1.0 / k), size=replicates)
    scene_weights = rng.multinomial(s, np.full(s, 1.0 / s), size=replicates)
    drawn_num = np.einsum("bk,ks,bs->b", seed_weights, by_scene_num, scene_weights)
    drawn_den = np.einsum("bk,ks,bs->b", seed_weights, by_scene_den, scene_weights)
    ratios = drawn_num[drawn_den > 0] / drawn_den[drawn_den > 0]
    tail = 100 * (1 - LEVEL) / 2
    low, high = np.percentile(ratios, [tail, 100 - tail])
    return {"value": float(by_scene_num.sum() / total), "low": float(low), "high": float(high)}


def mean_interval(values: np.ndarray, scenes: Sequence[int], **kw: Any) -> dict[str, float]:
    """The mean of (K seeds, F frames) per-frame ``values`` (NaN: frame without the region) with its
    interval over seeds and scenes (:func:`bootstrap_ratio`)."""
    values = np.atleast_2d(np.asarray(values, np.float64))
    return bootstrap_ratio(values, np.where(np.isfinite(values), 1.0, np.nan), scenes, **kw)


def decided(interval: Mapping[str, float]) -> str:
    """"lower" when the interval lies below 0, "higher" above it, else "undecided"."""
    if interval["high"] < 0:
        return "lower"
    if interval["low"] > 0:
        return "higher"
    return "undecided"


def rounded(interval: Mapping[str, float], digits: int = 3) -> dict[str, float]:
    return {key: round(value, digits) for key, value in interval.items()}
