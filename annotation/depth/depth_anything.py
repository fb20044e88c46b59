"""Depth Anything V2 through Hugging Face ``transformers``: ``AutoModelForDepthEstimation`` and
the checkpoint's image processor, loaded with ``from_pretrained`` from one local directory.

Pre- and post-processing are transformers' own DPT image processor, pinned to its PIL backend:
its default torchvision backend cannot be used with the CPU build of torch (no matching
torchvision wheel), and pinning keeps the numbers the same on every machine. The processor
resizes keeping the aspect ratio to sides that are multiples of the patch size (14; 518 px
target for the released checkpoints, read from ``preprocessor_config.json``), rescales and
normalises; ``post_process_depth_estimation`` resizes the output back (bicubic). A directory
without a processor config gets the released checkpoints' settings.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch
from transformers import AutoImageProcessor, AutoModelForDepthEstimation, DPTImageProcessorPil

from annotation.depth.base import DepthError, check_image

# preprocessor_config.json of the released Depth-Anything-V2-*-hf checkpoints.
_RELEASED_PROCESSOR = dict(size={"height": 518, "width": 518}, keep_aspect_ratio=True, ensure_multiple_of=14,
                           resample=3, do_rescale=True, rescale_factor=1 / 255, do_normalize=True,
                           image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225], do_pad=False)
_PROCESSOR_FILE = "preprocessor_config.json"


class DepthAnythingBackend:
    """Relative disparity from a local Depth Anything (V2) checkpoint directory."""

    name = "depth-anything-v2"

    def __init__(self, model_path: Path, device: str = "cpu") -> None:
        self.model_path = Path(model_path)
        self.model, self.processor, self.model_id = load_depth_anything(self.model_path, device)
        self.device = self.model.device
        # The backbone only sees whole patches: whatever the processor config says, keep sides multiples of it.
        self._multiple = math.lcm(int(self.processor.ensure_multiple_of or 1), int(self.model.config.patch_size))

    def estimate(self, image: np.ndarray) -> np.ndarray:
        """Relative disparity (float32 HxW, larger = nearer) of RGB uint8 HxWx3 ``image``."""
        image = check_image(image)
        height, width = image.shape[:2]
        try:
            inputs = self.processor(images=image, return_tensors="pt", input_data_format="channels_last",
                                    ensure_multiple_of=self._multiple)
        except ValueError as exc:  # e.g. an aspect ratio so extreme that one side rounds to 0 patches
            raise DepthError(f"cannot prepare a {height}x{width} image for {self.model_id}: {exc}") from None
        with torch.inference_mode():
            outputs = self.model(pixel_values=inputs["pixel_values"].to(self.device))
            [result] = self.processor.post_process_depth_estimation(outputs, target_sizes=[(height, width)])
        return result["predicted_depth"].float().cpu().numpy().reshape(height, width)


def load_depth_anything(model_path: Path, device: str = "cpu") -> tuple[Any, Any, str]:
    """(model in eval mode on ``device``, its PIL image processor, model id) from a local relative-depth
    Depth Anything checkpoint directory; ValueError (one line) naming the directory otherwise."""
    model_path = Path(model_path)
    config_file = model_path / "config.json"
    try:
        config = json.loads(config_file.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{model_path} is not a Depth Anything checkpoint directory: {exc}") from exc
    if config.get("model_type") != "depth_anything":
        raise ValueError(f"{config_file} is a {config.get('model_type')!r} model, not depth_anything")
    if config.get("depth_estimation_type", "relative") != "relative":
        raise ValueError(f"{config_file} is a metric-depth checkpoint; a relative (disparity) one is needed")
    try:
        torch_device = torch.device(device)
    except RuntimeError as exc:
        raise ValueError(f"bad torch device {device!r}: {exc}") from None
    model_id = f"{DepthAnythingBackend.name}:{model_path.name}:{_fingerprint(model_path)}"
    try:
        model = AutoModelForDepthEstimation.from_pretrained(model_path).to(torch_device).eval()
        if (model_path / _PROCESSOR_FILE).is_file():
            processor = AutoImageProcessor.from_pretrained(model_path, backend="pil")
        else:
            processor = DPTImageProcessorPil(**_RELEASED_PROCESSOR)
    except (OSError, ValueError) as exc:
        raise ValueError(f"cannot load Depth Anything from {model_path}: {exc}") from exc
    return model, processor, model_id


def _fingerprint(model_path: Path) -> str:
    """12 hex digits over the configs and the weight files' names and sizes: cheap to compute,
    and it changes when the checkpoint in the directory is replaced."""
    digest = hashlib.sha256()
    for name in ("config.json", _PROCESSOR_FILE):
        path = model_path / name
        digest.update(path.read_bytes() if path.is_file() else b"-")
    for path in sorted(model_path.glob("*.safetensors")) + sorted(model_path.glob("*.bin")):
        digest.update(f"{path.name}:{path.stat().st_size}".encode())
    return digest.hexdigest()[:12]
