"""MoCha-Stereo's network (Chen et al., "MoCha-Stereo: Motif Channel Attention Network for Stereo Matching",
CVPR 2024; ZYangChen/MoCha-Stereo): IGEV-Stereo (model/stereo/igev_volume.py: the group-wise volume, its
hourglass, the geometry encoding, the context upsampling) with timm's ``tf_efficientnetv2_l`` features
(model/stereo/efficientnet_features.py), a motif channel correlation volume (:class:`MotifChannelVolume`,
its ``nets/MCCV.py``) guiding the hourglass in place of the image features, mogrifier ConvLSTMs in place
of the GRUs (:class:`LstmUpdate`), and a refinement of the last upsampled iterate (:class:`Refinement`,
its ``nets/refinement.py`` REMP). Inference as its demo runs it (test mode), float32:
:func:`predict_disparity`, or as the stereo branch of a ``model.architecture = "mocha-stereo"`` network.

Layout and names are the published checkpoints' (``module.`` stripped) except the context and motion
encoders, the project's own (model/selective_igev_import.py's key map, shared by model/mocha_import.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.efficientnet_features import efficientnetv2_l_stages, efficientnetv2_l_stem
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
from model.stereo.raft import StereoResult
from model.stereo.raft_stereo import ContextEncoder
from model.stereo.selective_igev import DispHead
from model.stereo.update import MotionEncoder, pool2x, resize_like

HIDDEN = 128  # every published file's LSTM width (the reference's --hidden_dims default)
LEVELS = 3  # LSTM levels: the reference always builds three; the published files run three
MOTION_WIDTH, MOTION_CHANNELS, HEAD_WIDTH = 64, 128, 256
PAD_MULTIPLE = 32  # demo.py's InputPadder(divis_by=32)
DEMO_ITERATIONS = 32  # demo.py's --valid_iters default
MOGRIFIER_ROUNDS = 5
FEATURE_CHANNELS = (128, 192, 448, 384)  # the decoder's outputs at 1/4 (before the stem's 128), 1/8, 1/16, 1/32


@dataclass(frozen=True)
class MochaConfig(VolumeConfig):
    """The reference's argparse options that shape the network: those of the volume (its LSTMs are always
    three levels of 128)."""


class Feature(nn.Module):
    """EfficientNetV2-L's stages (sliced as the reference: [0], [1], [2], [3, 4], [5]) and a U-Net decoder
    (instance norm) → [B×128×h/4, B×192×h/8, B×448×h/16, B×384×h/32]."""

    def __init__(self) -> None:
        super().__init__()
        self.conv_stem, self.bn1 = efficientnetv2_l_stem()
        stages = efficientnetv2_l_stages(6)  # the 640-channel stage is not used (nor saved)
        self.block0 = nn.Sequential(stages[0])
        self.block1 = nn.Sequential(stages[1])
        self.block2 = nn.Sequential(stages[2])
        self.block3 = nn.Sequential(stages[3], stages[4])
        self.block4 = nn.Sequential(stages[5])
        self.deconv32_16 = Conv2x(384, 224, True, instance=True)
        self.deconv16_8 = Conv2x(448, 96, True, instance=True)
        self.deconv8_4 = Conv2x(192, 64, True, instance=True)
        self.conv4 = BasicConvIN(128, 128, kernel_size=3, stride=1, padding=1)

    def forward(self, x: Tensor) -> list[Tensor]:
        x2 = self.block0(self.bn1(self.conv_stem(x)))
        x4 = self.block1(x2)
        x8 = self.block2(x4)
        x16 = self.block3(x8)
        x32 = self.block4(x16)
        x16 = self.deconv32_16(x32, x16)
        x8 = self.deconv16_8(x16, x8)
        x4 = self.conv4(self.deconv8_4(x8, x4))
        return [x4, x8, x16, x32]


def high_pass(x: Tensor) -> Tensor:
    """MCCV's "high-frequency sliding window filter": ``x`` minus the 3×3 box mean (zeros past the border)
    of its channel sum. The reference convolves with a C×C kernel of 1/9 everywhere — every output channel
    the same sum over all input channels —, which this computes once."""
    return x - F.avg_pool2d(x.sum(1, keepdim=True), 3, stride=1, padding=1, count_include_pad=True)


class MotifChannelVolume(nn.Module):
    """The motif channel correlation volume (MCCV's Mca_Camp) at 1/8 and 1/16: per pixel 4 softmax motif
    weights from the high-passed left and right features (a 3×3 convolution), each scaling the left
    features, fused by a 3-D convolution over (motif, channel) → B×C×h×w. The reference also builds one
    at 1/4 (``sw_4x``, ``Conv3d_layer_4x``) whose output nothing reads: not built here."""

    def __init__(self) -> None:
        super().__init__()
        self.sw_8x = nn.Conv2d(2 * FEATURE_CHANNELS[1], 4, 3, 1, 1, bias=False)
        self.sw_16x = nn.Conv2d(2 * FEATURE_CHANNELS[2], 4, 3, 1, 1, bias=False)
        self.Conv3d_layer_8x = BasicConvIN(4, 1, is_3d=True, kernel_size=3, stride=1, padding=1)
        self.Conv3d_layer_16x = BasicConvIN(4, 1, is_3d=True, kernel_size=3, stride=1, padding=1)

    @staticmethod
    def _volume(left: Tensor, right: Tensor, motif_conv: nn.Module, fuse: nn.Module) -> Tensor:
        motif = F.softmax(motif_conv(high_pass(torch.cat([left, right], dim=1))), dim=1)  # B×4×h×w
        weighted = (motif.unsqueeze(1) * left.unsqueeze(2)).transpose(1, 2)  # B×4×C×h×w
        return fuse(weighted).squeeze(1)

    def forward(self, left: Sequence[Tensor], right: Sequence[Tensor]) -> list[Tensor]:
        """The hourglass's guidance at 1/8, 1/16, 1/32 (the last the left features themselves), with the
        1/4 features in front (unused by the hourglass, which reads entries 1–3)."""
        return [left[0], self._volume(left[1], right[1], self.sw_8x, self.Conv3d_layer_8x),
                self._volume(left[2], right[2], self.sw_16x, self.Conv3d_layer_16x), left[3]]


class Mogrifier(nn.Module):
    """Five rounds of mutual gating (nets/mogrifier.py): x ← 2σ(Q h)·x, h ← 2σ(R x)·h alternately, Q and
    R 3×3 convolutions."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.Q = nn.Conv2d(channels, channels, 3, padding=1)
        self.R = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: Tensor, h: Tensor) -> tuple[Tensor, Tensor]:
        for round_ in range(MOGRIFIER_ROUNDS):
            if round_ % 2 == 0:
                x = 2 * torch.sigmoid(self.Q(h)) * x
            else:
                h = 2 * torch.sigmoid(self.R(x)) * h
        return x, h


