"""How long a launch would train, from the step times the workspace's finished runs measured.

A step's cost grows with the samples in it, their pixels and the GRU iterations each one runs, so the
estimate takes the measured run of the same preset nearest in those three and scales its median step
time by their ratio (batch × crop pixels × iterations). Nothing here starts torch.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from dataset.services.training import effective_state
from dataset.tables import TrainingMetric, TrainingRun
from model.presets import load_preset
from model.runs.schema import RunLaunch

MEASURED_RUNS = 20  # the newest finished runs of a preset looked at: older ones rarely are nearer


@dataclass(frozen=True)
class Size:
    """What a training step's time scales with."""

    batch: int
    crop: tuple[int, int]  # (H, W) pixels
    iters: int

    @property
    def work(self) -> int:
        return self.batch * self.crop[0] * self.crop[1] * self.iters

    def text(self) -> str:
        return f"batch {self.batch}, {self.crop[0]}×{self.crop[1]}, {self.iters} iterations"


@dataclass(frozen=True)
class Measured:
    """A finished run's size and its median step time in seconds."""

    run: int
    size: Size
    step_s: float


def launch_size(request: RunLaunch) -> tuple[int, Size]:
    """The steps and the step size a validated launch trains with (the preset's where it names none)."""
    train = load_preset(request.preset).train
    crop = tuple(request.crop) if request.crop else tuple(train.crop)
    return (request.steps or train.steps,
            Size(request.batch or train.batch_size, (int(crop[0]), int(crop[1])), request.iters or train.train_iters))


def _size_of(config: dict[str, Any]) -> Size | None:
    train = config.get("train") or {}
    try:
        crop = train["crop"]
        return Size(int(train["batch_size"]), (int(crop[0]), int(crop[1])), int(train["train_iters"]))
    except (KeyError, TypeError, ValueError, IndexError):
        return None


def measured_runs(session: Session, preset: str) -> list[Measured]:
    """The newest finished runs of ``preset`` whose curves record a throughput, newest first."""
    runs = session.scalars(select(TrainingRun).where(TrainingRun.preset == preset, TrainingRun.step > 0)
                           .order_by(TrainingRun.id.desc()).limit(MEASURED_RUNS * 3))
    found = []
    for run in runs:
        size = _size_of(run.config or {})
        if size is None or not effective_state(run).finished or len(found) >= MEASURED_RUNS:
            continue
        rates = session.scalars(select(TrainingMetric.values).where(
            TrainingMetric.run_id == run.id, TrainingMetric.kind == "step"))
        # samples_per_s counts the whole batch (every process): batch / rate is the step's wall time.
        times = [size.batch / v["samples_per_s"] for v in rates
                 if isinstance(v.get("samples_per_s"), int | float) and v["samples_per_s"] > 0]
        if times:
            found.append(Measured(run.id, size, statistics.median(times)))
    return found


def duration_text(seconds: float) -> str:
    """``1 min 36 s``, ``3 h 5 min``: as the runs table writes durations."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60} s"
    return f"{s // 3600} h {(s % 3600) // 60} min"


def estimate(preset: str, steps: int, size: Size, measured: list[Measured]) -> dict[str, Any]:
    """``{"seconds", "text", "run", "scale"}``: ``steps`` × the nearest measured run's step time
    scaled to ``size`` (nearest: the smallest scaling, the newest on a tie); seconds None when no
    run of ``preset`` measured one."""
    if not measured:
        return {"seconds": None, "run": None, "scale": None,
                "text": f"unknown: no finished {preset} run has recorded its step times yet"}
    nearest = min(measured, key=lambda m: abs(math.log(size.work / m.size.work)))
    scale = size.work / nearest.size.work
    seconds = steps * nearest.step_s * scale
    scaled = "" if math.isclose(scale, 1) else f", scaled ×{scale:.3g} for batch, crop and iterations"
    return {"seconds": seconds, "run": nearest.run, "scale": scale,
            "text": f"about {duration_text(seconds)} ({steps} steps × {nearest.step_s:.3g} s measured on run "
                    f"{nearest.run} at {nearest.size.text()}{scaled})"}


def launch_estimate(session: Session, request: RunLaunch) -> dict[str, Any]:
    """The estimate for a validated launch, from the workspace's finished runs of its preset."""
    steps, size = launch_size(request)
    return estimate(request.preset, steps, size, measured_runs(session, request.preset))


def latest_finished_size(session: Session) -> dict[str, Any] | None:
    """The preset and step size of the newest finished run that trained a step: what the launch
    form starts from, so its estimate has a measured run to go by (None when there is none)."""
    for run in session.scalars(select(TrainingRun).where(TrainingRun.step > 0).order_by(TrainingRun.id.desc()).limit(50)):
        size = _size_of(run.config or {})
        if size is not None and effective_state(run).finished:
            return {"run": run.id, "preset": run.preset, "batch": size.batch, "crop": f"{size.crop[0]}x{size.crop[1]}",
                    "iters": size.iters}
    return None
