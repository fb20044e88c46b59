"""The training loop: RAFT-Stereo's ``train_stereo.py`` (AdamW, OneCycle, gradient clipping,
AMP, frozen BatchNorm), made distributed, resumable and deterministic.

- Every sample of a step is its own forward pass with its own flow-noise generator (seeded from
  ``model.train.order``), and gradients accumulate over a rank's samples. One generator per
  batch would make the noise depend on how the batch is split across ranks; this way 2 ranks ×
  B/2 compute exactly the gradient 1 rank × B does. Frozen BatchNorm and per-sample
  normalisation mean the per-sample passes equal one batched pass.
- ``fusion_loss`` divides by the valid-pixel count of the whole global batch (all-reduced), so
  each rank's loss is its share of the global loss; DDP averages gradients over the ranks, so
  the backward pass is of ``loss × world_size``, which turns that average into the sum.
- A checkpoint's ``extra`` holds everything else a resumed run needs (see :func:`_extra`), as
  tensors and plain values only: it loads with ``torch.load(weights_only=True)``.
- A run ends ``diverged`` on a non-finite loss, non-finite weights or non-finite validation
  predictions (its last good checkpoint stays), and ``cancelled`` after the step at which rank 0
  sees ``RUN_DIR/cancel``: every rank stops at that step, and the checkpoint of that step is
  written first, so a resume goes on from it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel

from core.atomic import atomic_write_bytes
from dataset.run_layout import INIT_FILE
from model.checkpoint import load_checkpoint, load_fitting, load_network, save_checkpoint
from model.data import open_split, training_loader
from model.losses import fusion_loss
from model.network import FusionNetwork, FusionOutput
from model.presets import Config
from model.train import CANCEL_FILE
from model.train.checkpoints import (
    best_path,
    check_stereo_init,
    copy_atomic,
    model_differences,
    prune,
    restore_rng,
    rng_state,
    seed_everything,
    step_checkpoints,
    step_path,
)
from model.train.dist import World, all_sum, barrier, broadcast_object, gather_objects
from model.train.events import Board, append_event
from model.train.order import data_position
from model.train.spec import RunSpec
from model.train.validate import validate

STEP_EVENT_EVERY_S = 2.0  # step events are at most this far apart (and the first and last step have one)
# RAFT-Stereo schedules 100 steps past the end so that the last step's learning rate is not 0.
SCHEDULE_TAIL = 100


@dataclasses.dataclass
class Outcome:
    state: str  # "succeeded" | "diverged" | "cancelled"
    reason: str | None
    step: int


def freeze_batchnorm(module: nn.Module) -> None:
    """BatchNorm layers keep their running statistics (eval mode) while the rest trains."""
    for layer in module.modules():
        if isinstance(layer, nn.modules.batchnorm._BatchNorm):
            layer.eval()


def loss_pixels(gt: torch.Tensor, valid: torch.Tensor, max_disparity: float) -> torch.Tensor:
    """The pixels the loss counts: valid ground truth below the maximum disparity (bool B×1×H×W)."""
    return valid & (gt.abs() < max_disparity)


class Trainer:
    """One rank's run of ``spec``; ``step`` is the number of finished optimiser steps."""

    def __init__(self, spec: RunSpec, world: World) -> None:
        self.spec, self.world = spec, world
        self.run_dir = spec.run_dir
        self.config: Config = spec.config
        cfg = self.config.train
        self.device = world.device
        self.amp = bool(cfg.amp) and self.device.type == "cuda"
        seed_everything(cfg.seed)
        self.train_reader = open_split(spec, "train")
        self.val_reader = open_split(spec, "val") if spec.splits["val"] else None
        resume = self._newest_checkpoint()
        self.network, payload = self._network(resume)
        self.network.train()
        freeze_batchnorm(self.network)
        if cfg.freeze_trunk:
            self.network.freeze_trunk()
        self.params = [p for p in self.network.parameters() if p.requires_grad]
        self.model: nn.Module = self.network
        if world.backend is not None:
            # Every trainable parameter gets a gradient in every step (lite, paper, use_vlm off; see
            # tests/test_runs_honest.py), so DDP need not search the graph for unused ones (were one
            # left out, DDP would stop the run at the next step with an error naming it).
            self.model = DistributedDataParallel(
                self.network, device_ids=[self.device.index] if self.device.type == "cuda" else None,
                find_unused_parameters=False)
        self.optimizer = torch.optim.AdamW(self.params, lr=cfg.lr, weight_decay=cfg.weight_decay, eps=1e-8)
        self.scheduler = torch.optim.lr_scheduler.OneCycleLR(
            self.optimizer, cfg.lr, total_steps=cfg.steps + SCHEDULE_TAIL, pct_start=cfg.pct_start,
            cycle_momentum=False, anneal_strategy="linear")
        self.scaler = torch.amp.GradScaler("cuda", enabled=self.amp)
        self.step = 0
        self.resumed_from: int | None = None
        self.best_epe = math.inf
        self.last_saved: int | None = None
        if resume is not None:
            self._restore(resume, payload)
        self.board = Board(self.run_dir, self.step) if world.is_main else None

    # --- setup ---------------------------------------------------------------------------------

    def _newest_checkpoint(self) -> Path | None:
        found = step_checkpoints(self.run_dir)
        return found[-1][1] if found else None

    def _network(self, resume: Path | None) -> tuple[FusionNetwork, dict[str, Any] | None]:
        """The network to train: the resumed checkpoint's, the init checkpoint's weights, or fresh."""
        source = resume or self.spec.init_checkpoint
        if source is None and self.spec.init_stereo is not None:
            return self._stereo_started(self.spec.init_stereo), None
        if source is None:
            return FusionNetwork(self.config.model).to(self.device), None
        network, stored, payload = load_network(source, device=str(self.device))
        differ = model_differences(stored.model, self.config.model)
        if differ:
            raise ValueError(f"{source}: its model config differs from run.json's in {', '.join(differ)}")
        return network, payload if resume is not None else None

    def _stereo_started(self, path: Path) -> FusionNetwork:
        """A fresh network whose stereo branch starts from the imported RAFT-Stereo checkpoint
        ``path``: the tensors that fit load (:func:`model.raft_import.stereo_branch_state`), the rest
        start fresh; rank 0 records which in ``RUN_DIR/init.json`` for the run page."""
        from model.raft_import import stereo_branch_state

        check_stereo_init(path, label=path.name)
        payload = load_checkpoint(path, label=path.name)
        network = FusionNetwork(self.config.model)
        fitted, unused = stereo_branch_state(payload["state"], network.trainable_state_dict())
        report = {**load_fitting(network, fitted), "unused": unused}
        if self.world.is_main:
            atomic_write_bytes(self.run_dir / INIT_FILE, json.dumps(report, indent=1).encode())
        return network.to(self.device)

    def _restore(self, path: Path, payload: dict[str, Any] | None) -> None:
        """Continue from ``path``: optimiser, schedule, scaler, step, best EPE and RNG states."""
        extra = (payload or load_checkpoint(path, map_location=str(self.device))).get("extra") or {}
        try:
            self.optimizer.load_state_dict(extra["optimizer"])
            self.scheduler.load_state_dict(extra["scheduler"])
            self.scaler.load_state_dict(extra["scaler"])
            data = extra["data"]
        except KeyError as exc:
            raise ValueError(f"{path}: not a training checkpoint of this engine (no {exc.args[0]})") from None
        step = int((payload or {}).get("step", data["position"] // self.config.train.batch_size))
        if data["samples"] != len(self.train_reader):
            raise ValueError(f"{path}: trained on {data['samples']} samples, the training split now has "
                             f"{len(self.train_reader)}")
        if extra.get("dataset_version") != self.spec.dataset_version:
            raise ValueError(f"{path}: trained on dataset version {extra.get('dataset_version')}, "
                             f"run.json pins {self.spec.dataset_version}")
        states = extra.get("rng") or []
        if len(states) == self.world.size:
            restore_rng(states[self.world.rank])
        else:  # another world size: still deterministic, no longer bit-exact
            seed_everything(self.config.train.seed + step)
        self.step = self.last_saved = step
        self.resumed_from = step
        best = extra.get("best_epe")
        self.best_epe = math.inf if best is None else float(best)

    # --- the run -------------------------------------------------------------------------------

    def run(self) -> Outcome:
        """Train from ``step`` to the configured steps; the outcome (an exception is a failure)."""
        try:
            return self._run()
        finally:
            if self.board is not None:
                self.board.close()

    def _run(self) -> Outcome:
        cfg = self.config.train
        world = self.world
        batches = training_loader(self.train_reader, cfg, start=self.step, rank=world.rank,
                                  world_size=world.size, workers=self.spec.workers)
        self._event({"event": "start", "step": self.step, "steps": cfg.steps, "world_size": world.size,
                     "resumed_from_step": self.resumed_from, "device": str(self.device),
                     "dataset_version": self.spec.dataset_version,
                     "samples": {"train": len(self.train_reader), "val": len(self.val_reader or [])}})
        # Rates count the time of loading and stepping, not of validation and checkpoints.
        mark, last_event = time.monotonic(), -math.inf
        train_s, timed, window_s, window_steps = 0.0, 0, 0.0, 0
        for batch in batches:
            lr = self.optimizer.param_groups[0]["lr"]
            loss, parts = self._train_step(batch)
            diverged = (f"non-finite loss ({loss}) at step {self.step + 1}" if not math.isfinite(loss)
                        else None if self._weights_finite() else f"non-finite weights after step {self.step + 1}")
            if diverged is not None:
                self._event({"event": "end", "state": "diverged", "reason": diverged, "step": self.step})
                return Outcome("diverged", diverged, self.step)
            self.step += 1
            now = time.monotonic()
            train_s, timed = train_s + now - mark, timed + 1
            window_s, window_steps = window_s + now - mark, window_steps + 1
            if self.board is not None:
                self.board.scalars(self.step, "train", {"loss": loss, "lr": lr, **parts})
            if world.is_main and (now - last_event >= STEP_EVENT_EVERY_S or timed == 1 or self.step == cfg.steps):
                rate = cfg.batch_size * window_steps / max(window_s, 1e-9)
                self._event({"event": "step", "step": self.step, "steps": cfg.steps, "loss": loss, "lr": lr,
                             "samples_per_s": round(rate, 3), "step_s": round(window_s / window_steps, 3),
                             "eta_s": round(train_s / timed * (cfg.steps - self.step), 1), "parts": parts})
                print(f"step {self.step}/{cfg.steps} loss {loss:.4f} lr {lr:.3g} {rate:.2f} samples/s", flush=True)
                last_event, window_s, window_steps = now, 0.0, 0
            diverged = self._after_step()
            if diverged is not None:
                self._event({"event": "end", "state": "diverged", "reason": diverged, "step": self.step})
                return Outcome("diverged", diverged, self.step)
            if self._cancel_seen():
                if self.last_saved != self.step:
                    self._checkpoint(best=False)
                reason = f"cancelled at step {self.step}"
                self._event({"event": "end", "state": "cancelled", "reason": reason, "step": self.step})
                return Outcome("cancelled", reason, self.step)
            mark = time.monotonic()
        if self.last_saved != self.step:
            self._checkpoint(best=False)
        self._event({"event": "end", "state": "succeeded", "reason": None, "step": self.step})
        return Outcome("succeeded", None, self.step)

    def _train_step(self, batch: dict[str, Any]) -> tuple[float, dict[str, float]]:
        """One optimiser step on this rank's share; the global batch's loss and its parts
        (the loss is NaN/inf when it diverged, and then nothing was updated)."""
        cfg, world, device = self.config.train, self.world, self.device
        left, right = batch["left"].to(device), batch["right"].to(device)
        gt, valid = batch["disparity"].to(device), batch["valid"].to(device)
        mono = [None if m is None else m[None].to(device) for m in batch["mono"]]
        counted = loss_pixels(gt, valid, cfg.max_disparity)
        total = all_sum(world, counted.sum().to(torch.float64)).to(torch.float32).clamp_min(1.0)
        self.optimizer.zero_grad(set_to_none=True)
        loss_sum = torch.zeros((), dtype=torch.float64, device=device)
        parts_sum: dict[str, float] = {}
        n = left.shape[0]
        for j in range(n):
            last = j == n - 1
            sync = contextlib.nullcontext() if last or world.backend is None else self.model.no_sync()
            with sync:
                noise = torch.Generator(device=device).manual_seed(batch["noise_seed"][j])
                with torch.autocast(device.type, dtype=torch.float16, enabled=self.amp):
                    out = self.model(left[j:j + 1], right[j:j + 1], mono[j],
                                     iters=cfg.train_iters, noise=noise)
                loss, parts = fusion_loss(_float(out), gt[j:j + 1], valid[j:j + 1], cfg, valid_total=total)
                self.scaler.scale(loss * world.size).backward()
            loss_sum += loss.detach().to(torch.float64)
            for name, value in parts.items():
                parts_sum[name] = parts_sum.get(name, 0.0) + float(value)
        names = sorted(parts_sum)
        stats = all_sum(world, torch.tensor([float(loss_sum), *(parts_sum[k] for k in names)], dtype=torch.float64,
                                            device=device)).tolist()
        if not math.isfinite(stats[0]):
            return stats[0], {}
        self.scaler.unscale_(self.optimizer)
        torch.nn.utils.clip_grad_norm_(self.params, cfg.grad_clip)
        self.scaler.step(self.optimizer)
        self.scaler.update()
        self.scheduler.step()
        return stats[0], dict(zip(names, stats[1:], strict=True))

    def _weights_finite(self) -> bool:
        """Whether every trained weight is finite (one device sync; DDP keeps the ranks' weights equal)."""
        return bool(torch.stack([torch.isfinite(p).all() for p in self.params]).all())

    def _cancel_seen(self) -> bool:
        """Whether rank 0 sees the cancel flag, on every rank alike (one tiny all-reduce)."""
        seen = self.world.is_main and (self.run_dir / CANCEL_FILE).exists()
        return bool(all_sum(self.world, torch.tensor([float(seen)], device=self.device)).item())

    def _after_step(self) -> str | None:
        """Validate and checkpoint when due; why the run diverged when its predictions are not
        finite (then nothing is saved)."""
        cfg = self.config.train
        final = self.step == cfg.steps
        best = False
        if self.val_reader is not None and (self.step % cfg.val_every == 0 or final):
            best, non_finite = self._validate()
            if non_finite:
                return f"non-finite predictions on {non_finite} validation sample(s) after step {self.step}"
        if self.step % cfg.checkpoint_every == 0 or final:
            self._checkpoint(best=best)
        elif best:
            self._checkpoint(best=True, step_file=False)
        return None

    def _validate(self) -> tuple[bool, int]:
        """Rank 0 validates while the others wait; on every rank: whether this is the best EPE so
        far, and how many validation predictions were not finite."""
        epe, non_finite = math.nan, 0
        if self.world.is_main:
            assert self.val_reader is not None and self.board is not None
            started = time.monotonic()
            result = validate(self.network, self.config, self.val_reader, self.device, self.run_dir, self.step)
            metrics, images, non_finite = result.metrics, result.images, result.non_finite
            self.network.train()
            freeze_batchnorm(self.network)
            for region, values in metrics.items():
                self.board.scalars(self.step, f"val/{region}", values)
            for path, rgb in images.items():
                self.board.image(self.step, f"val/{Path(path).stem}", rgb)
            self.board.flush()
            self._event({"event": "val", "step": self.step, "metrics": metrics, "images": list(images),
                         "seconds": round(time.monotonic() - started, 3)})
            epe = metrics["all"]["epe"]
        epe, non_finite = broadcast_object(self.world, (epe, non_finite))  # type: ignore[misc]
        if not non_finite and math.isfinite(epe) and epe < self.best_epe:
            self.best_epe = float(epe)
            return True, 0
        return False, int(non_finite)

    def _checkpoint(self, *, best: bool, step_file: bool = True) -> None:
        """Write this step's checkpoint (and best.pt) on rank 0 with every rank's RNG state, then
        prune; the others wait, so nobody runs ahead of a checkpoint that may not exist."""
        started = time.monotonic()
        states = gather_objects(self.world, rng_state())
        if self.world.is_main:
            target = step_path(self.run_dir, self.step) if step_file else best_path(self.run_dir)
            save_checkpoint(target, self.network, self.config, step=self.step, extra=self._extra(states))
            if step_file:
                self._event({"event": "checkpoint", "step": self.step, "path": _relative(target, self.run_dir),
                             "best": False, "seconds": round(time.monotonic() - started, 3)})
            if best:
                if step_file:
                    copy_atomic(target, best_path(self.run_dir))
                self._event({"event": "checkpoint", "step": self.step,
                             "path": _relative(best_path(self.run_dir), self.run_dir), "best": True})
            prune(self.run_dir, self.config.train.keep_last)
        if step_file:
            self.last_saved = self.step
        barrier(self.world)

    def _extra(self, states: list[object]) -> dict[str, Any]:
        """The engine's state in a checkpoint's ``extra``."""
        cfg = self.config.train
        n = len(self.train_reader)
        return {
            "optimizer": self.optimizer.state_dict(), "scheduler": self.scheduler.state_dict(),
            "scaler": self.scaler.state_dict(), "rng": states, "world_size": self.world.size,
            "data": {**data_position(self.step, cfg.batch_size, n), "samples": n, "seed": cfg.seed,
                     "batch_size": cfg.batch_size},
            "dataset_version": self.spec.dataset_version,
            "best_epe": None if math.isinf(self.best_epe) else self.best_epe,
        }

    def _event(self, event: dict[str, Any]) -> None:
        if self.world.is_main:
            append_event(self.run_dir, event)


def _relative(path: Path, run_dir: Path) -> str:
    return path.relative_to(run_dir).as_posix()


def _float(out: FusionOutput) -> FusionOutput:
    """The network's outputs in float32 (under AMP they may be half): the loss is computed in full precision."""
    changes = {}
    for field in dataclasses.fields(out):
        value = getattr(out, field.name)
        if isinstance(value, torch.Tensor):
            changes[field.name] = value.float()
        elif isinstance(value, list):
            changes[field.name] = [v.float() for v in value]
    return dataclasses.replace(out, **changes)