class MogrifierLSTM(nn.Module):
    """The reference's ConvLSTM cell: 3×3 gates plus per-pixel context biases (input, forget, cell, output);
    where the input is as wide as the state, the mogrifier gates both first (the cell state is not)."""

    def __init__(self, hidden: int, inputs: int) -> None:
        super().__init__()
        self.conv_it = nn.Conv2d(hidden + inputs, hidden, 3, padding=1)
        self.conv_c_t = nn.Conv2d(hidden + inputs, hidden, 3, padding=1)
        self.conv_ft = nn.Conv2d(hidden + inputs, hidden, 3, padding=1)
        self.conv_ot = nn.Conv2d(hidden + inputs, hidden, 3, padding=1)
        self.m = Mogrifier(hidden)

    def forward(self, c: Tensor, h: Tensor, context: Sequence[Tensor], *x: Tensor) -> tuple[Tensor, Tensor]:
        bi, bf, bc, bo = context
        inputs = torch.cat(x, dim=1)
        if inputs.shape[1] == h.shape[1]:
            inputs, h = self.m(inputs, h)
        hx = torch.cat([h, inputs], dim=1)
        cell = c * torch.sigmoid(self.conv_ft(hx) + bf) + torch.sigmoid(self.conv_it(hx) + bi) * torch.tanh(
            self.conv_c_t(hx) + bc)
        return cell, torch.sigmoid(self.conv_ot(hx) + bo) * torch.tanh(cell)


