"""The stereo branch: matching features of both views, the correlation pyramid, context from
the mono branch's features through learnable convolutions, and T GRU iterations refining the
disparity from zero; iterates are convex-upsampled to full resolution."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.corr import CorrPyramid1D
from model.stereo.extractor import FeatureEncoder, ResidualBlock
from model.stereo.update import MultiLevelUpdate
from model.stereo.upsample import convex_upsample


class ContextAdapter(nn.Module):
    """Mono features at the working resolution (B×C×h×w) → per GRU level the initial hidden
    state (tanh) and the gates' context terms (cz, cr, cq), at h, h/2, h/4."""

    def __init__(self, in_channels: int, hidden: tuple[int, int, int]) -> None:
        super().__init__()
        width = max(hidden)
        self.blocks = nn.ModuleList([ResidualBlock(in_channels, width, "group"),
                                     ResidualBlock(width, width, "group", stride=2),
                                     ResidualBlock(width, width, "group", stride=2)])
        self.heads = nn.ModuleList([nn.Conv2d(width, 2 * h, 3, padding=1) for h in hidden])
        self.zqr = nn.ModuleList([nn.Conv2d(h, 3 * h, 3, padding=1) for h in hidden])

    def forward(self, features: Tensor) -> tuple[list[Tensor], list[tuple[Tensor, ...]]]:
        nets, contexts = [], []
        x = features
        for block, head, zqr in zip(self.blocks, self.heads, self.zqr, strict=True):
            x = block(x)
            net, inp = head(x).chunk(2, dim=1)
            nets.append(torch.tanh(net))
            contexts.append(tuple(zqr(torch.relu(inp)).chunk(3, dim=1)))
        return nets, contexts


@dataclass
class StereoResult:
    iterates_low: list[Tensor]  # B×1×h×w pixels at the working resolution, one per iteration
    iterates: list[Tensor]  # B×1×H×W pixels, convex-upsampled (all, or only the last)
    hidden: Tensor  # the finest GRU hidden state after the last iteration, B×hidden0×h×w
    mask: Tensor  # its upsampling-mask logits
    left_features: Tensor  # B×feature_dim×h×w, the left view's matching features
    corr: CorrPyramid1D


class StereoBranch(nn.Module):
    """Left/right images normalised to [−1, 1] (B×3×H×W) and mono features → disparity iterates."""

    def __init__(self, config: ModelConfig, context_channels: int) -> None:
        super().__init__()
        self.factor = 2**config.n_downsample
        self.levels, self.radius = config.corr_levels, config.corr_radius
        self.border = config.upsample_border
        self.features = FeatureEncoder(3, config.feature_dim, config.encoder_dims, config.encoder_blocks,
                                       n_downsample=config.n_downsample, stem_kernel=config.stem_kernel,
                                       norm="instance")
        self.context = ContextAdapter(context_channels, config.hidden_dims)
        corr_channels = config.corr_levels * (2 * config.corr_radius + 1)
        self.update = MultiLevelUpdate(config.hidden_dims, corr_channels, config.motion_dim, self.factor)

    def forward(self, left: Tensor, right: Tensor, mono_features: Tensor, *, iters: int,
                all_iterates: bool) -> StereoResult:
        if iters < 1:
            raise ValueError(f"iters must be at least 1, got {iters}")
        batch = left.shape[0]
        features = self.features(torch.cat([left, right], dim=0))
        left_features, right_features = features[:batch], features[batch:]
        corr = CorrPyramid1D(left_features, right_features, levels=self.levels, radius=self.radius)
        net, context = self.context(mono_features)
        disparity = torch.zeros_like(left_features[:, :1])
        low, full = [], []
        for step in range(iters):
            # As RAFT: every iteration is supervised on its own, the lookup position is not differentiated.
            disparity = disparity.detach()
            last = step == iters - 1
            net, delta, mask = self.update(net, context, corr.lookup(disparity), disparity,
                                           with_mask=all_iterates or last)
            disparity = disparity + delta
            low.append(disparity)
            if mask is not None:
                full.append(convex_upsample(disparity, mask, self.factor, self.border))
        assert mask is not None
        return StereoResult(low, full, net[0], mask, left_features, corr)
