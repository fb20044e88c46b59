"""Selective-RAFT (Wang et al., "Selective-Stereo", CVPR 2024; Windsrain/Selective-Stereo) as a
stereo-only network: RAFT-Stereo's encoders and correlation, with each GRU level a *selective* GRU —
a 1×1 and a 3×3 ConvGRU mixed per pixel by a spatial attention map of the context — and the context
reweighted by a channel attention before it is fed to the GRUs as an input (no ``zqr`` gate terms).
Module for module the layout of its published checkpoints (model/selective_raft_import.py maps their
keys), so that an imported file predicts what its demo does.

Disparity is kept positive (left x matches right x − d) as everywhere here; Selective-RAFT's is its
negative (one channel, what its motion encoder reads), and its head writes −Δd.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.extractor import FeatureEncoder
from model.stereo.raft import StereoResult
from model.stereo.raft_stereo import (
    HEAD_WIDTH,
    MOTION_CHANNELS,
    MOTION_WIDTH,
    ContextEncoder,
    FrozenBatchNorm,
    iterate,
)
from model.stereo.update import ConvGRU, MotionEncoder, pool2x, resize_like
from model.stereo.upsample import MaskHead

# Selective-RAFT's fixed sizes: its GRUs' two kernels, the channel attention's reduction (in//16) and
# the spatial attention's kernel.
SMALL_KERNEL, LARGE_KERNEL, CAM_REDUCTION, SAM_KERNEL = 1, 3, 16, 7


class ChannelAttention(nn.Module):
    """Selective-RAFT's ChannelAttentionEnhancement: B×C×h×w → B×C×1×1 weights in (0, 1), one shared
    MLP (bias-free 1×1 convolutions) on the global average and the global maximum, summed."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.fc = nn.Sequential(nn.Conv2d(channels, channels // CAM_REDUCTION, 1, bias=False), nn.ReLU(),
                                nn.Conv2d(channels // CAM_REDUCTION, channels, 1, bias=False))

    def forward(self, x: Tensor) -> Tensor:
        return torch.sigmoid(self.fc(x.mean(dim=(2, 3), keepdim=True)) + self.fc(x.amax(dim=(2, 3), keepdim=True)))


class SpatialAttention(nn.Module):
    """Selective-RAFT's SpatialAttentionExtractor: B×C×h×w → B×1×h×w in (0, 1), a 7×7 convolution of
    the channel mean and maximum: how much each pixel takes the small-kernel GRU's state."""

    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Conv2d(2, 1, SAM_KERNEL, padding=SAM_KERNEL // 2, bias=False)

    def forward(self, x: Tensor) -> Tensor:
        return torch.sigmoid(self.conv(torch.cat([x.mean(dim=1, keepdim=True), x.amax(dim=1, keepdim=True)], dim=1)))


class SelectiveGRU(nn.Module):
    """Two plain ConvGRUs of one hidden state, 1×1 (``small``) and 3×3 (``large``), blended per pixel:
    ``attention``·small + (1 − ``attention``)·large."""

    def __init__(self, hidden: int, inputs: int) -> None:
        super().__init__()
        self.small = ConvGRU(hidden, inputs, SMALL_KERNEL)
        self.large = ConvGRU(hidden, inputs, LARGE_KERNEL)

    def forward(self, attention: Tensor, h: Tensor, *x: Tensor) -> Tensor:
        return self.small(h, None, *x) * attention + self.large(h, None, *x) * (1 - attention)


class SelectiveUpdate(nn.Module):
    """Selective-RAFT's BasicSelectiveMultiUpdateBlock: GRU levels 1/2**n … (finest first), each reading
    its context, its finer neighbour pooled and its coarser one resized; the finest reads the motion
    features and drives the 1-channel disparity head and the upsampling mask."""

    def __init__(self, hidden: int, levels: int, corr_channels: int, factor: int) -> None:
        super().__init__()
        self.levels = levels
        self.motion = MotionEncoder(corr_channels, MOTION_WIDTH, MOTION_CHANNELS, flow_channels=1)
        # level 0: context, motion, coarser; level k: context, finer pooled, coarser (none at the last)
        inputs = [hidden + MOTION_CHANNELS] + [2 * hidden] * (levels - 1)
        self.grus = nn.ModuleList([SelectiveGRU(hidden, inputs[level] + (hidden if level + 1 < levels else 0))
                                   for level in range(levels)])
        self.disp_head = nn.Sequential(nn.Conv2d(hidden, HEAD_WIDTH, 3, padding=1), nn.ReLU(inplace=True),
                                       nn.Conv2d(HEAD_WIDTH, 1, 3, padding=1))
        self.mask = MaskHead(hidden, factor, HEAD_WIDTH)

    def forward(self, net: list[Tensor], context: Sequence[Tensor], attention: Sequence[Tensor], corr: Tensor,
                disp: Tensor, *, with_mask: bool) -> tuple[list[Tensor], Tensor, Tensor | None]:
        """Every level updated coarse to fine; ``disp``: Selective-RAFT's disparity (−d, B×1×h×w).
        (hidden states, its update B×1×h×w, mask logits or None)."""
        net = list(net)
        for level in reversed(range(self.levels)):
            inputs = [context[level], self.motion(corr, disp) if level == 0 else pool2x(net[level - 1])]
            if level + 1 < self.levels:
                inputs.append(resize_like(net[level + 1], net[level]))
            net[level] = self.grus[level](attention[level], net[level], *inputs)
        return net, self.disp_head(net[0]), self.mask(net[0]) if with_mask else None


class SelectiveRaftBranch(FrozenBatchNorm):
    # As Selective-RAFT trains (its freeze_bn): batch norm stays frozen (running statistics).
    """Left/right images normalised to [−1, 1] (B×3×H×W) → disparity iterates, as Selective-RAFT."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        if config.gru_levels < 2:  # its update block never runs the finest GRU with one level
            raise ValueError("Selective-RAFT needs 2 or 3 GRU levels")
        self.factor = 2**config.n_downsample
        self.levels, self.radius, self.border = config.corr_levels, config.corr_radius, config.upsample_border
        self.cnet = ContextEncoder(config)
        self.features = FeatureEncoder(3, config.feature_dim, config.encoder_dims, config.encoder_blocks,
                                       n_downsample=config.n_downsample, stem_kernel=config.stem_kernel,
                                       norm="instance")
        hidden = config.hidden_dims[0]
        self.cam = ChannelAttention(hidden)  # one for every level, as Selective-RAFT
        self.sam = SpatialAttention()
        corr_channels = config.corr_levels * (2 * config.corr_radius + 1)
        self.update = SelectiveUpdate(hidden, config.gru_levels, corr_channels, self.factor)

    def forward(self, left: Tensor, right: Tensor, *, iters: int, all_iterates: bool) -> StereoResult:
        if iters < 1:
            raise ValueError(f"iters must be at least 1, got {iters}")
        batch = left.shape[0]
        hidden, inputs, _ = self.cnet(left, batch)
        features = self.features(torch.cat([left, right], dim=0))
        left_features, right_features = features[:batch], features[batch:]
        context = [torch.relu(x) for x in inputs]
        context = [self.cam(x) * x for x in context]
        attention = [self.sam(x) for x in context]

        def update(net: list[Tensor], sampled: Tensor, disparity: Tensor,
                   with_mask: bool) -> tuple[list[Tensor], Tensor, Tensor | None]:
            return self.update(net, context, attention, sampled, -disparity, with_mask=with_mask)

        # As Selective-RAFT: RAFT-Stereo's loop, the correlation in float32.
        return iterate(left_features, right_features, [torch.tanh(h) for h in hidden], update, levels=self.levels,
                       radius=self.radius, factor=self.factor, border=self.border, iters=iters,
                       all_iterates=all_iterates)