class LstmUpdate(nn.Module):
    """LSTMMultiUpdateBlock at 3 levels (1/16, 1/8, 1/4, coarse to fine), the finest reading the motion
    features. → (states, the 1/4 features for the upsampling weights, disparity update B×1×h×w in pixels
    at 1/4).

    One state per level: the reference passes the same list as cell and hidden states
    (``netC = net_list``), so each level's cell state is overwritten by its hidden state as soon as it is
    assigned, and every step starts from c = h."""

    def __init__(self, corr_planes: int) -> None:
        super().__init__()
        self.encoder = MotionEncoder(corr_planes, MOTION_WIDTH, MOTION_CHANNELS)
        self.lstm04 = MogrifierLSTM(HIDDEN, MOTION_CHANNELS + HIDDEN)
        self.lstm08 = MogrifierLSTM(HIDDEN, 2 * HIDDEN)
        self.lstm16 = MogrifierLSTM(HIDDEN, HIDDEN)
        self.disp_head = DispHead(HIDDEN, HEAD_WIDTH)
        self.mask_feat_4 = nn.Sequential(nn.Conv2d(HIDDEN, 32, 3, padding=1), nn.ReLU(inplace=True))

    def forward(self, net: list[Tensor], inp: Sequence[Sequence[Tensor]], corr: Tensor,
                disparity: Tensor) -> tuple[list[Tensor], Tensor, Tensor]:
        net = list(net)
        net[2] = self.lstm16(net[2], net[2], inp[2], pool2x(net[1]))[1]
        net[1] = self.lstm08(net[1], net[1], inp[1], pool2x(net[0]), resize_like(net[2], net[1]))[1]
        motion = self.encoder(corr, disparity)
        net[0] = self.lstm04(net[0], net[0], inp[0], motion, resize_like(net[1], net[0]))[1]
        return net, self.mask_feat_4(net[0]), self.disp_head(net[0])


def _conv_bn_leaky(in_channels: int, out_channels: int) -> nn.Sequential:
    """REMP's conv2d: 3×3 (no bias), batch norm, LeakyReLU(0.2)."""
    return nn.Sequential(nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
                         nn.BatchNorm2d(out_channels), nn.LeakyReLU(0.2, inplace=True))


