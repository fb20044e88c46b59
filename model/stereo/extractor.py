"""Convolutional encoders: residual blocks in stages, a stem then two strided stages, giving
features at 1/2**n_downsample of the input (n_downsample 2 or 3)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

Norm = str  # "instance" | "group" | "batch" | "none"


def norm_layer(kind: Norm, channels: int) -> nn.Module:
    """A normalisation of ``channels``: instance (matching features, as RAFT-Stereo's fnet),
    group (context: keeps absolute levels and works at batch size 1), batch (RAFT-Stereo's
    published context encoders, frozen in training) or none."""
    if kind == "batch":
        return nn.BatchNorm2d(channels)
    if kind == "instance":
        return nn.InstanceNorm2d(channels)
    if kind == "group":
        return nn.GroupNorm(max(1, channels // 8), channels)
    if kind == "none":
        return nn.Identity()
    raise ValueError(f"unknown norm {kind!r}")


class ResidualBlock(nn.Module):
    """Two 3×3 convolutions with a skip (a strided 1×1 projection when the shape changes)."""

    def __init__(self, in_channels: int, channels: int, norm: Norm, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, channels, 3, stride=stride, padding=1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)
        self.norm1, self.norm2 = norm_layer(norm, channels), norm_layer(norm, channels)
        self.skip: nn.Module = nn.Identity()
        if stride != 1 or in_channels != channels:
            self.skip = nn.Sequential(nn.Conv2d(in_channels, channels, 1, stride=stride), norm_layer(norm, channels))

    def forward(self, x: Tensor) -> Tensor:
        y = torch.relu(self.norm1(self.conv1(x)))
        y = torch.relu(self.norm2(self.conv2(y)))
        return torch.relu(self.skip(x) + y)


class FeatureEncoder(nn.Module):
    """B×in×H×W → B×out×H/2**n×W/2**n. The stem is strided when n_downsample is 3 (as RAFT-Stereo),
    then ``blocks[0]`` blocks at the stem's resolution and two stages of ``blocks[1]``, ``blocks[2]``
    blocks, each opening with a stride-2 block; a 1×1 convolution to ``out_channels`` ends it, or
    nothing (``out_channels`` None: the trunk of RAFT-Stereo's context encoder, B×dims[2]×…)."""

    def __init__(self, in_channels: int, out_channels: int | None, dims: Sequence[int], blocks: Sequence[int], *,
                 n_downsample: int, stem_kernel: int, norm: Norm) -> None:
        super().__init__()
        stem_stride = 2 if n_downsample == 3 else 1
        self.stem = nn.Sequential(
            nn.Conv2d(in_channels, dims[0], stem_kernel, stride=stem_stride, padding=stem_kernel // 2),
            norm_layer(norm, dims[0]), nn.ReLU(inplace=True))
        layers: list[nn.Module] = [ResidualBlock(dims[0], dims[0], norm) for _ in range(blocks[0])]
        for previous, dim, count in ((dims[0], dims[1], blocks[1]), (dims[1], dims[2], blocks[2])):
            layers.append(ResidualBlock(previous, dim, norm, stride=2))
            layers.extend(ResidualBlock(dim, dim, norm) for _ in range(count - 1))
        self.layers = nn.Sequential(*layers)
        self.out = nn.Conv2d(dims[2], out_channels, 1) if out_channels is not None else nn.Identity()
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out", nonlinearity="relu")

    def forward(self, x: Tensor) -> Tensor:
        return self.out(self.layers(self.stem(x)))
