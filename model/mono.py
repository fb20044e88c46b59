"""The mono branch: relative (affine-invariant) disparity of the left view, and features for
the stereo branch's context.

Backends: ``precomputed`` — the disparity is given (a sample's stored mono disparity or a
``--mono`` file) and a small learnable encoder over [left image, mono disparity] makes the
features; ``depth-anything-v2`` — frozen Depth Anything V2 from a local directory (loaded by
:func:`annotation.depth.depth_anything.load_depth_anything`, the loader the annotation backend
uses), its features the DPT head's last feature map (the input of ``head.conv2``: fusion/2
channels at the model's input resolution) resized to the working resolution, as the authors do.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.extractor import FeatureEncoder


@dataclass
class MonoResult:
    disparity: Tensor  # B×1×H×W relative disparity (larger = nearer), as given or estimated
    features: Tensor  # B×C×h×w at the stereo working resolution (1/2**n_downsample)


def normalize_mono(mono: Tensor) -> Tensor:
    """B×1×H×W relative disparity → per image min–max normalised to [0, 1] (its affine
    ambiguity removed up to sign; values are otherwise kept)."""
    flat = mono.flatten(1)
    lo = flat.min(dim=1).values.view(-1, 1, 1, 1)
    hi = flat.max(dim=1).values.view(-1, 1, 1, 1)
    return (mono - lo) / (hi - lo).clamp_min(1e-6)


class PrecomputedMono(nn.Module):
    """Mono disparity given as input; features from a learnable (weight-free) encoder."""

    frozen = False

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.feature_channels = config.mono_feature_dim
        self.encoder = FeatureEncoder(4, config.mono_feature_dim, config.encoder_dims, config.encoder_blocks,
                                      n_downsample=config.n_downsample, stem_kernel=config.stem_kernel,
                                      norm="group")

    def forward(self, left: Tensor, mono: Tensor | None) -> MonoResult:
        """``left`` B×3×H×W in [−1, 1]; ``mono`` B×1×H×W relative disparity (required)."""
        if mono is None:
            raise ValueError("mono backend 'precomputed' needs mono: pass a mono disparity (e.g. --mono)")
        return MonoResult(mono, self.encoder(torch.cat([left, 2 * normalize_mono(mono) - 1], dim=1)))


class DepthAnythingMono(nn.Module):
    """Frozen Depth Anything V2 (``backbone``): estimates the disparity unless one is given, and
    always gives its DPT features."""

    frozen = True

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        from annotation.depth.depth_anything import load_depth_anything, use_original_positions
        from annotation.depth.depth_anything_import import imported_source

        if not config.mono_model_path:
            raise ValueError("mono backend 'depth-anything-v2' needs model.mono_model_path (a local checkpoint dir)")
        path = Path(config.mono_model_path)
        if not path.is_dir():
            raise ValueError(f"model.mono_model_path {path} is not a directory")
        self.backbone, processor, self.model_id = load_depth_anything(path, "cpu")
        self.backbone.requires_grad_(False)
        # Weights converted from an original .pth learnt DINOv2's own position-grid interpolation: keep it
        # (a property of the network). The image still enters as below, batched on the device
        # (docs/depth-anything.md, "Serving generation and the paper preset").
        source = imported_source(path)
        self.original_positions = bool(source and source.get("pipeline") == "original")
        if self.original_positions:
            use_original_positions(self.backbone)
        self.model_path = path
        self.factor = 2**config.n_downsample
        self.patch = int(self.backbone.config.patch_size)
        self.input_size = config.mono_input_size
        self.feature_channels = int(self.backbone.config.fusion_hidden_size) // 2
        self.register_buffer("mean", torch.tensor(processor.image_mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(processor.image_std).view(1, 3, 1, 1), persistent=False)

    def train(self, mode: bool = True) -> DepthAnythingMono:
        super().train(mode)
        self.backbone.eval()  # frozen: its norms and dropouts stay in inference mode
        return self

    def input_shape(self, height: int, width: int) -> tuple[int, int]:
        """Long side → ``input_size``, aspect kept, both sides multiples of the patch."""
        scale = self.input_size / max(height, width)
        return (max(1, round(height * scale / self.patch)) * self.patch,
                max(1, round(width * scale / self.patch)) * self.patch)

    def forward(self, left: Tensor, mono: Tensor | None) -> MonoResult:
        height, width = left.shape[2:]
        pixels = F.interpolate((left + 1) / 2, self.input_shape(height, width), mode="bicubic", align_corners=False)
        pixels = ((pixels.clamp(0, 1) - self.mean) / self.std).to(next(self.backbone.parameters()).dtype)
        captured: list[Tensor] = []
        hook = self.backbone.head.conv2.register_forward_pre_hook(lambda _m, args: captured.append(args[0]))
        try:
            with torch.no_grad():
                estimate = self.backbone(pixel_values=pixels).predicted_depth.unsqueeze(1).float()
        finally:
            hook.remove()
        size = (height // self.factor, width // self.factor)
        features = F.interpolate(captured[0].float(), size, mode="bilinear", align_corners=False)
        if mono is None:
            mono = F.interpolate(estimate, (height, width), mode="bilinear", align_corners=False)
        return MonoResult(mono, features)

    def state_hash(self) -> str:
        """sha256 over the backbone's tensors (names, shapes, bytes)."""
        return tensor_hash(self.backbone.state_dict())


def tensor_hash(state: dict[str, Tensor]) -> str:
    """Content hash of a state dict (sorted names, dtypes, shapes and bytes)."""
    digest = hashlib.sha256()
    for name in sorted(state):
        tensor = state[name].detach().cpu().contiguous()
        digest.update(f"{name}:{tensor.dtype}:{tuple(tensor.shape)}".encode())
        # reshape: a 0-dim tensor (a batch norm's num_batches_tracked) cannot be viewed as bytes as it is
        digest.update(tensor.reshape(-1).view(torch.uint8).numpy().tobytes() if tensor.numel() else b"")
    return digest.hexdigest()


def make_mono(config: ModelConfig) -> PrecomputedMono | DepthAnythingMono:
    """The mono backend named by ``config.mono_backend``."""
    if config.mono_backend == "depth-anything-v2":
        return DepthAnythingMono(config)
    return PrecomputedMono(config)


__all__ = ["DepthAnythingMono", "MonoResult", "PrecomputedMono", "make_mono", "normalize_mono", "tensor_hash"]
