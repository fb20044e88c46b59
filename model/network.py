"""The VLM-driven monocular–stereo fusion network (paper section 4), wiring the branches as
RAFT-Stereo's ``raft_stereo.py`` does: mono branch → context → stereo GRU iterations → VLM
embeddings → flow confidence → global fusion. With ``model.architecture = "raft-stereo"`` (or
another of :data:`BASELINE_BRANCHES`) the same class is that paper's own stereo-only network
(model/stereo/raft_stereo.py, selective_raft.py, selective_igev.py, mocha_stereo.py), so training, checkpoints,
prediction and evaluation treat them alike."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.confidence import ConfidenceHead
from model.fusion import GlobalFusion, least_squares_affine
from model.mono import make_mono, normalize_mono
from model.presets import ModelConfig
from model.stereo.mocha_stereo import MochaBranch
from model.stereo.raft import StereoBranch, StereoResult
from model.stereo.raft_stereo import RaftStereoBranch
from model.stereo.selective_igev import SelectiveIgevBranch
from model.stereo.selective_raft import SelectiveRaftBranch
from model.vlm import make_vlm

# Parameters under these prefixes are frozen backbones: never trained, never stored in checkpoints
# (their LoRA adapters, named "lora_", are).
FROZEN_PREFIXES = ("mono.backbone.", "vlm.backbone.")
# The trunk a fusion network is pre-trained as (``bench pretrain``): its mono context encoder and stereo
# branch, what ``train.freeze_trunk`` holds fixed while the heads on top of it learn.
TRUNK_PREFIXES = ("mono.", "stereo_branch.")
# The stereo-only networks by model.architecture: images normalised to [−1, 1] → StereoResult.
BASELINE_BRANCHES: dict[str, type[nn.Module]] = {"raft-stereo": RaftStereoBranch,
                                                 "selective-raft": SelectiveRaftBranch,
                                                 "selective-igev": SelectiveIgevBranch,
                                                 "mocha-stereo": MochaBranch}


@dataclass
class FusionOutput:
    disparity: Tensor  # B×1×H×W, pixels, final fused disparity, full resolution
    stereo_iterates: list[Tensor]  # T tensors B×1×H×W, pixels (in eval mode by default only the last)
    stereo: Tensor  # B×1×H×W, the last iterate
    mono_aligned: Tensor  # B×1×H×W, pixels: s_m·D_m + t_m, upsampled to full resolution
    confidence: Tensor  # B×1×h×w in (0, 1) at the stereo working resolution
    confidence_logits: Tensor  # same shape, pre-sigmoid
    mono: Tensor  # B×1×H×W, the relative mono disparity used (given or estimated; zeros for RAFT-Stereo)
    # A stereo-only network's (model.use_mono off): disparity is the stereo branch's, fully trusted
    # (confidence 1, logits +inf), no aligned mono (zeros); the loss is the iterates' alone.
    stereo_only: bool = False
    # B×1×H×W pixels: the mono fitted to the stereo by one least-squares scale and shift per image (None
    # for a stereo-only network): what the mono is worth where the gate takes it without a local fit.
    mono_fitted: Tensor | None = None


class FusionNetwork(nn.Module):
    """Left/right RGB (float32 B×3×H×W in [0, 255], H and W multiples of ``size_multiple``) and an
    optional relative mono disparity → :class:`FusionOutput`."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        self.factor = 2**config.n_downsample
        # A baseline's context comes from an image encoder of its own: no mono branch at all.
        self.mono = make_mono(config) if config.architecture == "fusion" else None
        self.stereo_branch: nn.Module = (
            StereoBranch(config, self.mono.feature_channels) if self.mono is not None
            else BASELINE_BRANCHES[config.architecture](config))
        self.vlm = make_vlm(config) if config.use_vlm else None
        condition_dim = self.vlm.dim if self.vlm is not None else 0
        # Built only where they are used: DDP requires every parameter to get a gradient.
        self.confidence = ConfidenceHead(config, condition_dim) if config.use_mono else None
        self.fusion = GlobalFusion(config, config.hidden_dims[0]) if config.use_mono else None
        self.size_multiple = config.size_multiple
        self._hashes: dict[str, str] | None = None

    def forward(self, left: Tensor, right: Tensor, mono: Tensor | None = None, *, iters: int,
                noise: torch.Generator | Sequence[torch.Generator] | None = None,
                all_iterates: bool | None = None) -> FusionOutput:
        """``iters`` GRU iterations; ``noise``: generator(s) for the flow's Gaussian noise (one for
        the batch or one per sample); ``all_iterates``: upsample every iterate (default: in
        training mode only; in eval mode ``stereo_iterates`` holds the last one)."""
        self._check(left, right, mono)
        all_iterates = self.training if all_iterates is None else all_iterates
        left_n, right_n = 2 * (left / 255.0) - 1, 2 * (right / 255.0) - 1
        if self.mono is None:
            stereo = self.stereo_branch(left_n, right_n, iters=iters, all_iterates=all_iterates)
            return _stereo_only(stereo, torch.zeros_like(left[:, :1]))
        # Stereo only: the context encoder sees the left image beside a constant, never the mono input.
        mono_result = self.mono(left_n, mono if self.config.use_mono else torch.zeros_like(left[:, :1]))
        mono_full = normalize_mono(mono_result.disparity)
        mono_low = F.avg_pool2d(mono_full, self.factor)
        assert isinstance(self.stereo_branch, StereoBranch)
        stereo = self.stereo_branch(left_n, right_n, mono_result.features, iters=iters, all_iterates=all_iterates)
        if self.confidence is None or self.fusion is None:
            return _stereo_only(stereo, mono_result.disparity)
        disparity_low = stereo.iterates_low[-1]
        cost = stereo.corr.lookup(disparity_low.detach())
        s0, t0 = least_squares_affine(mono_low, disparity_low.detach())
        disparities = (disparity_low, s0 * mono_low + t0)
        vlm = self.vlm(left_n, stereo.iterates[-1], mono_result.disparity) if self.vlm is not None else None
        logits = self.confidence(cost, vlm=vlm, features=stereo.left_features, noise=noise, disparities=disparities)
        confidence = torch.sigmoid(logits)
        fused = self.fusion(mono_low, disparity_low, confidence, stereo.hidden, stereo.mask)
        size = left.shape[2:]
        scale = F.interpolate(fused.scale, size, mode="bilinear", align_corners=False)
        shift = F.interpolate(fused.shift, size, mode="bilinear", align_corners=False)
        aligned = self.factor * (scale * mono_full + shift)
        return FusionOutput(fused.disparity, stereo.iterates, stereo.iterates[-1], aligned, confidence, logits,
                            mono_result.disparity, mono_fitted=self.factor * (s0 * mono_full + t0))

    def _check(self, left: Tensor, right: Tensor, mono: Tensor | None) -> None:
        if left.ndim != 4 or left.shape[1] != 3 or left.shape != right.shape:
            raise ValueError(f"left and right must both be B×3×H×W, got {tuple(left.shape)} and {tuple(right.shape)}")
        height, width = left.shape[2:]
        if height % self.size_multiple or width % self.size_multiple:
            raise ValueError(f"image sides must be multiples of {self.size_multiple}, got {height}×{width}")
        if mono is not None and tuple(mono.shape) != (left.shape[0], 1, height, width):
            raise ValueError(f"mono must be B×1×H×W = {(left.shape[0], 1, height, width)}, got {tuple(mono.shape)}")

    def train(self, mode: bool = True) -> FusionNetwork:
        super().train(mode)
        return self  # frozen backbones keep themselves in eval mode (their modules' train())

    def frozen_modules(self) -> dict[str, nn.Module]:
        """The frozen backbones by name ("mono", "vlm"); empty for weight-free backends."""
        modules: dict[str, nn.Module] = {}
        if getattr(self.mono, "frozen", False):
            modules["mono"] = self.mono
        if self.vlm is not None and getattr(self.vlm, "frozen", False):
            modules["vlm"] = self.vlm
        return modules

    def frozen_state_hashes(self) -> dict[str, str]:
        """sha256 content hashes of the frozen backbones' released weights, by name (may be {})."""
        if self._hashes is None:
            self._hashes = {name: module.state_hash() for name, module in self.frozen_modules().items()}  # type: ignore[operator]
        return dict(self._hashes)

    def frozen_paths(self) -> dict[str, str]:
        """The local directories the frozen backbones were loaded from, by name."""
        return {name: str(module.model_path) for name, module in self.frozen_modules().items()}

    def trainable_state_dict(self) -> dict[str, Tensor]:
        """Everything but the frozen backbones (LoRA adapters included), detached."""
        return {name: tensor.detach() for name, tensor in self.state_dict().items() if not _is_frozen(name)}

    def load_trainable_state_dict(self, state: dict[str, Tensor]) -> None:
        """Loads what :meth:`trainable_state_dict` gave; ValueError naming missing or unknown keys."""
        expected = set(self.trainable_state_dict())
        missing, unknown = expected - set(state), set(state) - expected
        if missing or unknown:
            raise ValueError("checkpoint weights do not fit this network: "
                             f"missing {sorted(missing)[:5]}, unknown {sorted(unknown)[:5]}")
        self.load_state_dict(state, strict=False)

    def freeze_trunk(self) -> None:
        """Hold the trunk (TRUNK_PREFIXES) fixed: its parameters stop requiring gradients."""
        for name, parameter in self.named_parameters():
            if name.startswith(TRUNK_PREFIXES):
                parameter.requires_grad_(False)

    def trainable_parameters(self) -> list[nn.Parameter]:
        """Parameters the optimiser updates (frozen backbones excluded, their LoRA adapters included)."""
        return [p for p in self.parameters() if p.requires_grad]


def _stereo_only(stereo: StereoResult, mono: Tensor) -> FusionOutput:
    """A stereo-only network's output: its last iterate, fully trusted, no aligned mono."""
    last, low = stereo.iterates[-1], stereo.iterates_low[-1]
    return FusionOutput(last, stereo.iterates, last, torch.zeros_like(last), torch.ones_like(low),
                        torch.full_like(low, torch.inf), mono, stereo_only=True)


def _is_frozen(name: str) -> bool:
    return name.startswith(FROZEN_PREFIXES) and "lora_" not in name
