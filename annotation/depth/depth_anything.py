"""Depth Anything V2 through Hugging Face ``transformers``: ``AutoModelForDepthEstimation`` and
the checkpoint's image processor, loaded with ``from_pretrained`` from one local directory.

Pre- and post-processing are transformers' own DPT image processor, pinned to its PIL backend:
its default torchvision backend cannot be used with the CPU build of torch (no matching
torchvision wheel), and pinning keeps the numbers the same on every machine. The processor
resizes keeping the aspect ratio to sides that are multiples of the patch size (14; 518 px
target for the released checkpoints, read from ``preprocessor_config.json``), rescales and
normalises; ``post_process_depth_estimation`` resizes the output back (bicubic). A directory
without a processor config gets the released checkpoints' settings.

A directory converted from Depth Anything V2's original ``.pth`` files
(``annotation.depth.depth_anything_import``) runs the original code's ``infer_image(image, 518)``
instead, step for step: the float image resized by OpenCV (bicubic) so that both sides are at least
518 px and multiples of 14, ImageNet normalisation, DINOv2's position embeddings interpolated by a
scale factor with a 0.1 offset, and the output resized back bilinearly with ``align_corners=True``.
"""

from __future__ import annotations

import math
import types
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from transformers import AutoImageProcessor, AutoModelForDepthEstimation, DPTImageProcessorPil

from annotation.checkpoints import CONFIG_FILE, PROCESSOR_FILE, open_checkpoint
from annotation.depth.base import DepthError, check_image
from annotation.depth.depth_anything_import import imported_source

# preprocessor_config.json of the released Depth-Anything-V2-*-hf checkpoints.
_RELEASED_PROCESSOR = dict(size={"height": 518, "width": 518}, keep_aspect_ratio=True, ensure_multiple_of=14,
                           resample=3, do_rescale=True, rescale_factor=1 / 255, do_normalize=True,
                           image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225], do_pad=False)
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
ORIGINAL_SIZE = 518  # the original infer_image's default input_size
POSITION_OFFSET = 0.1  # DINOv2's (and so the original Depth Anything's) interpolation offset
# The original scales the shorter side up to 518 px: a long, thin image would become a network input
# whose attention no machine holds. Beyond this side it is refused instead.
MAX_ORIGINAL_SIDE = 8 * ORIGINAL_SIZE


class DepthAnythingBackend:
    """Relative disparity from a local Depth Anything (V2) checkpoint directory."""

    name = "depth-anything-v2"

    def __init__(self, model_path: Path, device: str = "cpu") -> None:
        self.model_path = Path(model_path)
        self.model, self.processor, self.model_id = load_depth_anything(self.model_path, device)
        self.device = self.model.device
        source = imported_source(self.model_path)
        self.original = bool(source and source.get("pipeline") == "original")
        if self.original:
            use_original_positions(self.model)
        # The backbone only sees whole patches: whatever the processor config says, keep sides multiples of it.
        self._multiple = math.lcm(int(self.processor.ensure_multiple_of or 1), int(self.model.config.patch_size))

    def estimate(self, image: np.ndarray) -> np.ndarray:
        """Relative disparity (float32 HxW, larger = nearer) of RGB uint8 HxWx3 ``image``."""
        image = check_image(image)
        height, width = image.shape[:2]
        if self.original:
            return upsample(self.network_output(image), height, width)
        try:
            inputs = self.processor(images=image, return_tensors="pt", input_data_format="channels_last",
                                    ensure_multiple_of=self._multiple)
        except ValueError as exc:  # e.g. an aspect ratio so extreme that one side rounds to 0 patches
            raise DepthError(f"cannot prepare a {height}x{width} image for {self.model_id}: {exc}") from None
        with torch.inference_mode():
            outputs = self.model(pixel_values=inputs["pixel_values"].to(self.device))
            [result] = self.processor.post_process_depth_estimation(outputs, target_sizes=[(height, width)])
        return result["predicted_depth"].float().cpu().numpy().reshape(height, width)

    def network_output(self, image: np.ndarray) -> torch.Tensor:
        """The model's relative disparity (1xhxw, on the model's device) for RGB uint8 ``image`` prepared
        as the original code prepares it (:func:`original_input`)."""
        height, width = original_size(image.shape[0], image.shape[1], self._multiple)
        if max(height, width) > MAX_ORIGINAL_SIDE:
            raise DepthError(f"a {image.shape[0]}x{image.shape[1]} image would enter the network as {height}x{width}: "
                             f"an aspect ratio beyond {MAX_ORIGINAL_SIDE // ORIGINAL_SIZE}:1 is not supported")
        pixels = torch.from_numpy(original_input(image, self._multiple))[None].to(self.device)
        with torch.inference_mode():
            return self.model(pixel_values=pixels).predicted_depth


