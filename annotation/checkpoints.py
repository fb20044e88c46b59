"""Local checkpoint directories (what ``save_pretrained`` writes): one way to open and name them.

Every model-backed component (the depth, segmentation and VLM backends, the fusion model's
monocular and VLM branches) opens its directory here, so they refuse the same bad input with
the same one-line error and name the weights the same way: ``model_id`` is
``<backend>:<directory name>:<fingerprint>``, and the fingerprint changes when the checkpoint
in the directory is replaced, so caches keyed by it miss instead of serving stale results.
No torch import: opening and naming a directory is cheap and needs no model.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

CONFIG_FILE = "config.json"
PROCESSOR_FILE = "preprocessor_config.json"
# Files that change what a checkpoint answers without touching its weights (prompts, decoding);
# hashed by content where present. The two above are hashed always (a placeholder when missing).
# imported_from.json marks a Depth Anything directory converted from an original file, which then runs
# the original pipeline.
_EXTRA_CONFIGS = ("generation_config.json", "tokenizer_config.json", "chat_template.json", "chat_template.jinja",
                  "imported_from.json")
_WEIGHT_PATTERNS = ("*.safetensors", "*.bin")


@dataclass(frozen=True)
class Checkpoint:
    """An opened checkpoint directory: its ``config.json`` (a dict), ``model_type`` and a
    12-hex-digit ``fingerprint`` of its configs and weight files."""

    path: Path
    config: dict[str, Any]
    model_type: str
    fingerprint: str

    def model_id(self, backend: str) -> str:
        """``<backend>:<directory name>:<fingerprint>``: names these weights in caches and records."""
        return f"{backend}:{self.path.name}:{self.fingerprint}"


def open_checkpoint(path: str | Path, what: str, model_types: Collection[str] | None = None) -> Checkpoint:
    """Open the checkpoint directory ``path`` of a ``what`` model (e.g. "SAM2", for messages).

    Raises ValueError (one line) when ``path`` is not a directory, its ``config.json`` is missing,
    unreadable or names no ``model_type``, or (``model_types`` given) names another type.
    """
    path = Path(path)
    if not path.is_dir():
        raise ValueError(f"{what} model path {path} is not a directory")
    config_file = path / CONFIG_FILE
    try:
        config = json.loads(config_file.read_text(encoding="utf-8"))
        model_type = config["model_type"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        reason = f"{type(exc).__name__}: {exc}" if isinstance(exc, KeyError) else str(exc).splitlines()[0]
        raise ValueError(f"{path} is not a {what} checkpoint directory: {reason}") from None
    if not isinstance(model_type, str):
        raise ValueError(f"{config_file}: model_type must be a string, got {model_type!r}")
    if model_types is not None and model_type not in model_types:
        raise ValueError(f"{config_file} is a {model_type!r} model, not {' or '.join(sorted(model_types))}")
    return Checkpoint(path, config, model_type, fingerprint(path))


def fingerprint(path: Path) -> str:
    """12 hex digits over the configs' bytes and the weight files' names and sizes: cheap to
    compute (weights are not read), and it changes when the checkpoint is replaced."""
    digest = hashlib.sha256()
    for name in (CONFIG_FILE, PROCESSOR_FILE):
        file = path / name
        digest.update(file.read_bytes() if file.is_file() else b"-")
    for name in _EXTRA_CONFIGS:
        file = path / name
        if file.is_file():
            digest.update(name.encode() + b"\0" + file.read_bytes())
    for pattern in _WEIGHT_PATTERNS:
        for file in sorted(path.glob(pattern)):
            digest.update(f"{file.name}:{file.stat().st_size}".encode())
    return digest.hexdigest()[:12]
