"""The process group: the one module that reads torchrun's RANK / WORLD_SIZE / LOCAL_RANK /
MASTER_ADDR. Without them (``python -m model.train``) it is a world of one with no group."""

from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import timedelta

import torch
import torch.distributed as torch_dist

# Validation and checkpoints run on rank 0 while the others wait at a barrier.
_TIMEOUT = timedelta(minutes=60)


@dataclass(frozen=True)
class World:
    """This process's place: ``rank`` of ``size`` processes, on ``device``."""

    rank: int
    size: int
    local_rank: int
    device: torch.device
    backend: str | None  # None: a single process without a process group

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def init_world(device: str | None = None) -> World:
    """Join torchrun's group (gloo on CPU, NCCL on CUDA) or stand alone when not under torchrun.

    ``device``: "cpu", "cuda" (this rank's LOCAL_RANK-th GPU) or None (CUDA when available).
    """
    size = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    kind = device or ("cuda" if torch.cuda.is_available() else "cpu")
    if kind.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ValueError(f"device {kind!r}: CUDA is not available on this machine")
        index = local_rank if kind == "cuda" else torch.device(kind).index
        torch.cuda.set_device(index)
        target = torch.device("cuda", index)
    elif kind == "cpu":
        target = torch.device("cpu")
    else:
        raise ValueError(f"device {kind!r}: expected cpu, cuda or cuda:N")
    if size == 1 and "MASTER_ADDR" not in os.environ:
        return World(rank=0, size=1, local_rank=0, device=target, backend=None)
    backend = "nccl" if target.type == "cuda" else "gloo"
    torch_dist.init_process_group(backend, rank=rank, world_size=size, timeout=_TIMEOUT,
                                  device_id=target if target.type == "cuda" else None)
    return World(rank=rank, size=size, local_rank=local_rank, device=target, backend=backend)


def all_sum(world: World, values: torch.Tensor) -> torch.Tensor:
    """``values`` summed over the ranks (in place; returned for chaining)."""
    if world.backend is not None:
        torch_dist.all_reduce(values, op=torch_dist.ReduceOp.SUM)
    return values


def gather_objects(world: World, value: object) -> list[object]:
    """Every rank's ``value``, in rank order (pickled; small things only)."""
    if world.backend is None:
        return [value]
    out: list[object] = [None] * world.size
    torch_dist.all_gather_object(out, value)
    return out


def broadcast_object(world: World, value: object) -> object:
    """Rank 0's ``value`` on every rank."""
    if world.backend is None:
        return value
    box = [value]
    torch_dist.broadcast_object_list(box, src=0)
    return box[0]


def barrier(world: World) -> None:
    if world.backend is not None:
        torch_dist.barrier()


def close_world(world: World) -> None:
    if world.backend is not None and torch_dist.is_initialized():
        torch_dist.destroy_process_group()
