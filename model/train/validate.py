"""Validation during training: EPE and bad-2/3 (percent) on all / illusion / non-illusion pixels
of the validation split, averaged over images as the authors do, plus a few pictures."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from core.atomic import atomic_write_bytes
from dataset.preview.images import encode_png
from dataset.readers import Reader
from model.metrics import disparity_metrics
from model.network import FusionNetwork
from model.predictor import Predictor
from model.presets import Config
from model.train.images import prediction_strip
from model.train.order import validation_noise_seed

REGIONS = ("all", "illusion", "non_illusion")
METRICS = ("epe", "bad2", "bad3")
VAL_DIR = "val"
IMAGES = 4  # the first few validation samples are pictured at every validation

Metrics = dict[str, dict[str, float]]


@dataclass(frozen=True)
class Validation:
    """One validation: ``metrics`` per region (NaN where no validation pixel falls in the region),
    the pictures written under ``RUN_DIR/val/step_XXXXXXX/`` (relative path → RGB uint8 H×5W×3),
    and how many predictions held a non-finite value (a diverged network's)."""

    metrics: Metrics
    images: dict[str, np.ndarray]
    non_finite: int


@torch.no_grad()
def validate(network: FusionNetwork, config: Config, reader: Reader, device: torch.device, run_dir: Path,
             step: int, images: int = IMAGES) -> Validation:
    """Predict every validation sample and score it (see :class:`Validation`)."""
    predictor = Predictor(network, config, device=str(device))
    sums = {region: dict.fromkeys(METRICS, 0.0) for region in REGIONS}
    counts = dict.fromkeys(REGIONS, 0)
    written: dict[str, np.ndarray] = {}
    non_finite = 0
    for i in range(len(reader)):
        sample = reader[i]
        pred = predictor.predict(sample.left, sample.right, sample.mono, iters=config.train.test_iters,
                                 seed=validation_noise_seed(config.train.seed, i))
        non_finite += int(not np.isfinite(pred.disparity).all())
        for region in REGIONS:
            mask = sample.regions.get(region)
            if mask is None or not mask.any():
                continue
            values = disparity_metrics(pred.disparity, sample.disparity, mask, thresholds=(2, 3))
            for name in METRICS:
                sums[region][name] += values[name]
            counts[region] += 1
        if i < images:
            relative = Path(VAL_DIR) / f"step_{step:07d}" / f"{_file_stem(sample.name)}.png"
            strip = prediction_strip(sample.left, sample.disparity, pred.disparity, pred.confidence)
            atomic_write_bytes(run_dir / relative, encode_png(strip))
            written[relative.as_posix()] = strip
    metrics = {region: {name: (sums[region][name] / counts[region] if counts[region] else math.nan)
                        for name in METRICS} for region in REGIONS}
    return Validation(metrics, written, non_finite)


def _file_stem(name: str) -> str:
    """A sample name ("video_3/000007") as one safe file name ("video_3__000007")."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name.replace("/", "__")).strip("._") or "sample"