def original_size(height: int, width: int, multiple: int = 14, target: int = ORIGINAL_SIZE) -> tuple[int, int]:
    """(height, width) the original code resizes an image to: scaled keeping the aspect ratio so
    that both sides reach ``target``, each rounded to a multiple (half to even, as numpy rounds),
    or rounded up where rounding would fall below ``target``."""
    scale = max(target / height, target / width)

    def fit(side: float) -> int:
        rounded = int(np.round(side / multiple) * multiple)
        return rounded if rounded >= target else int(np.ceil(side / multiple) * multiple)

    return fit(scale * height), fit(scale * width)


def original_input(image: np.ndarray, multiple: int = 14) -> np.ndarray:
    """RGB uint8 HxWx3 → float32 3xhxw as the original pipeline feeds its network: the image in
    [0, 1] as float64, resized by OpenCV's bicubic (not PIL's, which filters when it shrinks), then
    normalised with ImageNet's mean and std."""
    height, width = original_size(image.shape[0], image.shape[1], multiple)
    resized = cv2.resize(image.astype(np.float64) / 255.0, (width, height), interpolation=cv2.INTER_CUBIC)
    normalised = (resized - np.array(IMAGENET_MEAN)) / np.array(IMAGENET_STD)
    return np.ascontiguousarray(normalised.transpose(2, 0, 1)).astype(np.float32)


def upsample(depth: torch.Tensor, height: int, width: int, *, align_corners: bool = True) -> np.ndarray:
    """The network's 1xhxw output resized to the image (float32 HxW): bilinear with corners aligned,
    as the original ``infer_image`` does (``transformers``' post-processing is bicubic)."""
    resized = F.interpolate(depth[:, None].float(), (height, width), mode="bilinear", align_corners=align_corners)
    return resized[0, 0].cpu().numpy().astype(np.float32)


def use_original_positions(model: Any) -> None:
    """Make the model's DINOv2 embeddings interpolate their position grid as the original DINOv2
    does: by a scale factor of (patches + 0.1) / grid, not to a target size. The sampling positions
    differ slightly, and the outputs with them."""
    embeddings = model.backbone.embeddings
    embeddings.interpolate_pos_encoding = types.MethodType(_original_positions, embeddings)


def _original_positions(self: Any, embeddings: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Position embeddings for a ``height`` x ``width`` px input (bound to a Dinov2Embeddings)."""
    positions = self.position_embeddings
    grid = positions.shape[1] - 1
    if embeddings.shape[1] - 1 == grid and height == width:
        return positions
    side = math.sqrt(grid)
    patch_height, patch_width = self.patch_embeddings.patch_size
    scale = ((height // patch_height + POSITION_OFFSET) / side, (width // patch_width + POSITION_OFFSET) / side)
    dim = positions.shape[-1]
    patch_positions = positions[:, 1:].float().reshape(1, int(side), int(side), dim).permute(0, 3, 1, 2)
    patch_positions = F.interpolate(patch_positions, scale_factor=scale, mode="bicubic", antialias=False)
    patch_positions = patch_positions.permute(0, 2, 3, 1).reshape(1, -1, dim).to(positions.dtype)
    return torch.cat((positions[:, :1], patch_positions), dim=1)



def load_depth_anything(model_path: Path, device: str = "cpu") -> tuple[Any, Any, str]:
    """(model in eval mode on ``device``, its PIL image processor, model id) from a local relative-depth
    Depth Anything checkpoint directory; ValueError (one line) naming the directory otherwise."""
    checkpoint = open_checkpoint(model_path, "Depth Anything", {"depth_anything"})
    model_path = checkpoint.path
    if checkpoint.config.get("depth_estimation_type", "relative") != "relative":
        raise ValueError(f"{model_path / CONFIG_FILE} is a metric-depth checkpoint; a relative (disparity) one is needed")
    try:
        torch_device = torch.device(device)
    except RuntimeError as exc:
        raise ValueError(f"bad torch device {device!r}: {exc}") from None
    try:
        model = AutoModelForDepthEstimation.from_pretrained(model_path).to(torch_device).eval()
        if (model_path / PROCESSOR_FILE).is_file():
            processor = AutoImageProcessor.from_pretrained(model_path, backend="pil")
        else:
            processor = DPTImageProcessorPil(**_RELEASED_PROCESSOR)
    except (OSError, ValueError) as exc:
        raise ValueError(f"cannot load Depth Anything from {model_path}: {exc}") from exc
    return model, processor, checkpoint.model_id(DepthAnythingBackend.name)
