"""Selective-IGEV's network (Wang et al., "Selective-Stereo", CVPR 2024; Windsrain/Selective-Stereo, MIT):
IGEV-Stereo whose GRUs are Selective Recurrent Units — per level a 1×1-kernel and a 3×3-kernel GRU
blended by a spatial attention map from the context (the "contextual spatial attention"), the context
itself scaled by a channel attention. Inference as its demo runs it (test mode: only the last iterate
is upsampled), float32: :func:`predict_disparity` alone, or as the stereo branch of a
``model.architecture = "selective-igev"`` network (:class:`SelectiveIgevBranch`), which `predict` and
`evaluate` run with the same padding.

Layout and names are the published checkpoints' (``module.`` stripped) except where a module is the
project's own: the context encoder (RAFT-Stereo's MultiBasicEncoder, :class:`ContextEncoder`) and the
motion encoder (:class:`MotionEncoder`); model/selective_igev_import.py maps those keys.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.igev_volume import (
    GROUPS,
    BasicConv,
    BasicConvIN,
    Conv2x,
    FeatureAtt,
    GeometryEncoding,
    Hourglass,
    VolumeConfig,
    context_upsample,
    disparity_regression,
    groupwise_volume,
)
from model.stereo.inputs import demo_disparity
from model.stereo.mobilenet_features import MobileNetV2Stem, mobilenetv2_stages
from model.stereo.raft import StereoResult
from model.stereo.raft_stereo import ContextEncoder
from model.stereo.update import MotionEncoder, pool2x, resize_like

HIDDEN = 128  # every published file's GRU width; the channel attention is built for 128 channels
MOTION_WIDTH, MOTION_CHANNELS, HEAD_WIDTH = 64, 128, 256
PAD_MULTIPLE = 32  # the demo's InputPadder(divis_by=32): the volume at 1/4 is halved three times
DEMO_ITERATIONS = 32  # demo_imgs.py's --valid_iters default


@dataclass(frozen=True)
class SelectiveIGEVConfig(VolumeConfig):
    """The reference's argparse options that shape the network: ``n_gru_layers`` (1–3),
    ``corr_levels``, ``corr_radius``, ``max_disp`` (pixels at full resolution, a multiple of 32: the
    cost volume spans max_disp/4 disparities at 1/4)."""

    n_gru_layers: int = 3

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.n_gru_layers not in (1, 2, 3):
            raise ValueError(f"n_gru_layers must be 1, 2 or 3, got {self.n_gru_layers}")


class Feature(nn.Module):
    """The matching/guidance features: MobileNetV2's stages at 1/2 … 1/32, then a U-Net decoder (instance
    norm) → [B×48×h/4, B×64×h/8, B×192×h/16, B×160×h/32] (the first before the stem features are added)."""

    def __init__(self) -> None:
        super().__init__()
        stem = MobileNetV2Stem()
        self.conv_stem, self.bn1, self.act1 = stem.conv_stem, stem.bn1, stem.act1
        stages = mobilenetv2_stages(6)  # the 320-channel stage is not used
        # As the reference slices timm's blocks: [0], [1], [2], [3, 4], [5].
        self.block0 = nn.Sequential(stages[0])
        self.block1 = nn.Sequential(stages[1])
        self.block2 = nn.Sequential(stages[2])
        self.block3 = nn.Sequential(stages[3], stages[4])
        self.block4 = nn.Sequential(stages[5])
        self.deconv32_16 = Conv2x(160, 96, True, instance=True)
        self.deconv16_8 = Conv2x(192, 32, True, instance=True)
        self.deconv8_4 = Conv2x(64, 24, True, instance=True)
        self.conv4 = BasicConvIN(48, 48, kernel_size=3, stride=1, padding=1)

    def forward(self, x: Tensor) -> list[Tensor]:
        x2 = self.block0(self.act1(self.bn1(self.conv_stem(x))))
        x4 = self.block1(x2)
        x8 = self.block2(x4)
        x16 = self.block3(x8)
        x32 = self.block4(x16)
        x16 = self.deconv32_16(x32, x16)
        x8 = self.deconv16_8(x16, x8)
        x4 = self.conv4(self.deconv8_4(x8, x4))
        return [x4, x8, x16, x32]


class RaftConvGRU(nn.Module):
    """A plain convolutional GRU cell (square kernel, no context terms)."""

    def __init__(self, hidden: int, inputs: int, kernel: int) -> None:
        super().__init__()
        self.convz = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)
        self.convr = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)
        self.convq = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)

    def forward(self, h: Tensor, x: Tensor) -> Tensor:
        hx = torch.cat([h, x], dim=1)
        z = torch.sigmoid(self.convz(hx))
        r = torch.sigmoid(self.convr(hx))
        q = torch.tanh(self.convq(torch.cat([r * h, x], dim=1)))
        return (1 - z) * h + z * q


class SelectiveConvGRU(nn.Module):
    """The Selective Recurrent Unit: a 1×1 GRU where ``att`` (B×1×h×w in 0…1) is high, a 3×3 one where low."""

    def __init__(self, hidden: int, inputs: int) -> None:
        super().__init__()
        self.small_gru = RaftConvGRU(hidden, inputs, 1)
        self.large_gru = RaftConvGRU(hidden, inputs, 3)

    def forward(self, att: Tensor, h: Tensor, *x: Tensor) -> Tensor:
        inputs = torch.cat(x, dim=1)
        return self.small_gru(h, inputs) * att + self.large_gru(h, inputs) * (1 - att)


class ChannelAttention(nn.Module):
    """B×C×h×w → B×C×1×1 weights in 0…1 (a shared 2-layer 1×1 MLP over mean- and max-pooled features)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.fc = nn.Sequential(nn.Conv2d(channels, channels // 16, 1, bias=False), nn.ReLU(),
                                nn.Conv2d(channels // 16, channels, 1, bias=False))

    def forward(self, x: Tensor) -> Tensor:
        return torch.sigmoid(self.fc(F.adaptive_avg_pool2d(x, 1)) + self.fc(F.adaptive_max_pool2d(x, 1)))


class SpatialAttention(nn.Module):
    """B×C×h×w → B×1×h×w weights in 0…1 (a 7×7 convolution of the channel mean and max)."""

    def __init__(self) -> None:
        super().__init__()
        self.samconv = nn.Conv2d(2, 1, 7, padding=3, bias=False)

    def forward(self, x: Tensor) -> Tensor:
        pooled = torch.cat([x.mean(dim=1, keepdim=True), x.max(dim=1, keepdim=True)[0]], dim=1)
        return torch.sigmoid(self.samconv(pooled))


class DispHead(nn.Module):
    def __init__(self, channels: int, width: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, width, 3, padding=1)
        self.conv2 = nn.Conv2d(width, 1, 3, padding=1)

    def forward(self, x: Tensor) -> Tensor:
        return self.conv2(torch.relu(self.conv1(x)))


class SelectiveUpdate(nn.Module):
    """BasicSelectiveMultiUpdateBlock: SRUs at 1/16, 1/8, 1/4 (coarse to fine, ``levels`` of them),
    each fed its context; the finest reads the motion features. → (hidden states, the 1/4 features
    for the upsampling weights, disparity update B×1×h×w in pixels at 1/4)."""

    def __init__(self, levels: int, corr_planes: int) -> None:
        super().__init__()
        self.levels = levels
        self.encoder = MotionEncoder(corr_planes, MOTION_WIDTH, MOTION_CHANNELS)
        if levels == 3:
            self.gru16 = SelectiveConvGRU(HIDDEN, 2 * HIDDEN)
        if levels >= 2:
            self.gru08 = SelectiveConvGRU(HIDDEN, HIDDEN * (levels == 3) + 2 * HIDDEN)
        self.gru04 = SelectiveConvGRU(HIDDEN, MOTION_CHANNELS + HIDDEN * (levels > 1) + HIDDEN)
        self.disp_head = DispHead(HIDDEN, HEAD_WIDTH)
        self.mask_feat_4 = nn.Sequential(nn.Conv2d(HIDDEN, 32, 3, padding=1), nn.ReLU(inplace=True))

    def forward(self, net: list[Tensor], inp: Sequence[Tensor], corr: Tensor, disparity: Tensor,
                att: Sequence[Tensor]) -> tuple[list[Tensor], Tensor, Tensor]:
        net = list(net)
        if self.levels == 3:
            net[2] = self.gru16(att[2], net[2], inp[2], pool2x(net[1]))
        if self.levels == 3:
            net[1] = self.gru08(att[1], net[1], inp[1], pool2x(net[0]), resize_like(net[2], net[1]))
        elif self.levels == 2:
            net[1] = self.gru08(att[1], net[1], inp[1], pool2x(net[0]))
        motion = torch.cat([inp[0], self.encoder(corr, disparity)], dim=1)
        if self.levels > 1:  # as the reference: with one level the finest GRU never runs
            net[0] = self.gru04(att[0], net[0], motion, resize_like(net[1], net[0]))
        # The upsampling features scaled down by 4, as the reference (to balance gradients).
        return net, 0.25 * self.mask_feat_4(net[0]), self.disp_head(net[0])


class SelectiveIGEV(nn.Module):
    """Images normalised to [−1, 1] (B×3×H×W, H and W multiples of 32) → :class:`StereoResult`: disparity
    iterates in pixels, positive (left x matches right x − d), at 1/4 (``iterates_low``, in 1/4-resolution
    pixels) and upsampled to H×W (``iterates``: the last only unless ``all_iterates``, the reference's test
    mode). The branch protocol of model.network's baselines (:class:`SelectiveIgevBranch`)."""

    def __init__(self, config: SelectiveIGEVConfig = SelectiveIGEVConfig()) -> None:
        super().__init__()
        self.config = config
        # RAFT-Stereo's MultiBasicEncoder is Selective-IGEV's context encoder, layer for layer
        # (batch norm, 1/4 trunk, 128 channels, two heads per level).
        self.cnet = ContextEncoder(ModelConfig(
            architecture="raft-stereo", n_downsample=2, encoder_dims=(64, 96, 128), encoder_blocks=(2, 2, 2),
            stem_kernel=7, hidden_dims=(HIDDEN,) * 3, context_norm="batch", gru_levels=config.n_gru_layers,
            use_mono=False, use_vlm=False))
        self.update_block = SelectiveUpdate(config.n_gru_layers, config.corr_planes)
        self.sam = SpatialAttention()
        self.cam = ChannelAttention(HIDDEN)
        self.feature = Feature()
        self.stem_2 = nn.Sequential(BasicConvIN(3, 32, kernel_size=3, stride=2, padding=1),
                                    nn.Conv2d(32, 32, 3, 1, 1, bias=False), nn.InstanceNorm2d(32), nn.ReLU())
        self.stem_4 = nn.Sequential(BasicConvIN(32, 48, kernel_size=3, stride=2, padding=1),
                                    nn.Conv2d(48, 48, 3, 1, 1, bias=False), nn.InstanceNorm2d(48), nn.ReLU())
        self.spx_2_gru = Conv2x(32, 32, True)
        self.spx_gru = nn.Sequential(nn.ConvTranspose2d(2 * 32, 9, kernel_size=4, stride=2, padding=1))
        self.conv = BasicConvIN(96, 96, kernel_size=3, padding=1, stride=1)
        self.desc = nn.Conv2d(96, 96, kernel_size=1, padding=0, stride=1)
        self.corr_stem = BasicConv(GROUPS, GROUPS, is_3d=True, kernel_size=3, stride=1, padding=1)
        self.corr_feature_att = FeatureAtt(GROUPS, 96)
        self.cost_agg = Hourglass(GROUPS)
        self.classifier = nn.Conv3d(GROUPS, 1, 3, 1, 1, bias=False)

    def forward(self, left: Tensor, right: Tensor, *, iters: int = DEMO_ITERATIONS,
                all_iterates: bool = False) -> StereoResult:
        if iters < 1:
            raise ValueError(f"iters must be at least 1, got {iters}")
        features_left, features_right = self.feature(left), self.feature(right)
        stem_2x = self.stem_2(left)
        stem_2y = self.stem_2(right)
        features_left[0] = torch.cat((features_left[0], self.stem_4(stem_2x)), 1)
        features_right[0] = torch.cat((features_right[0], self.stem_4(stem_2y)), 1)
        match_left = self.desc(self.conv(features_left[0]))
        match_right = self.desc(self.conv(features_right[0]))
        volume = groupwise_volume(match_left, match_right, self.config.max_disp // 4, GROUPS)
        volume = self.corr_feature_att(self.corr_stem(volume), features_left[0])
        geometry = self.cost_agg(volume, features_left)
        probability = F.softmax(self.classifier(geometry).squeeze(1), dim=1)
        disparity = disparity_regression(probability)

        hidden, context, _ = self.cnet(left, left.shape[0])
        net = [torch.tanh(h) for h in hidden]
        inp = [torch.relu(c) for c in context]
        inp = [self.cam(x) * x for x in inp]
        att = [self.sam(x) for x in inp]

        encoding = GeometryEncoding(match_left.float(), match_right.float(), geometry.float(),
                                    levels=self.config.corr_levels, radius=self.config.corr_radius)
        low: list[Tensor] = []
        full: list[Tensor] = []
        weights = None
        for step in range(iters):
            disparity = disparity.detach()  # as the reference trains: no gradient through earlier iterates
            net, mask_features, delta = self.update_block(net, inp, encoding(disparity), disparity, att)
            disparity = disparity + delta
            low.append(disparity)
            if all_iterates or step == iters - 1:  # test mode upsamples the last iterate only
                weights = F.softmax(self.spx_gru(self.spx_2_gru(mask_features, stem_2x)), 1)
                full.append(context_upsample(disparity * 4.0, weights).unsqueeze(1))
        assert weights is not None
        return StereoResult(low, full, net[0], weights, match_left, encoding)  # type: ignore[arg-type]


class SelectiveIgevBranch(SelectiveIGEV):
    """Selective-IGEV as the stereo branch of a ``model.architecture = "selective-igev"`` network
    (model/network.py's BASELINE_BRANCHES): its options from the model config."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__(SelectiveIGEVConfig(n_gru_layers=config.gru_levels, corr_levels=config.corr_levels,
                                             corr_radius=config.corr_radius, max_disp=config.max_disp))


def predict_disparity(network: SelectiveIGEV, left: np.ndarray, right: np.ndarray, *,
                      iters: int = DEMO_ITERATIONS) -> np.ndarray:
    """What Selective-IGEV's demo_imgs.py computes for a pair: ``left``/``right`` RGB uint8 H×W×3 of one
    size → H×W float32 disparity in pixels (positive: left x matches right x − d; the network's output
    as it is). Centred replicate padding to multiples of 32, ``iters`` refinements (the demo's 32),
    test mode, the padding cropped off; on the network's device, float32, no autograd. Puts the network
    in eval mode, as the demo does (batch norms use their running statistics)."""
    return demo_disparity(network, left, right, iters, PAD_MULTIPLE)
