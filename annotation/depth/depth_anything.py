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

import math
from pathlib import Path

import numpy as np
import torch
from transformers import AutoImageProcessor, AutoModelForDepthEstimation, DPTImageProcessorPil

from annotation.checkpoints import CONFIG_FILE, PROCESSOR_FILE, open_checkpoint
from annotation.depth.base import DepthError, check_image

# preprocessor_config.json of the released Depth-Anything-V2-*-hf checkpoints.
_RELEASED_PROCESSOR = dict(size={"height": 518, "width": 518}, keep_aspect_ratio=True, ensure_multiple_of=14,
                           resample=3, do_rescale=True, rescale_factor=1 / 255, do_normalize=True,
                           image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225], do_pad=False)


class DepthAnythingBackend:
    """Relative disparity from a local Depth Anything (V2) checkpoint directory."""

    name = "depth-anything-v2"

    def __init__(self, model_path: Path, device: str = "cpu") -> None:
        checkpoint = open_checkpoint(model_path, "Depth Anything", {"depth_anything"})
        self.model_path = checkpoint.path
        if checkpoint.config.get("depth_estimation_type", "relative") != "relative":
            raise ValueError(f"{self.model_path / CONFIG_FILE} is a metric-depth checkpoint; "
                             "a relative (disparity) one is needed")
        try:
            self.device = torch.device(device)
        except RuntimeError as exc:
            raise ValueError(f"bad torch device {device!r}: {exc}") from None
        self.model_id = checkpoint.model_id(self.name)
        try:
            self.model = AutoModelForDepthEstimation.from_pretrained(self.model_path).to(self.device).eval()
            if (self.model_path / PROCESSOR_FILE).is_file():
                self.processor = AutoImageProcessor.from_pretrained(self.model_path, backend="pil")
            else:
                self.processor = DPTImageProcessorPil(**_RELEASED_PROCESSOR)
        except (OSError, ValueError) as exc:
            raise ValueError(f"cannot load Depth Anything from {self.model_path}: {exc}") from exc
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