class SimpleUNet(nn.Module):
    """REMP's Simple_UNet over B×32×H×W (H, W multiples of 16): down four times, up, down and up again
    (ReLU units, batch norm) → B×32×H×W."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        relu = {"leaky": False}
        self.conv1a = BasicConv(channels, 48, kernel_size=3, stride=2, padding=1, **relu)  # type: ignore[arg-type]
        self.conv2a = BasicConv(48, 64, kernel_size=3, stride=2, padding=1, **relu)  # type: ignore[arg-type]
        self.conv3a = BasicConv(64, 96, kernel_size=3, stride=2, dilation=2, padding=2, **relu)  # type: ignore[arg-type]
        self.conv4a = BasicConv(96, 128, kernel_size=3, stride=2, dilation=2, padding=2, **relu)  # type: ignore[arg-type]
        widths = [(128, 96, True), (96, 64, True), (64, 48, True), (48, 32, True), (32, 48, False), (48, 64, False),
                  (64, 96, False), (96, 128, False), (128, 96, True), (96, 64, True), (64, 48, True),
                  (48, channels, True)]
        names = ["deconv4a", "deconv3a", "deconv2a", "deconv1a", "conv1b", "conv2b", "conv3b", "conv4b",
                 "deconv4b", "deconv3b", "deconv2b", "deconv1b"]
        for name, (inputs, outputs, deconv) in zip(names, widths, strict=True):
            setattr(self, name, Conv2x(inputs, outputs, deconv, keep_concat=False, leaky=False))

    def forward(self, x: Tensor) -> Tensor:
        rem0 = x
        rem1 = x = self.conv1a(x)
        rem2 = x = self.conv2a(x)
        rem3 = x = self.conv3a(x)
        rem4 = x = self.conv4a(x)
        rem3 = x = self.deconv4a(x, rem3)
        rem2 = x = self.deconv3a(x, rem2)
        rem1 = x = self.deconv2a(x, rem1)
        rem0 = x = self.deconv1a(x, rem0)
        rem1 = x = self.conv1b(x, rem1)
        rem2 = x = self.conv2b(x, rem2)
        rem3 = x = self.conv3b(x, rem3)
        x = self.conv4b(x, rem4)
        x = self.deconv4b(x, rem3)
        x = self.deconv3b(x, rem2)
        x = self.deconv2b(x, rem1)
        return self.deconv1b(x, rem0)


def warp_right(right: Tensor, disparity: Tensor) -> Tensor:
    """nets/warp.py's disp_warp: the right image sampled at x − d (bilinear, border), as the reference
    does it — coordinates normalised by W − 1 but sampled with corners not aligned (grid_sample's
    default), which shifts the sample by up to half a pixel; kept, since the weights learnt with it."""
    batch, _, height, width = right.shape
    xs = torch.arange(width, dtype=right.dtype, device=right.device).view(1, 1, width) - disparity[:, 0]
    ys = torch.arange(height, dtype=right.dtype, device=right.device).view(1, height, 1).expand(batch, height, width)
    grid = torch.stack([2 * xs / (width - 1) - 1, 2 * ys / (height - 1) - 1], dim=-1)
    return F.grid_sample(right, grid, mode="bilinear", padding_mode="border", align_corners=False)


class Refinement(nn.Module):
    """REMP: from the left image, the right warped by the disparity, and the disparity (all B×·×H×W at
    full resolution) a correction; returns −relu(d + correction), which the network adds to d (so the
    output is d − relu(d + correction), as the reference)."""

    def __init__(self) -> None:
        super().__init__()
        channels = 32
        self.conv1 = _conv_bn_leaky(6, 16)
        self.conv2 = _conv_bn_leaky(1, 16)
        self.conv_start = BasicConv(32, channels, kernel_size=3, padding=2, dilation=2, leaky=False)
        self.RefinementBlock = SimpleUNet(channels)
        self.LFE = nn.Sequential(nn.Conv2d(channels, 2 * channels, 1), nn.ReLU(inplace=True),
                                 nn.Conv2d(2 * channels, channels, 1), nn.Sigmoid())
        self.LMC = nn.Sequential(nn.Conv2d(channels, channels, 3, padding=1),
                                 nn.Conv2d(channels, 2 * channels, 3, padding=1), nn.ReLU(inplace=True),
                                 nn.Conv2d(2 * channels, channels, 3, padding=1), nn.Sigmoid())
        self.final_conv = nn.Conv2d(32, 1, 3, 1, 1)

    def forward(self, disparity: Tensor, left: Tensor, right: Tensor) -> Tensor:
        flaw = warp_right(right, disparity) - left
        x = torch.cat((self.conv1(torch.cat((flaw, left), dim=1)), self.conv2(disparity)), dim=1)
        x = self.RefinementBlock(self.conv_start(x))
        low = self.LFE(F.adaptive_avg_pool2d(x, 1))
        motif = self.LMC(x)
        x = self.final_conv((1 - motif) * low + motif * x)
        return -F.relu(disparity + x)


class MochaStereo(nn.Module):
    """Images normalised to [−1, 1] (B×3×H×W, H and W multiples of 32) → :class:`StereoResult`: disparity
    iterates in pixels, positive (left x matches right x − d), at 1/4 (``iterates_low``) and upsampled to
    H×W (``iterates``: the last only unless ``all_iterates``), the last refined (REMP) as the reference's
    test mode returns it. The branch protocol of model.network's baselines (:class:`MochaBranch`)."""

    def __init__(self, config: MochaConfig = MochaConfig()) -> None:
        super().__init__()
        self.config = config
        # RAFT-Stereo's MultiBasicEncoder is IGEV's (and MoCha's) context encoder, layer for layer.
        self.cnet = ContextEncoder(ModelConfig(
            architecture="raft-stereo", n_downsample=2, encoder_dims=(64, 96, 128), encoder_blocks=(2, 2, 2),
            stem_kernel=7, hidden_dims=(HIDDEN,) * 3, context_norm="batch", gru_levels=LEVELS,
            use_mono=False, use_vlm=False))
        self.update_block = LstmUpdate(config.corr_planes)
        self.context_zqr_convs = nn.ModuleList([nn.Conv2d(HIDDEN, 4 * HIDDEN, 3, padding=1) for _ in range(LEVELS)])
        self.feature = Feature()
        stem = FEATURE_CHANNELS[0]
        self.stem_2 = nn.Sequential(BasicConvIN(3, 32, kernel_size=3, stride=2, padding=1),
                                    nn.Conv2d(32, 32, 3, 1, 1, bias=False), nn.InstanceNorm2d(32), nn.ReLU())
        self.stem_4 = nn.Sequential(BasicConvIN(32, stem, kernel_size=3, stride=2, padding=1),
                                    nn.Conv2d(stem, stem, 3, 1, 1, bias=False), nn.InstanceNorm2d(stem), nn.ReLU())
        self.spx_2_gru = Conv2x(32, 32, True)
        self.spx_gru = nn.Sequential(nn.ConvTranspose2d(2 * 32, 9, kernel_size=4, stride=2, padding=1))
        self.conv = BasicConvIN(2 * stem, 96, kernel_size=3, padding=1, stride=1)
        self.desc = nn.Conv2d(96, 96, kernel_size=1, padding=0, stride=1)
        self.corr_stem = BasicConv(GROUPS, GROUPS, is_3d=True, kernel_size=3, stride=1, padding=1)
        self.corr_feature_att = FeatureAtt(GROUPS, 2 * stem)
        self.cost_agg = Hourglass(GROUPS, FEATURE_CHANNELS[1:])  # type: ignore[arg-type]
        self.classifier = nn.Conv3d(GROUPS, 1, 3, 1, 1, bias=False)
        self.mccv = MotifChannelVolume()
        self.REMP = Refinement()

    def forward(self, left: Tensor, right: Tensor, *, iters: int = DEMO_ITERATIONS,
                all_iterates: bool = False) -> StereoResult:
        if iters < 1:
            raise ValueError(f"iters must be at least 1, got {iters}")
        features_left, features_right = self.feature(left), self.feature(right)
        stem_2x, stem_2y = self.stem_2(left), self.stem_2(right)
        features_left[0] = torch.cat((features_left[0], self.stem_4(stem_2x)), 1)
        features_right[0] = torch.cat((features_right[0], self.stem_4(stem_2y)), 1)
        match_left = self.desc(self.conv(features_left[0]))
        match_right = self.desc(self.conv(features_right[0]))
        volume = groupwise_volume(match_left, match_right, self.config.max_disp // 4, GROUPS)
        volume = self.corr_feature_att(self.corr_stem(volume), features_left[0])
        geometry = self.cost_agg(volume, self.mccv(features_left, features_right))
        disparity = disparity_regression(F.softmax(self.classifier(geometry).squeeze(1), dim=1))

        hidden, context, _ = self.cnet(left, left.shape[0])
        net = [torch.tanh(h) for h in hidden]
        inp = [conv(torch.relu(c)).split(HIDDEN, dim=1) for c, conv in zip(context, self.context_zqr_convs, strict=True)]

        encoding = GeometryEncoding(match_left.float(), match_right.float(), geometry.float(),
                                    levels=self.config.corr_levels, radius=self.config.corr_radius)
        low: list[Tensor] = []
        full: list[Tensor] = []
        weights = None
        for step in range(iters):
            disparity = disparity.detach()
            net, mask_features, delta = self.update_block(net, inp, encoding(disparity), disparity)
            disparity = disparity + delta
            low.append(disparity)
            if all_iterates or step == iters - 1:  # test mode upsamples the last iterate only
                weights = F.softmax(self.spx_gru(self.spx_2_gru(mask_features, stem_2x)), 1)
                up = context_upsample(disparity * 4.0, weights).unsqueeze(1)
                if step == iters - 1:  # the reference refines the last iterate only
                    up = up + self.REMP(up, left, right)
                full.append(up)
        assert weights is not None
        return StereoResult(low, full, net[0], weights, match_left, encoding)  # type: ignore[arg-type]


class MochaBranch(MochaStereo):
    """MoCha-Stereo as the stereo branch of a ``model.architecture = "mocha-stereo"`` network
    (model/network.py's BASELINE_BRANCHES): its options from the model config."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__(MochaConfig(corr_levels=config.corr_levels, corr_radius=config.corr_radius,
                                     max_disp=config.max_disp))


def predict_disparity(network: MochaStereo, left: np.ndarray, right: np.ndarray, *,
                      iters: int = DEMO_ITERATIONS) -> np.ndarray:
    """What MoCha-Stereo's demo.py computes for a pair: ``left``/``right`` RGB uint8 H×W×3 of one size →
    H×W float32 disparity in pixels (positive: left x matches right x − d; the network's output as it
    is). Centred replicate padding to multiples of 32, ``iters`` refinements (the demo's 32), test mode,
    the padding cropped off; on the network's device, float32, no autograd, eval mode."""
    return demo_disparity(network, left, right, iters, PAD_MULTIPLE)
