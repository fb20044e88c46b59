"""The pre-trained trunk of ``lite``: its mono context encoder and stereo branch, as one file.

``bench pretrain`` writes ``<work dir>/pretrain/trunk.safetensors`` (the ``mono.*`` and
``stereo_branch.*`` tensors of its run's best checkpoint; safetensors, so loading it runs no code)
and ``trunk.json`` beside it (the file's sha256, size, tensor and parameter counts, and the recipe
that made it: data, seeds, overrides, steps, code version). ``bench fusion`` fine-tunes every network
from it through the training engine's ordinary ``init`` checkpoint: :func:`compose_init` writes, per
network and seed, a full checkpoint of that network — the trunk's tensors where a tensor of the same
name and shape exists, the rest exactly as a fresh run of that seed would start — and says which
tensors started fresh (the stereo-only network has no VLM, confidence or fusion head to fill).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors

from core.atomic import atomic_write_bytes
from model.checkpoint import load_checkpoint, save_checkpoint
from model.network import TRUNK_PREFIXES, FusionNetwork
from model.presets import Config

FORMAT = "illusion-studio-trunk/1"
TRUNK_FILE = Path("pretrain") / "trunk.safetensors"  # under the benchmark's work dir
# The stereo-only network's trunk (``bench pretrain --stereo-only``): a stereo branch that never read the mono.
STEREO_ONLY_TRUNK_FILE = Path("pretrain") / "trunk-stereo-only.safetensors"


def trunk_file(stereo_only: bool = False, truth: str = "surface") -> Path:
    """Where ``bench pretrain`` writes a trunk under the work dir: TRUNK_FILE, STEREO_ONLY_TRUNK_FILE, or
    either with ``-matcher`` before the suffix when pre-trained on the matcher's truth."""
    path = STEREO_ONLY_TRUNK_FILE if stereo_only else TRUNK_FILE
    return path if truth == "surface" else path.with_name(f"{path.stem}-{truth}{path.suffix}")


@dataclass(frozen=True)
class Trunk:
    """A loaded trunk: its tensors by name, the file's sha256, the recipe that made it, the file's name."""

    state: dict[str, torch.Tensor]
    sha256: str
    recipe: dict[str, Any]
    name: str


def record_path(path: Path) -> Path:
    """``trunk.json`` for ``trunk.safetensors``: the recipe and hash kept beside the file."""
    return Path(path).with_suffix(".json")


def save_trunk(checkpoint: Path, path: Path, recipe: dict[str, Any]) -> dict[str, Any]:
    """Write the trunk tensors (TRUNK_PREFIXES) of the fusion checkpoint ``checkpoint`` to ``path`` and its
    record (:func:`record_path`) with ``recipe``, both atomically; returns the record."""
    state = {name: tensor.contiguous() for name, tensor in load_checkpoint(checkpoint)["state"].items()
             if name.startswith(TRUNK_PREFIXES)}
    if not state:
        raise ValueError(f"{checkpoint} holds no {' or '.join(TRUNK_PREFIXES)} tensors")
    data = save_safetensors(state, metadata={"format": FORMAT})
    record = {"file": Path(path).name, "format": FORMAT, "sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data),
              "tensors": len(state), "parameters": sum(t.numel() for t in state.values()), "recipe": recipe}
    atomic_write_bytes(Path(path), data)
    atomic_write_bytes(record_path(path), (json.dumps(record, indent=1) + "\n").encode())
    return record


def load_trunk(path: Path) -> Trunk:
    """The trunk at ``path``, checked against its record: ValueError when either is missing, the file's
    sha256 is not the recorded one, or it holds anything but trunk tensors."""
    path = Path(path)
    record = record_path(path)
    if not path.is_file() or not record.is_file():
        raise ValueError(f"pre-trained trunk {path} needs both the file and {record.name} beside it "
                         "(`illusion-studio bench pretrain` writes them)")
    data = path.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    doc = json.loads(record.read_text())
    if doc.get("sha256") != digest:
        raise ValueError(f"{path}: sha256 {digest[:12]}… is not the {str(doc.get('sha256'))[:12]}… that {record.name} "
                         "records: the file changed after pre-training")
    try:
        state = load_safetensors(data)
    except SafetensorError as exc:
        raise ValueError(f"{path} is not a readable safetensors file ({exc})") from None
    foreign = sorted(name for name in state if not name.startswith(TRUNK_PREFIXES))
    if not state or foreign:
        raise ValueError(f"{path} is not a trunk: {'no tensors' if not state else f'it holds {foreign[0]}'}")
    return Trunk(state, digest, doc.get("recipe") or {}, path.name)


def compose_init(trunk: Trunk, config: Config, seed: int, path: Path) -> dict[str, Any]:
    """Write to ``path`` a step-0 checkpoint of ``config``'s network for a training run's ``init``: each
    tensor from ``trunk`` where it holds one of the same name and shape, the others as the engine's
    fresh network of training seed ``seed`` starts (the engine seeds torch with it, then builds the
    network). Returns the count loaded, the names that started fresh, and the trunk tensors unused."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        network = FusionNetwork(config.model)
    state = network.trainable_state_dict()
    fits = {name for name, tensor in trunk.state.items() if name in state and state[name].shape == tensor.shape}
    network.load_trainable_state_dict({**state, **{name: trunk.state[name] for name in fits}})
    save_checkpoint(path, network, config, step=0)
    return {"loaded": len(fits), "fresh": sorted(set(state) - fits), "unused": sorted(set(trunk.state) - fits)}
