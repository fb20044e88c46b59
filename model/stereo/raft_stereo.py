"""RAFT-Stereo's own network (Lipson et al., 3DV 2021) as a stereo branch: an image context encoder,
matching features from an encoder of their own or — shared backbone — from the context encoder's
trunk, 1–3 GRU levels fed by RAFT-Stereo's motion encoder, its 2-channel flow head and slow–fast
schedule. Module for module the layout of its published checkpoints (model/raft_import.py maps their
keys), so that an imported file predicts what RAFT-Stereo's demo does; corr, GRU cells, mask head
and convex upsampling are the fusion network's own.

Disparity is kept positive (left x matches right x − d) as everywhere here; RAFT-Stereo's flow is
its negative, with a y component that is always 0, and that is what its motion encoder reads and
its head writes: (−d, 0) in, −Δd out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Self

import torch
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.corr import CorrPyramid1D
from model.stereo.extractor import FeatureEncoder, Norm, ResidualBlock
from model.stereo.raft import StereoResult
from model.stereo.update import ConvGRU, MotionEncoder, pool2x, resize_like
from model.stereo.upsample import MaskHead, convex_upsample

# RAFT-Stereo's fixed widths: the motion encoder's stacks and output, the flow and mask heads' hidden layer.
MOTION_WIDTH, MOTION_CHANNELS, HEAD_WIDTH = 64, 128, 256
FLOW_CHANNELS = 2  # flow x (= −disparity) and y (always 0)


class ContextEncoder(nn.Module):
    """RAFT-Stereo's MultiBasicEncoder: a trunk laid out as the matching encoder (stem, three stages;
    ``context_norm``), one more stride-2 stage per coarser GRU level, and per level two heads, the
    initial hidden state and the context, each a residual block and a 3×3 convolution (at the third
    level the convolution alone)."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        norm: Norm = config.context_norm
        width, levels = config.encoder_dims[2], config.gru_levels
        self.trunk = FeatureEncoder(3, None, config.encoder_dims, config.encoder_blocks,
                                    n_downsample=config.n_downsample, stem_kernel=config.stem_kernel, norm=norm)
        self.down = nn.ModuleList([nn.Sequential(ResidualBlock(width, width, norm, stride=2),
                                                 ResidualBlock(width, width, norm)) for _ in range(levels - 1)])
        self.hidden = nn.ModuleList([_head(width, h, norm, level) for level, h in enumerate(config.hidden_dims[:levels])])
        self.context = nn.ModuleList([_head(width, h, norm, level) for level, h in enumerate(config.hidden_dims[:levels])])

    def forward(self, images: Tensor, batch: int) -> tuple[list[Tensor], list[Tensor], Tensor]:
        """(hidden-state features per level, context features per level — both of the first ``batch``
        images, finest level first — and the trunk's output for all images)."""
        trunk = self.trunk(images)
        x = trunk[:batch]
        hidden, context = [], []
        for level, (hidden_head, context_head) in enumerate(zip(self.hidden, self.context, strict=True)):
            if level:
                x = self.down[level - 1](x)
            hidden.append(hidden_head(x))
            context.append(context_head(x))
        return hidden, context, trunk


def _head(width: int, channels: int, norm: Norm, level: int) -> nn.Module:
    conv = nn.Conv2d(width, channels, 3, padding=1)
    return conv if level == 2 else nn.Sequential(ResidualBlock(width, width, norm), conv)


class RaftUpdate(nn.Module):
    """RAFT-Stereo's multi-level update: GRUs at 1/2**n … 1/2**(n+levels−1) (hidden sizes finest
    first), each fed its finer neighbour pooled and its coarser one resized; the finest reads the
    motion features and drives the flow head and the upsampling mask."""

    def __init__(self, hidden: Sequence[int], levels: int, corr_channels: int, factor: int) -> None:
        super().__init__()
        self.levels = levels
        self.motion = MotionEncoder(corr_channels, MOTION_WIDTH, MOTION_CHANNELS, FLOW_CHANNELS)
        inputs = [MOTION_CHANNELS, *hidden[: levels - 1]]  # level 0 reads motion, level k the pooled level k−1
        self.grus = nn.ModuleList([
            ConvGRU(hidden[level], inputs[level] + (hidden[level + 1] if level + 1 < levels else 0))
            for level in range(levels)])
        self.flow_head = nn.Sequential(nn.Conv2d(hidden[0], HEAD_WIDTH, 3, padding=1), nn.ReLU(inplace=True),
                                       nn.Conv2d(HEAD_WIDTH, FLOW_CHANNELS, 3, padding=1))
        self.mask = MaskHead(hidden[0], factor, HEAD_WIDTH)

    def refine(self, net: list[Tensor], context: Sequence[Sequence[Tensor]], finest: int,
               motion: Tensor | None = None) -> list[Tensor]:
        """The hidden states with levels ``levels−1`` … ``finest`` updated, coarse to fine (level 0
        needs ``motion``)."""
        net = list(net)
        for level in reversed(range(finest, self.levels)):
            inputs = [motion if level == 0 else pool2x(net[level - 1])]
            if level + 1 < self.levels:
                inputs.append(resize_like(net[level + 1], net[level]))
            net[level] = self.grus[level](net[level], context[level], *inputs)
        return net

    def forward(self, net: list[Tensor], context: Sequence[Sequence[Tensor]], corr: Tensor, flow: Tensor, *,
                with_mask: bool) -> tuple[list[Tensor], Tensor, Tensor | None]:
        """Every level updated; (hidden states, flow update B×2×h×w, mask logits or None)."""
        net = self.refine(net, context, 0, self.motion(corr, flow))
        return net, self.flow_head(net[0]), self.mask(net[0]) if with_mask else None


