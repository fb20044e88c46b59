"""Checkpoints: the whole config, the trainable (and LoRA) weights, the frozen backbones'
content hashes and directories — never the backbones themselves — the step and ``extra``
(the trainer's optimizer/scheduler/RNG/data position). Written atomically."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from dataset.atomic import atomic_write_bytes
from model.network import FusionNetwork
from model.presets import Config

FORMAT = "illusion-studio-fusion/1"


def save_checkpoint(path: Path, network: FusionNetwork, config: Config, *, step: int,
                    extra: dict[str, Any] | None = None) -> None:
    """Write the checkpoint of ``network`` at training ``step`` to ``path`` atomically."""
    payload = {"format": FORMAT, "config": config.to_dict(), "state": network.trainable_state_dict(),
               "frozen_hashes": network.frozen_state_hashes(), "frozen_paths": network.frozen_paths(),
               "step": int(step), "extra": extra or {}}
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    atomic_write_bytes(Path(path), buffer.getvalue())


def load_checkpoint(path: Path, map_location: str = "cpu") -> dict[str, Any]:
    """The raw payload; ValueError naming ``path`` when it is missing or not such a checkpoint."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"checkpoint {path} does not exist")
    try:
        # Not weights_only: ``extra`` holds the trainer's optimizer and RNG states.
        payload = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as exc:  # torch raises many kinds for a file that is not a checkpoint
        raise ValueError(f"{path} is not a readable checkpoint: {type(exc).__name__}: {exc}") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not an Illusion Studio fusion-model checkpoint")
    return payload


def load_network(path: Path, device: str = "cpu") -> tuple[FusionNetwork, Config, dict[str, Any]]:
    """(network in eval mode on ``device``, its config, the raw payload). The network is built from
    the stored config; the frozen backbones load from the stored config's directories and must
    hash as they did at saving (ValueError naming the directory otherwise)."""
    payload = load_checkpoint(path)
    config = Config.from_dict(payload["config"])
    network = FusionNetwork(config.model)
    hashes = network.frozen_state_hashes()
    for name, expected in payload.get("frozen_hashes", {}).items():
        if hashes.get(name) != expected:
            directory = network.frozen_paths().get(name, "(none)")
            raise ValueError(f"the {name} backbone in {directory} differs from the one checkpoint {path} "
                             "was trained with (content hash mismatch)")
    network.load_trainable_state_dict(payload["state"])
    return network.to(device).eval(), config, payload
