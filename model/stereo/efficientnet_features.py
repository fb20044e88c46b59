"""EfficientNetV2-L's first stages as a feature pyramid, in pure torch, its parameters named as timm
0.6.5's ``tf_efficientnetv2_l`` (``conv_stem``, ``bn1``, ``blocks.S.B.conv_exp`` …), so that checkpoints
holding timm's weights (MoCha-Stereo's ``feature.*``) load without timm.

The ``tf_`` port of the TensorFlow model: batch norms with eps 1e-3, SiLU, and TensorFlow's "same"
padding — a stride-2 convolution of an even side pads 0 before and 1 after (asymmetric), which no
symmetric ``padding=`` reproduces; stride-1 convolutions pad symmetrically, as timm does them. Stage
kinds: fused (``cn``: one 3×3 conv, BN, SiLU, skip), edge residual (``er``: 3×3 expansion, BN, SiLU,
1×1 projection, BN) and inverted residual with squeeze-excitation (``ir``: 1×1 expansion, 3×3
depthwise, SE, 1×1 projection), a skip where the stride is 1 and the width stays.
"""

from __future__ import annotations

import math

import torch.nn.functional as F
from torch import Tensor, nn

BN_EPS = 1e-3  # timm's BN_EPS_TF_DEFAULT for the tf_ models
STEM_CHANNELS = 32
# timm's arch_def for efficientnetv2_l: (kind, blocks, stride, expansion, output channels, SE ratio).
STAGES: tuple[tuple[str, int, int, int, int, float], ...] = (
    ("cn", 4, 1, 1, 32, 0.0), ("er", 7, 2, 4, 64, 0.0), ("er", 7, 2, 4, 96, 0.0), ("ir", 10, 2, 4, 192, 0.25),
    ("ir", 19, 1, 6, 224, 0.25), ("ir", 25, 2, 6, 384, 0.25), ("ir", 7, 1, 6, 640, 0.25))


