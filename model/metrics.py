"""Stereo metrics as pure functions: disparity errors (EPE, bad-x, KITTI D1) and depth errors
(AbsRel, RMSE, log10, δ1–δ3) from disparity with a camera, on any region mask.

Inputs are numpy arrays or torch tensors of one shape (H×W, or anything elementwise: B×1×H×W);
both give the same numbers (computed in float64), and tensors stay on their device until the
final scalar. ``mask`` is bool; pixels whose ground truth is not finite never count, so a region
may be passed as is. An empty region gives NaN, not an error.

The functions return FRACTIONS; :func:`disparity_metrics` and :func:`reporting_form` give the
reporting form (bad-x, D1 and δ in percent), as the paper's tables and every report print them.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

Array = Any  # np.ndarray or torch.Tensor
DEFAULT_THRESHOLDS = (1, 2, 3, 5)
KITTI_D1_PX, KITTI_D1_RELATIVE = 3.0, 0.05
_FRACTION_PREFIXES = ("bad", "delta", "d1")


def epe(pred: Array, gt: Array, mask: Array) -> float:
    """Mean absolute disparity error (pixels) over ``mask``; NaN if the mask is empty."""
    err, _ = _errors(pred, gt, mask)
    return _mean(err)


def bad(pred: Array, gt: Array, mask: Array, threshold: float) -> float:
    """FRACTION of mask pixels with |pred − gt| > ``threshold`` pixels (a non-finite prediction
    counts as bad); NaN if the mask is empty."""
    err, _ = _errors(pred, gt, mask)
    return _mean(~(err <= threshold))


def d1(pred: Array, gt: Array, mask: Array) -> float:
    """KITTI 2015 D1: FRACTION of mask pixels whose error exceeds both 3 px and 5 % of the ground truth."""
    err, ref = _errors(pred, gt, mask)
    return _mean(~((err <= KITTI_D1_PX) | (err <= KITTI_D1_RELATIVE * abs(ref))))


def depth_metrics(pred_disp: Array, gt_disp: Array, mask: Array, fx: float, baseline: float,
                  depth_range: tuple[float, float] | None = None, *, doffs: float = 0.0) -> dict[str, float]:
    """Depth errors of a disparity prediction: ``abs_rel``, ``rmse`` (metres), ``log10`` and
    ``delta1``..``delta3`` (FRACTIONS of pixels with max(p/g, g/p) < 1.25**k).

    Depth = ``fx`` (pixels) · ``baseline`` (metres) / (disparity + ``doffs``) (pixels; ``doffs``
    is Middlebury's principal-point offset, 0 for rectified rigs). Only mask pixels with a
    positive ground-truth disparity + doffs count; with ``depth_range`` = (near, far) metres only those
    whose true depth lies strictly inside it, and predicted depths are clipped into it (a
    non-positive predicted disparity counts as farthest). Without a range such a prediction has
    infinite depth, and the errors it enters are infinite. All NaN if no pixel counts.
    """
    if not (fx > 0 and baseline > 0):
        raise ValueError(f"fx and baseline must be > 0, got fx={fx}, baseline={baseline}")
    pred, gt, region = _prepared(pred_disp, gt_disp, mask)
    pred, gt = pred + doffs, gt + doffs
    region = region & (gt > 0)
    focal_length = fx * baseline
    gt_depth = focal_length / gt[region]
    pred_disp_in = pred[region]
    with np.errstate(divide="ignore", invalid="ignore"):
        pred_depth = focal_length / pred_disp_in
    pred_depth[~(pred_disp_in > 0)] = math.inf
    if depth_range is not None:
        near, far = depth_range
        if not 0 < near < far:
            raise ValueError(f"depth_range must be (near, far) with 0 < near < far, got {depth_range}")
        keep = (gt_depth > near) & (gt_depth < far)
        gt_depth, pred_depth = gt_depth[keep], pred_depth[keep].clip(near, far)
    if _count(gt_depth) == 0:
        return {key: math.nan for key in ("abs_rel", "rmse", "log10", "delta1", "delta2", "delta3")}
    ratio = _maximum(pred_depth / gt_depth, gt_depth / pred_depth)
    diff = pred_depth - gt_depth
    log10 = abs(_log10(pred_depth) - _log10(gt_depth))
    return {"abs_rel": _mean(abs(diff) / gt_depth), "rmse": math.sqrt(_mean(diff * diff)), "log10": _mean(log10),
            **{f"delta{k}": _mean(ratio < 1.25**k) for k in (1, 2, 3)}}


def counted_pixels(gt: Array, mask: Array) -> int:
    """How many pixels the disparity metrics count (mask ∧ finite gt): the weight that turns
    per-image EPE and bad-x into pixel-pooled figures (Σ metricᵢ·nᵢ / Σ nᵢ)."""
    _, _, region = _prepared(gt, gt, mask)
    return int(region.sum())


def bad_key(threshold: float) -> str:
    """The report key of a bad-x threshold: ``bad2`` for 2, ``bad0_5`` for 0.5."""
    return "bad" + f"{threshold:g}".replace(".", "_")


def disparity_metrics(pred: Array, gt: Array, mask: Array, thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS,
                      *, kitti_d1: bool = False) -> dict[str, float]:
    """The reporting form: ``epe`` (pixels) and ``bad<x>`` per threshold in PERCENT (plus ``d1``
    in percent when ``kitti_d1``), e.g. {"epe", "bad1", "bad2", "bad3", "bad5"}."""
    values = {"epe": epe(pred, gt, mask), **{bad_key(t): bad(pred, gt, mask, t) for t in thresholds}}
    if kitti_d1:
        values["d1"] = d1(pred, gt, mask)
    return reporting_form(values)


def reporting_form(metrics: dict[str, float]) -> dict[str, float]:
    """Fractions (``bad*``, ``delta*``, ``d1``) → percent; every other metric unchanged."""
    return {key: 100.0 * value if key.startswith(_FRACTION_PREFIXES) else value for key, value in metrics.items()}


# --- shared by numpy and torch ------------------------------------------------------------------

def _is_tensor(value: Any) -> bool:
    torch = sys.modules.get("torch")  # a tensor cannot exist unless torch is imported
    return torch is not None and isinstance(value, torch.Tensor)


def _prepared(pred: Array, gt: Array, mask: Array) -> tuple[Array, Array, Array]:
    """(pred, gt) as float64 and the mask ∧ finite gt, all numpy or all torch (on the first tensor's device)."""
    tensors = [v for v in (pred, gt, mask) if _is_tensor(v)]
    if tensors:
        import torch

        device = tensors[0].device
        pred, gt, mask = (torch.as_tensor(v, device=device) for v in (pred, gt, mask))
        pred, gt, mask = pred.double(), gt.double(), mask.bool()
        finite = torch.isfinite(gt)
    else:
        pred, gt = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
        mask = np.asarray(mask)
        if mask.dtype != np.bool_:
            raise ValueError(f"mask must be bool, got {mask.dtype}")
        finite = np.isfinite(gt)
    if not (tuple(pred.shape) == tuple(gt.shape) == tuple(mask.shape)):
        raise ValueError(f"pred, gt and mask must have one shape, got {tuple(pred.shape)}, {tuple(gt.shape)}, "
                         f"{tuple(mask.shape)}")
    return pred, gt, mask & finite


def _errors(pred: Array, gt: Array, mask: Array) -> tuple[Array, Array]:
    """|pred − gt| and gt over the counted pixels (1-D)."""
    pred, gt, region = _prepared(pred, gt, mask)
    return abs(pred[region] - gt[region]), gt[region]


def _count(values: Array) -> int:
    return int(values.numel() if _is_tensor(values) else values.size)


def _mean(values: Array) -> float:
    if _count(values) == 0:
        return math.nan
    return float(values.double().mean().item() if _is_tensor(values) else values.astype(np.float64).mean())


def _maximum(a: Array, b: Array) -> Array:
    if _is_tensor(a):
        import torch

        return torch.maximum(a, b)
    return np.maximum(a, b)


def _log10(values: Array) -> Array:
    if _is_tensor(values):
        return values.log10()
    with np.errstate(divide="ignore"):
        return np.log10(values)