# One update of the loop (:func:`iterate`): (hidden states, the correlation sampled at the disparity, the
# disparity, with_mask) → (hidden states, the step subtracted from the disparity B×1×h×w, mask logits or None).
Update = Callable[[list[Tensor], Tensor, Tensor, bool], tuple[list[Tensor], Tensor, Tensor | None]]


def iterate(left: Tensor, right: Tensor, net: list[Tensor], update: Update, *, levels: int, radius: int, factor: int,
            border: str, iters: int, all_iterates: bool) -> StereoResult:
    """RAFT-Stereo's loop, as the networks built on it (Selective-RAFT) run it too: the correlation of the
    ``left``/``right`` matching features, built and sampled in float32 outside any autocast; from
    disparity 0, ``iters`` updates, each subtracting its step (the heads write −Δd), the mask asked for at
    the last (at every one with ``all_iterates``) and convex-upsampled (``factor``, ``border``) where given."""
    # As RAFT-Stereo: the correlation is built and sampled in float32, outside any autocast.
    with torch.autocast(left.device.type, enabled=False):
        corr = CorrPyramid1D(left.float(), right.float(), levels=levels, radius=radius)
    disparity = torch.zeros_like(left[:, :1], dtype=torch.float32)
    low, full = [], []
    mask = None
    for step in range(iters):
        disparity = disparity.detach()
        with torch.autocast(left.device.type, enabled=False):
            sampled = corr.lookup(disparity)
        net, delta, mask = update(net, sampled, disparity, all_iterates or step == iters - 1)
        disparity = disparity - delta.float()
        low.append(disparity)
        if mask is not None:
            full.append(convex_upsample(disparity, mask, factor, border))
    assert mask is not None
    return StereoResult(low, full, net[0], mask, left, corr)


class FrozenBatchNorm(nn.Module):
    """A module that trains as RAFT-Stereo (and Selective-RAFT's freeze_bn) does: its batch norm stays
    frozen (running statistics, eval mode)."""

    def train(self, mode: bool = True) -> Self:
        super().train(mode)
        for module in self.modules():
            if isinstance(module, nn.BatchNorm2d):
                module.eval()
        return self


class RaftStereoBranch(FrozenBatchNorm):
    """Left/right images normalised to [−1, 1] (B×3×H×W) → disparity iterates, as RAFT-Stereo."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.factor = 2**config.n_downsample
        self.levels, self.radius = config.corr_levels, config.corr_radius
        self.slow_fast, self.border = config.slow_fast_gru, config.upsample_border
        self.cnet = ContextEncoder(config)
        self.features: nn.Module | None = None
        self.match_head: nn.Module | None = None
        if config.shared_backbone:
            width = config.encoder_dims[2]
            self.match_head = nn.Sequential(ResidualBlock(width, width, "instance"),
                                            nn.Conv2d(width, config.feature_dim, 3, padding=1))
        else:
            self.features = FeatureEncoder(3, config.feature_dim, config.encoder_dims, config.encoder_blocks,
                                           n_downsample=config.n_downsample, stem_kernel=config.stem_kernel,
                                           norm="instance")
        hidden = config.hidden_dims[: config.gru_levels]
        self.zqr = nn.ModuleList([nn.Conv2d(h, 3 * h, 3, padding=1) for h in hidden])
        corr_channels = config.corr_levels * (2 * config.corr_radius + 1)
        self.update = RaftUpdate(hidden, config.gru_levels, corr_channels, self.factor)

    def forward(self, left: Tensor, right: Tensor, *, iters: int, all_iterates: bool) -> StereoResult:
        if iters < 1:
            raise ValueError(f"iters must be at least 1, got {iters}")
        batch = left.shape[0]
        both = torch.cat([left, right], dim=0)
        if self.match_head is not None:
            hidden, inputs, trunk = self.cnet(both, batch)
            features = self.match_head(trunk)
        else:
            hidden, inputs, _ = self.cnet(left, batch)
            assert self.features is not None
            features = self.features(both)
        left_features, right_features = features[:batch], features[batch:]
        context = [tuple(zqr(torch.relu(x)).chunk(3, dim=1)) for zqr, x in zip(self.zqr, inputs, strict=True)]

        def update(net: list[Tensor], sampled: Tensor, disparity: Tensor,
                   with_mask: bool) -> tuple[list[Tensor], Tensor, Tensor | None]:
            if self.slow_fast:
                for finest in range(self.update.levels - 1, 0, -1):
                    net = self.update.refine(net, context, finest)
            flow = torch.cat([-disparity, torch.zeros_like(disparity)], dim=1)
            net, delta, mask = self.update(net, context, sampled, flow, with_mask=with_mask)
            return net, delta[:, :1], mask

        return iterate(left_features, right_features, [torch.tanh(h) for h in hidden], update, levels=self.levels,
                       radius=self.radius, factor=self.factor, border=self.border, iters=iters,
                       all_iterates=all_iterates)
