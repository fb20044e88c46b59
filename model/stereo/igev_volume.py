"""IGEV-Stereo's cost-volume parts (Xu et al., CVPR 2023), as Selective-IGEV uses them: conv–norm–leaky
ReLU units, the group-wise correlation volume at 1/4, its 3D hourglass guided by image features, the
soft-argmin initial disparity, the "combined geometry encoding" sampled around the current disparity,
and the 3×3 context upsampling. Module and parameter names are IGEV's (``conv``, ``bn``, ``feat_att``,
``conv1_up`` …), so its checkpoints load key for key.

Disparities are positive pixels (left x matches right x − d), as IGEV's and everywhere here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.stereo.corr import CorrPyramid1D

GROUPS = 8  # group-wise correlation groups (the volume's channels)


@dataclass(frozen=True)
class VolumeConfig:
    """The IGEV family's reference argparse options that shape the volume and its lookup: ``corr_levels``,
    ``corr_radius``, ``max_disp`` (pixels at full resolution, a multiple of 32: the cost volume spans
    max_disp/4 disparities at 1/4)."""

    corr_levels: int = 2
    corr_radius: int = 4
    max_disp: int = 192

    def __post_init__(self) -> None:
        if self.max_disp <= 0 or self.max_disp % 32:
            raise ValueError(f"max_disp must be a positive multiple of 32, got {self.max_disp}")
        if self.corr_levels < 1 or self.corr_radius < 0:
            raise ValueError(f"corr_levels ≥ 1 and corr_radius ≥ 0, got {self.corr_levels}, {self.corr_radius}")

    @property
    def corr_planes(self) -> int:
        """Channels the motion encoder reads: per level (GROUPS volume channels + 1 correlation) × samples."""
        return self.corr_levels * (GROUPS + 1) * (2 * self.corr_radius + 1)


class BasicConv(nn.Module):
    """Convolution (2D or 3D, transposed if ``deconv``; no bias), BatchNorm, LeakyReLU(0.01) (ReLU where
    ``leaky`` is off: MoCha-Stereo's refinement). The norm exists even when ``bn`` is off (IGEV's
    checkpoints hold its tensors), unused."""

    def __init__(self, in_channels: int, out_channels: int, *, deconv: bool = False, is_3d: bool = False,
                 bn: bool = True, relu: bool = True, kernel_size: int | tuple[int, ...] = 3,
                 stride: int | tuple[int, ...] = 1, padding: int | tuple[int, ...] = 0, dilation: int = 1,
                 leaky: bool = True) -> None:
        super().__init__()
        self.use_bn, self.relu, self.leaky = bn, relu, leaky
        conv: type[nn.Module]
        if is_3d:
            conv = nn.ConvTranspose3d if deconv else nn.Conv3d
        else:
            conv = nn.ConvTranspose2d if deconv else nn.Conv2d
        self.conv = conv(in_channels, out_channels, kernel_size, stride=stride, padding=padding, dilation=dilation,
                         bias=False)
        self.bn = nn.BatchNorm3d(out_channels) if is_3d else nn.BatchNorm2d(out_channels)

    def forward(self, x: Tensor) -> Tensor:
        x = self.conv(x)
        if self.use_bn:
            x = self.bn(x)
        if not self.relu:
            return x
        return F.leaky_relu(x) if self.leaky else F.relu(x)


class BasicConvIN(nn.Module):
    """2D (3D if ``is_3d``) convolution (transposed if ``deconv``; no bias), InstanceNorm (no affine, no
    tensors), LeakyReLU(0.01): IGEV's BasicConv_IN."""

    def __init__(self, in_channels: int, out_channels: int, *, deconv: bool = False, is_3d: bool = False,
                 norm: bool = True, relu: bool = True, kernel_size: int = 3, stride: int = 1,
                 padding: int = 0) -> None:
        super().__init__()
        self.use_in, self.relu = norm, relu
        conv: type[nn.Module]
        if is_3d:
            conv = nn.ConvTranspose3d if deconv else nn.Conv3d
        else:
            conv = nn.ConvTranspose2d if deconv else nn.Conv2d
        self.conv = conv(in_channels, out_channels, kernel_size, stride=stride, padding=padding, bias=False)
        self.IN = nn.InstanceNorm3d(out_channels) if is_3d else nn.InstanceNorm2d(out_channels)

    def forward(self, x: Tensor) -> Tensor:
        x = self.conv(x)
        if self.use_in:
            x = self.IN(x)
        return F.leaky_relu(x) if self.relu else x


