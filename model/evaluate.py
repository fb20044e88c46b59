"""Evaluate disparity predictors over a dataset reader: per-sample metrics per region, their mean over
samples (the authors' convention, the headline) and pixel-pooled figures beside it.

The loop is torch-free; the network methods bring torch in themselves (``model.methods``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dataset.readers import SampleError, StereoSample, resize_sample
from model.methods import Predict
from model.metrics import bad_key, depth_metrics, disparity_metrics, reporting_form

RESOLUTIONS = {"full": 1.0, "half": 0.5, "quarter": 0.25}
DEFAULT_THRESHOLDS: tuple[float, ...] = (1, 2, 3, 5)


@dataclass(frozen=True)
class EvalOptions:
    resolution: str = "full"
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    depth_range: tuple[float, float] | None = None  # metres; None: the dataset camera's own
    regions: tuple[str, ...] | None = None  # None: every region the reader gives


@dataclass
class _Pool:
    """Pixel sums of one (method, region) over every sample, for the pooled figures."""

    count: int = 0
    abs_err: float = 0.0
    bad: dict[float, int] = field(default_factory=dict)

    def add(self, err: np.ndarray, thresholds: Iterable[float]) -> None:
        self.count += int(err.size)
        self.abs_err += float(err.sum(dtype=np.float64))
        for t in thresholds:
            self.bad[t] = self.bad.get(t, 0) + int((err > t).sum())

    def figures(self) -> dict[str, float]:
        if self.count == 0:
            return {"epe": math.nan, "pixels": 0}
        out = {"epe": self.abs_err / self.count}
        out.update({bad_key(t): 100.0 * n / self.count for t, n in self.bad.items()})
        out["pixels"] = self.count
        return out


def sample_metrics(pred: np.ndarray, sample: StereoSample, options: EvalOptions) -> dict[str, dict[str, float]]:
    """Metrics of one prediction (float32 HxW pixels, the sample's size) per region: EPE, bad-x in
    percent and, where the sample has a camera, depth metrics (δ in percent). Pixels are those of
    the region with a finite ground truth; a non-finite prediction there counts as 0 px."""
    gt = sample.disparity
    if pred.shape != gt.shape:
        raise SampleError(f"prediction is {pred.shape[1]}x{pred.shape[0]}, ground truth {gt.shape[1]}x{gt.shape[0]}")
    pred = np.where(np.isfinite(pred), pred, 0).astype(np.float32)
    finite = np.isfinite(gt)
    out: dict[str, dict[str, float]] = {}
    for region, mask in _regions(sample, options):
        where = mask & finite
        figures = disparity_metrics(pred, gt, where, thresholds=options.thresholds)
        camera = sample.camera
        if camera is not None:
            figures.update(reporting_form(depth_metrics(pred, gt, where, camera.fx, camera.baseline,
                                                        options.depth_range or camera.depth_range, doffs=camera.doffs)))
        out[region] = figures
    return out


def _regions(sample: StereoSample, options: EvalOptions) -> list[tuple[str, np.ndarray]]:
    names = options.regions or tuple(sample.regions)
    return [(name, sample.regions[name]) for name in names if name in sample.regions]


def evaluate(samples: Iterable[StereoSample], methods: dict[str, Predict], options: EvalOptions, *,
             total: int | None = None, dataset: str = "",
             on_progress: Callable[[int, int], None] | None = None,
             on_prediction: Callable[[str, StereoSample, np.ndarray], None] | None = None,
             on_failure: Callable[[str, str, str], None] | None = None) -> dict[str, Any]:
    """Run every method on every sample and aggregate.

    ``samples`` at full resolution (resized here to ``options.resolution``); ``total`` for progress.
    A sample a method cannot predict (or a reader cannot read: pass it as an exception from the
    iterable's ``__next__`` — see :func:`iter_reader`) is reported under ``failed`` with its reason.
    Returns ``{"dataset", "resolution", "samples", "failed", "methods": {M: {"regions": {R: {...}},
    "pooled": {R: {...}}, "per_sample": [{"sample", "regions"}]}}}``.
    """
    if options.resolution not in RESOLUTIONS:
        raise ValueError(f"unknown resolution {options.resolution!r}; use {', '.join(RESOLUTIONS)}")
    factor = RESOLUTIONS[options.resolution]
    per_sample: dict[str, list[dict[str, Any]]] = {m: [] for m in methods}
    pools: dict[str, dict[str, _Pool]] = {m: {} for m in methods}
    failed: list[dict[str, str]] = []
    evaluated = 0
    for index, item in enumerate(samples):
        if isinstance(item, _Unreadable):
            failed.append({"sample": item.name, "method": "", "reason": item.reason})
            if on_failure:
                on_failure(item.name, "", item.reason)
        else:
            sample = item if factor == 1.0 else resize_sample(item, factor)
            evaluated += 1
            for name, predict in methods.items():
                try:
                    pred = predict(sample)
                    figures = sample_metrics(pred, sample, options)
                except SampleError as exc:
                    failed.append({"sample": sample.name, "method": name, "reason": str(exc)})
                    if on_failure:
                        on_failure(sample.name, name, str(exc))
                    continue
                per_sample[name].append({"sample": sample.name, "regions": figures})
                finite = np.isfinite(sample.disparity)
                err = np.abs(np.where(np.isfinite(pred), pred, 0) - np.where(finite, sample.disparity, 0))
                for region, mask in _regions(sample, options):
                    pools[name].setdefault(region, _Pool()).add(err[mask & finite], options.thresholds)
                if on_prediction:
                    on_prediction(name, sample, pred)
        if on_progress:
            on_progress(index + 1, total or index + 1)
    return {
        "dataset": dataset, "resolution": options.resolution, "samples": evaluated, "failed": failed,
        "methods": {name: {"regions": mean_over_samples(rows),
                           "pooled": {r: p.figures() for r, p in pools[name].items()},
                           "per_sample": rows}
                    for name, rows in per_sample.items()},
    }


def mean_over_samples(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per region and metric, the mean over the samples where it is defined (a sample whose region
    is empty has NaN there and does not count); ``samples`` says how many did."""
    sums: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        for region, figures in row["regions"].items():
            bucket = sums.setdefault(region, {})
            for key, value in figures.items():
                if value is not None and math.isfinite(value):
                    bucket.setdefault(key, []).append(float(value))
    out: dict[str, dict[str, float]] = {}
    for region, bucket in sums.items():
        out[region] = {key: float(np.mean(values)) for key, values in bucket.items()}
        out[region]["samples"] = len(bucket.get("epe", []))
    return out


@dataclass(frozen=True)
class _Unreadable:
    name: str
    reason: str


def iter_reader(reader: Any) -> Iterable[StereoSample | _Unreadable]:
    """The reader's samples in order; one that cannot be read becomes a reported failure."""
    for i in range(len(reader)):
        try:
            yield reader[i]
        except SampleError as exc:
            yield _Unreadable(reader.names[i], str(exc))
