"""Checkpoints: the whole config, the trainable (and LoRA) weights, the frozen backbones'
content hashes and directories — never the backbones themselves — the step and ``extra``
(the trainer's optimizer/scheduler/RNG/data position). Written atomically.

Every load is ``torch.load(weights_only=True)``: a checkpoint holds tensors and plain values only,
so a file that names any other Python object is refused instead of run. Files written before
that rule (their ``extra.rng`` held numpy's RNG tuple) are converted once, from a shell, by
:func:`upgrade_checkpoint` (``illusion-studio checkpoints upgrade``).
"""

from __future__ import annotations

import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy._core import multiarray as numpy_multiarray

from core.atomic import atomic_write_bytes
from model.network import FusionNetwork
from model.presets import Config

FORMAT = "illusion-studio-fusion/1"
# What checkpoints of earlier releases hold beyond tensors: numpy's RNG state (an array and scalars).
_NUMPY_GLOBALS = [np.dtype, np.ndarray, numpy_multiarray._reconstruct, numpy_multiarray.scalar,
                  *(type(np.dtype(t)) for t in (np.uint8, np.int32, np.int64, np.uint32, np.float32, np.float64,
                                                np.bool_))]
UPGRADE_HINT = "illusion-studio checkpoints upgrade [PATH | --all]"


class UnsafeCheckpoint(ValueError):
    """A file that ``weights_only`` loading refuses: a checkpoint of an older release, or a pickle."""


def save_checkpoint(path: Path, network: FusionNetwork, config: Config, *, step: int,
                    extra: dict[str, Any] | None = None, source: dict[str, Any] | None = None) -> None:
    """Write the checkpoint of ``network`` at training ``step`` to ``path`` atomically; ``source``
    says where imported weights came from (plain values: file name, digest, architecture)."""
    payload = {"format": FORMAT, "config": config.to_dict(), "state": network.trainable_state_dict(),
               "frozen_hashes": network.frozen_state_hashes(), "frozen_paths": network.frozen_paths(),
               "step": int(step), "extra": extra or {}}
    if source is not None:
        payload["source"] = source
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    atomic_write_bytes(Path(path), buffer.getvalue())


def load_checkpoint(path: Path, map_location: str = "cpu", *, label: str | None = None) -> dict[str, Any]:
    """The raw payload, loaded with ``weights_only=True``.

    ``label`` names the file in messages (default: its path); callers serving the web pass a name
    relative to the workspace. Messages never quote the file's bytes.
    """
    path, label = Path(path), label or str(path)
    payload = read_weights_only(path, label, map_location=map_location,
                                hint=f"a checkpoint written before weights-only loading can be converted with "
                                     f"`{UPGRADE_HINT}`")
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{label} is not an Illusion Studio fusion-model checkpoint")
    return payload


def read_weights_only(path: Path, label: str, *, map_location: str = "cpu", hint: str = "") -> Any:
    """``torch.load(path, weights_only=True)``: tensors and plain values only. UnsafeCheckpoint for a
    file that names other Python objects (``hint`` says what to do), ValueError for one that is
    missing or unreadable; messages name the file by ``label`` and never quote its bytes."""
    if not path.is_file():
        raise ValueError(f"checkpoint {label} does not exist")
    if not zipfile.is_zipfile(path):  # torch.save has written zip archives since torch 1.6
        raise ValueError(f"{label} is not a readable checkpoint")
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError:
        # weights_only refuses any global it does not allow: an older checkpoint's numpy RNG
        # state, or a pickle that would run code. Neither is loaded here.
        raise UnsafeCheckpoint(f"{label} holds Python objects beyond tensors and plain values and is not loaded"
                               + (f": {hint}" if hint else " (weights-only loading)")) from None
    except Exception:  # torch raises many kinds for a file that is not a checkpoint
        raise ValueError(f"{label} is not a readable checkpoint") from None


def load_network(path: Path, device: str = "cpu", *,
                 label: str | None = None) -> tuple[FusionNetwork, Config, dict[str, Any]]:
    """(network in eval mode on ``device``, its config, the raw payload). The network is built from
    the stored config; the frozen backbones load from the stored config's directories and must
    hash as they did at saving (ValueError naming the directory otherwise)."""
    label = label or str(path)
    payload = load_checkpoint(path, label=label)
    config = Config.from_dict(payload["config"])
    network = FusionNetwork(config.model)
    hashes = network.frozen_state_hashes()
    for name, expected in payload.get("frozen_hashes", {}).items():
        if hashes.get(name) != expected:
            directory = network.frozen_paths().get(name, "(none)")
            raise ValueError(f"the {name} backbone in {directory} differs from the one checkpoint {label} "
                             "was trained with (content hash mismatch)")
    network.load_trainable_state_dict(payload["state"])
    return network.to(device).eval(), config, payload


def weights_finite(payload: dict[str, Any]) -> bool:
    """Whether every floating-point weight of a loaded checkpoint is finite (a diverged run's are not)."""
    return all(bool(torch.isfinite(t).all()) for t in payload.get("state", {}).values()
               if isinstance(t, torch.Tensor) and t.is_floating_point())


def plain_value(value: Any) -> Any:
    """``value`` with numpy arrays as tensors and numpy scalars as Python numbers, recursively:
    what ``weights_only`` loading accepts."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(value))
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: plain_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        converted = [plain_value(v) for v in value]
        return converted if isinstance(value, list) else tuple(converted)
    return value


def upgrade_checkpoint(path: Path) -> bool:
    """Rewrite an older checkpoint at ``path`` (atomically) so that it loads with ``weights_only``;
    False when it already does. The older file is read weights-only too, with numpy's array and
    scalar reconstruction allowed (what its RNG state needs) and nothing else, so even a planted
    pickle runs no code here. ValueError naming the file when it is not such a checkpoint."""
    path = Path(path)
    try:
        load_checkpoint(path)
        return False
    except UnsafeCheckpoint:
        pass
    try:
        with torch.serialization.safe_globals(_NUMPY_GLOBALS):
            payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raise ValueError(f"{path} holds objects beyond numpy arrays: not a checkpoint of an earlier release") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not an Illusion Studio fusion-model checkpoint")
    buffer = io.BytesIO()
    torch.save(plain_value(payload), buffer)
    data = buffer.getvalue()
    torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)  # refuses before anything is replaced
    atomic_write_bytes(path, data)
    return True



def load_fitting(network: torch.nn.Module, state: dict[str, torch.Tensor]) -> dict[str, list[str]]:
    """Load the tensors of ``state`` whose key and shape ``network``'s trainable state has; the rest
    of the network keeps its fresh weights. Returns ``{"loaded", "fresh", "unused"}``: keys loaded,
    keys of the network left as they were, keys of ``state`` with no place (or another shape)."""
    own = network.trainable_state_dict() if hasattr(network, "trainable_state_dict") else network.state_dict()
    fits = {k: v for k, v in state.items() if k in own and tuple(v.shape) == tuple(own[k].shape)}
    network.load_state_dict(fits, strict=False)
    return {"loaded": sorted(fits), "fresh": sorted(set(own) - set(fits)), "unused": sorted(set(state) - set(fits))}