class SameConv2d(nn.Conv2d):
    """nn.Conv2d with TensorFlow's "same" padding (timm's Conv2dSame where it is dynamic): per side
    ``max((⌈n/s⌉ − 1)·s + k − n, 0)`` zeros, the smaller half before. Stride 1 with odd kernels pads
    symmetrically, as timm's static padding does."""

    def __init__(self, in_channels: int, out_channels: int, kernel: int, stride: int = 1, groups: int = 1,
                 bias: bool = False) -> None:
        static = stride == 1
        super().__init__(in_channels, out_channels, kernel, stride, kernel // 2 if static else 0, groups=groups,
                         bias=bias)
        self.dynamic = not static

    def forward(self, x: Tensor) -> Tensor:
        if self.dynamic:
            pads = []
            for size, kernel, stride in zip(reversed(x.shape[-2:]), reversed(self.kernel_size),
                                            reversed(self.stride), strict=True):
                total = max((math.ceil(size / stride) - 1) * stride + kernel - size, 0)
                pads += [total // 2, total - total // 2]
            x = F.pad(x, pads)
        return super().forward(x)


class BatchNormAct(nn.BatchNorm2d):
    """timm's BatchNormAct2d: batch norm (eps 1e-3), then SiLU unless ``act`` is off."""

    def __init__(self, channels: int, act: bool = True) -> None:
        super().__init__(channels, eps=BN_EPS)
        self.act = act

    def forward(self, x: Tensor) -> Tensor:
        x = super().forward(x)
        return F.silu(x) if self.act else x


class SqueezeExcite(nn.Module):
    """Per-channel gates from the global mean: 1×1 reduce (bias), SiLU, 1×1 expand (bias), sigmoid."""

    def __init__(self, channels: int, reduced: int) -> None:
        super().__init__()
        self.conv_reduce = nn.Conv2d(channels, reduced, 1)
        self.conv_expand = nn.Conv2d(reduced, channels, 1)

    def forward(self, x: Tensor) -> Tensor:
        scale = self.conv_expand(F.silu(self.conv_reduce(x.mean((2, 3), keepdim=True))))
        return x * scale.sigmoid()


class ConvBnAct(nn.Module):
    """timm's ConvBnAct (``cn``): 3×3 conv, BN, SiLU, plus the input where the shape stays."""

    def __init__(self, in_channels: int, out_channels: int, stride: int) -> None:
        super().__init__()
        self.conv = SameConv2d(in_channels, out_channels, 3, stride)
        self.bn1 = BatchNormAct(out_channels)
        self.has_skip = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.bn1(self.conv(x))
        return x + y if self.has_skip else y


class EdgeResidual(nn.Module):
    """timm's EdgeResidual (``er``, FusedMBConv): 3×3 expansion (the stride), BN, SiLU, 1×1, BN."""

    def __init__(self, in_channels: int, out_channels: int, stride: int, expansion: int) -> None:
        super().__init__()
        middle = in_channels * expansion
        self.conv_exp = SameConv2d(in_channels, middle, 3, stride)
        self.bn1 = BatchNormAct(middle)
        self.conv_pwl = SameConv2d(middle, out_channels, 1)
        self.bn2 = BatchNormAct(out_channels, act=False)
        self.has_skip = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.bn2(self.conv_pwl(self.bn1(self.conv_exp(x))))
        return x + y if self.has_skip else y


class InvertedResidual(nn.Module):
    """timm's InvertedResidual (``ir``, MBConv): 1×1 expansion, BN, SiLU, 3×3 depthwise (the stride),
    BN, SiLU, squeeze-excitation (reduced to ``se_ratio``·input channels), 1×1, BN."""

    def __init__(self, in_channels: int, out_channels: int, stride: int, expansion: int, se_ratio: float) -> None:
        super().__init__()
        middle = in_channels * expansion
        self.conv_pw = SameConv2d(in_channels, middle, 1)
        self.bn1 = BatchNormAct(middle)
        self.conv_dw = SameConv2d(middle, middle, 3, stride, groups=middle)
        self.bn2 = BatchNormAct(middle)
        # timm divides the ratio by the expansion and applies it to the expanded width: in·ratio, rounded.
        self.se = SqueezeExcite(middle, round(in_channels * se_ratio))
        self.conv_pwl = SameConv2d(middle, out_channels, 1)
        self.bn3 = BatchNormAct(out_channels, act=False)
        self.has_skip = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.bn2(self.conv_dw(self.bn1(self.conv_pw(x))))
        y = self.bn3(self.conv_pwl(self.se(y)))
        return x + y if self.has_skip else y


def efficientnetv2_l_stages(count: int = len(STAGES)) -> list[nn.Sequential]:
    """The first ``count`` stages (timm's ``blocks[0:count]``); after stages 0–6 the features are at
    1/2, 1/4, 1/8, 1/16, 1/16, 1/32, 1/32 of the image (with the stride-2 stem), 32, 64, 96, 192, 224,
    384, 640 channels."""
    stages, channels = [], STEM_CHANNELS
    for kind, blocks, stride, expansion, out_channels, se_ratio in STAGES[:count]:
        layers: list[nn.Module] = []
        for block in range(blocks):
            block_stride = stride if block == 0 else 1
            if kind == "cn":
                layers.append(ConvBnAct(channels, out_channels, block_stride))
            elif kind == "er":
                layers.append(EdgeResidual(channels, out_channels, block_stride, expansion))
            else:
                layers.append(InvertedResidual(channels, out_channels, block_stride, expansion, se_ratio))
            channels = out_channels
        stages.append(nn.Sequential(*layers))
    return stages


def efficientnetv2_l_stem() -> tuple[SameConv2d, BatchNormAct]:
    """timm's ``conv_stem`` (3×3, stride 2, "same") and ``bn1`` (BN + SiLU): B×3×H×W → B×32×H/2×W/2."""
    return SameConv2d(3, STEM_CHANNELS, 3, 2), BatchNormAct(STEM_CHANNELS)