class Conv2x(nn.Module):
    """IGEV's 2D Conv2x (``Conv2x_IN`` with ``instance``), concatenating, channels kept doubled: a
    stride-2 convolution (transposed, 4×4, when ``deconv``: upsampling ×2), resized (nearest) to
    ``rem`` where the sizes differ, concatenated with it, a 3×3 unit → 2·out channels. Without
    ``keep_concat`` the 3×3 unit gives out channels, and ``leaky`` off makes the units ReLU: the
    Conv2x of MoCha-Stereo's refinement (batch norm; its sizes always agree)."""

    def __init__(self, in_channels: int, out_channels: int, deconv: bool, *, instance: bool = False,
                 keep_concat: bool = True, leaky: bool = True) -> None:
        super().__init__()
        kernel = 4 if deconv else 3
        if instance:
            self.conv1: nn.Module = BasicConvIN(in_channels, out_channels, deconv=deconv, kernel_size=kernel,
                                                stride=2, padding=1)
            self.conv2: nn.Module = BasicConvIN(2 * out_channels, 2 * out_channels, kernel_size=3, stride=1, padding=1)
        else:
            self.conv1 = BasicConv(in_channels, out_channels, deconv=deconv, kernel_size=kernel, stride=2, padding=1,
                                   leaky=leaky)
            width = 2 * out_channels if keep_concat else out_channels
            self.conv2 = BasicConv(2 * out_channels, width, kernel_size=3, stride=1, padding=1, leaky=leaky)

    def forward(self, x: Tensor, rem: Tensor) -> Tensor:
        x = self.conv1(x)
        if x.shape != rem.shape:
            x = F.interpolate(x, size=rem.shape[-2:], mode="nearest")
        return self.conv2(torch.cat((x, rem), 1))


