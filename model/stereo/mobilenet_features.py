"""MobileNetV2 (width 1.0) as a feature pyramid, in pure torch, its parameters named as timm 0.5.4's
``mobilenetv2_100`` (``conv_stem``, ``bn1``, ``act1``, ``blocks.S.B.conv_pw`` …), so that checkpoints
holding timm's weights (Selective-IGEV's ``feature.*``) load without timm.

Each stage is what timm's ``blocks[S]`` is: a depthwise-separable block first (stage 0), then
inverted residuals (1×1 expansion, ReLU6, 3×3 depthwise, ReLU6, 1×1 linear projection, a skip
where stride 1 and the width stays). BatchNorm everywhere, eps 1e-5, as timm's defaults.
"""

from __future__ import annotations

from torch import Tensor, nn

# (expansion, output channels, blocks, first stride) per stage: MobileNetV2's table, timm's arch_def
# ds_r1_k3_s1_c16, ir_r2_k3_s2_e6_c24, ir_r3_k3_s2_e6_c32, ir_r4_k3_s2_e6_c64, ir_r3_k3_s1_e6_c96,
# ir_r3_k3_s2_e6_c160, ir_r1_k3_s1_e6_c320.
STAGES: tuple[tuple[int, int, int, int], ...] = (
    (1, 16, 1, 1), (6, 24, 2, 2), (6, 32, 3, 2), (6, 64, 4, 2), (6, 96, 3, 1), (6, 160, 3, 2), (6, 320, 1, 1))
STEM_CHANNELS = 32


class DepthwiseSeparableConv(nn.Module):
    """timm's DepthwiseSeparableConv as mobilenetv2 uses it: 3×3 depthwise, BN, ReLU6, 1×1, BN
    (no activation after the pointwise convolution: timm's ``pw_act`` off)."""

    def __init__(self, in_channels: int, out_channels: int, stride: int) -> None:
        super().__init__()
        self.conv_dw = nn.Conv2d(in_channels, in_channels, 3, stride, 1, groups=in_channels, bias=False)
        self.bn1 = nn.BatchNorm2d(in_channels)
        self.act1 = nn.ReLU6(inplace=True)
        self.conv_pw = nn.Conv2d(in_channels, out_channels, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.has_residual = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.bn2(self.conv_pw(self.act1(self.bn1(self.conv_dw(x)))))
        return x + y if self.has_residual else y


class InvertedResidual(nn.Module):
    """timm's InvertedResidual without squeeze-excitation: 1×1 to ``expansion``× channels, BN, ReLU6,
    3×3 depthwise (the stride), BN, ReLU6, 1×1 linear projection, BN; plus the input where the shape
    stays."""

    def __init__(self, in_channels: int, out_channels: int, stride: int, expansion: int) -> None:
        super().__init__()
        middle = in_channels * expansion
        self.conv_pw = nn.Conv2d(in_channels, middle, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(middle)
        self.act1 = nn.ReLU6(inplace=True)
        self.conv_dw = nn.Conv2d(middle, middle, 3, stride, 1, groups=middle, bias=False)
        self.bn2 = nn.BatchNorm2d(middle)
        self.act2 = nn.ReLU6(inplace=True)
        self.conv_pwl = nn.Conv2d(middle, out_channels, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(out_channels)
        self.has_residual = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.act1(self.bn1(self.conv_pw(x)))
        y = self.act2(self.bn2(self.conv_dw(y)))
        y = self.bn3(self.conv_pwl(y))
        return x + y if self.has_residual else y


def mobilenetv2_stages(count: int = len(STAGES)) -> list[nn.Sequential]:
    """The first ``count`` stages (timm's ``blocks[0:count]``); stage S's input is 1/2**… of the image
    as MobileNetV2's strides give: after stages 0–6, 1/2, 1/4, 1/8, 1/16, 1/16, 1/32, 1/32 (with the
    stride-2 stem)."""
    stages, channels = [], STEM_CHANNELS
    for index, (expansion, out_channels, blocks, stride) in enumerate(STAGES[:count]):
        layers: list[nn.Module] = []
        for block in range(blocks):
            block_stride = stride if block == 0 else 1
            if index == 0:
                layers.append(DepthwiseSeparableConv(channels, out_channels, block_stride))
            else:
                layers.append(InvertedResidual(channels, out_channels, block_stride, expansion))
            channels = out_channels
        stages.append(nn.Sequential(*layers))
    return stages


class MobileNetV2Stem(nn.Module):
    """timm's ``conv_stem``/``bn1``/``act1``: B×3×H×W → B×32×H/2×W/2 (3×3, stride 2, BN, ReLU6)."""

    def __init__(self) -> None:
        super().__init__()
        self.conv_stem = nn.Conv2d(3, STEM_CHANNELS, 3, 2, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(STEM_CHANNELS)
        self.act1 = nn.ReLU6(inplace=True)

    def forward(self, x: Tensor) -> Tensor:
        return self.act1(self.bn1(self.conv_stem(x)))