class FeatureAtt(nn.Module):
    """Image features B×F×h×w gate a cost volume B×C×D×h×w (sigmoid, one weight per channel and pixel,
    shared over disparities)."""

    def __init__(self, cv_channels: int, feature_channels: int) -> None:
        super().__init__()
        self.feat_att = nn.Sequential(BasicConv(feature_channels, feature_channels // 2, kernel_size=1),
                                      nn.Conv2d(feature_channels // 2, cv_channels, 1))

    def forward(self, cv: Tensor, features: Tensor) -> Tensor:
        return torch.sigmoid(self.feat_att(features).unsqueeze(2)) * cv


def _unit3d(in_channels: int, out_channels: int, kernel: int, stride: int = 1) -> BasicConv:
    return BasicConv(in_channels, out_channels, is_3d=True, kernel_size=kernel, stride=stride, padding=kernel // 2)


class Hourglass(nn.Module):
    """IGEV's cost aggregation: a 3D encoder–decoder over B×C×D×h×w at 1/4, three stride-2 stages
    (volume sides ÷8: D, h, w must be multiples of 8), each gated by the image features of its
    resolution (``feature_channels`` at 1/8, 1/16, 1/32: IGEV's 64, 192, 160) → B×8×D×h×w."""

    def __init__(self, channels: int, feature_channels: tuple[int, int, int] = (64, 192, 160)) -> None:
        super().__init__()
        c = channels
        self.conv1 = nn.Sequential(_unit3d(c, 2 * c, 3, 2), _unit3d(2 * c, 2 * c, 3))
        self.conv2 = nn.Sequential(_unit3d(2 * c, 4 * c, 3, 2), _unit3d(4 * c, 4 * c, 3))
        self.conv3 = nn.Sequential(_unit3d(4 * c, 6 * c, 3, 2), _unit3d(6 * c, 6 * c, 3))
        up = {"deconv": True, "is_3d": True, "kernel_size": 4, "stride": 2, "padding": 1}
        self.conv3_up = BasicConv(6 * c, 4 * c, **up)  # type: ignore[arg-type]
        self.conv2_up = BasicConv(4 * c, 2 * c, **up)  # type: ignore[arg-type]
        self.conv1_up = BasicConv(2 * c, 8, bn=False, relu=False, **up)  # type: ignore[arg-type]
        self.agg_0 = nn.Sequential(_unit3d(8 * c, 4 * c, 1), _unit3d(4 * c, 4 * c, 3), _unit3d(4 * c, 4 * c, 3))
        self.agg_1 = nn.Sequential(_unit3d(4 * c, 2 * c, 1), _unit3d(2 * c, 2 * c, 3), _unit3d(2 * c, 2 * c, 3))
        f8, f16, f32 = feature_channels
        self.feature_att_8 = FeatureAtt(2 * c, f8)
        self.feature_att_16 = FeatureAtt(4 * c, f16)
        self.feature_att_32 = FeatureAtt(6 * c, f32)
        self.feature_att_up_16 = FeatureAtt(4 * c, f16)
        self.feature_att_up_8 = FeatureAtt(2 * c, f8)

    def forward(self, x: Tensor, features: list[Tensor]) -> Tensor:
        conv1 = self.feature_att_8(self.conv1(x), features[1])
        conv2 = self.feature_att_16(self.conv2(conv1), features[2])
        conv3 = self.feature_att_32(self.conv3(conv2), features[3])
        conv2 = self.agg_0(torch.cat((self.conv3_up(conv3), conv2), dim=1))
        conv2 = self.feature_att_up_16(conv2, features[2])
        conv1 = self.agg_1(torch.cat((self.conv2_up(conv2), conv1), dim=1))
        conv1 = self.feature_att_up_8(conv1, features[1])
        return self.conv1_up(conv1)


def groupwise_volume(left: Tensor, right: Tensor, max_disparity: int, groups: int) -> Tensor:
    """B×C×h×w features → B×groups×max_disparity×h×w: per group of C/groups channels the mean of
    left(x)·right(x − d), 0 where x − d falls off the image."""
    batch, channels, height, width = left.shape
    volume = left.new_zeros([batch, groups, max_disparity, height, width])
    for d in range(min(max_disparity, width)):  # wider disparities see no right pixel: 0
        product = left[..., d:] * right[..., : width - d]
        volume[:, :, d, :, d:] = product.view(batch, groups, channels // groups, height, width - d).mean(dim=2)
    return volume


def disparity_regression(probability: Tensor) -> Tensor:
    """B×D×h×w probabilities over disparities 0 … D−1 → B×1×h×w expected disparity (soft argmin)."""
    values = torch.arange(probability.shape[1], dtype=probability.dtype, device=probability.device)
    return torch.sum(probability * values.view(1, -1, 1, 1), 1, keepdim=True)


def context_upsample(disparity: Tensor, weights: Tensor) -> Tensor:
    """B×1×h×w disparity (already in full-resolution pixels) and B×9×4h×4w weights → B×4h×4w: each
    full-resolution pixel mixes the 3×3 coarse neighbours of the pixel it lies in (zeros past the
    border, as IGEV)."""
    batch, _, height, width = disparity.shape
    patches = F.unfold(disparity, 3, 1, 1).reshape(batch, 9, height, width)
    patches = F.interpolate(patches, (4 * height, 4 * width), mode="nearest")
    return (patches * weights).sum(1)


def _sample_rows(volume: Tensor, positions: Tensor) -> Tensor:
    """(N×C×1×W volume, N×1×K×1 positions in samples along W) → N×C×1×K: linear interpolation,
    0 outside (grid_sample with corners aligned, as IGEV's bilinear_sampler)."""
    grid_x = 2 * positions / max(volume.shape[-1] - 1, 1) - 1
    grid = torch.cat([grid_x, torch.zeros_like(grid_x)], dim=-1)
    return F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=True)


class GeometryEncoding:
    """IGEV's Combined_Geo_Encoding_Volume: per pixel, at ``levels`` levels (halved along disparity or
    right x), 2·radius+1 samples around the current disparity of (a) the aggregated volume B×C×D×h×w
    and (b) the all-pairs correlation of the matching features (plain dot products).
    ``__call__(disparity)`` (B×1×h×w, pixels at 1/4) → B×(levels·(C+1)·(2·radius+1))×h×w, per level
    the volume's samples (channel-major) then the correlation's."""

    def __init__(self, left: Tensor, right: Tensor, volume: Tensor, *, levels: int, radius: int) -> None:
        batch, channels, depth, height, width = volume.shape
        self.levels, self.radius, self.shape = levels, radius, (batch, height, width)
        flat = volume.permute(0, 3, 4, 1, 2).reshape(batch * height * width, channels, 1, depth)
        self.volumes = [flat]
        for _ in range(levels - 1):
            flat = F.avg_pool2d(flat, (1, 2), stride=(1, 2))
            self.volumes.append(flat)
        # The correlation pyramid and its lookup are RAFT's (model/stereo/corr.py); it divides the dot
        # products by √dim, which IGEV does not, so the left features come in scaled by √dim.
        self.corr = CorrPyramid1D(left * math.sqrt(left.shape[1]), right, levels=levels, radius=radius)

    def __call__(self, disparity: Tensor) -> Tensor:
        batch, height, width = self.shape
        samples = 2 * self.radius + 1
        offsets = torch.linspace(-self.radius, self.radius, samples, device=disparity.device).view(1, 1, samples, 1)
        per_pixel = disparity.reshape(batch * height * width, 1, 1, 1)
        correlations = self.corr.lookup(disparity).split(samples, dim=1)
        out = []
        for level, volume in enumerate(self.volumes):
            sampled = _sample_rows(volume, offsets + per_pixel / 2**level)
            out.append(sampled.view(batch, height, width, -1).permute(0, 3, 1, 2))
            out.append(correlations[level])
        return torch.cat(out, dim=1).contiguous().float()
