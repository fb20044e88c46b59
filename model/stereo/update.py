"""The multi-level ConvGRU update (RAFT-Stereo): GRUs at 1/2**n, 1/2**(n+1), 1/2**(n+2) pass
hidden states up and down; the finest one reads correlation and disparity ("motion") features
and predicts a disparity update and the convex-upsampling mask."""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.stereo.upsample import MaskHead


class ConvGRU(nn.Module):
    """A convolutional GRU cell whose gates also get per-pixel context terms (cz, cr, cq),
    computed once per forward from the context features; ``context`` None: plain gates (RAFT's
    ConvGRU, which Selective-RAFT feeds its context as an input instead)."""

    def __init__(self, hidden: int, inputs: int, kernel: int = 3) -> None:
        super().__init__()
        self.convz = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)
        self.convr = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)
        self.convq = nn.Conv2d(hidden + inputs, hidden, kernel, padding=kernel // 2)

    def forward(self, h: Tensor, context: Sequence[Tensor] | None, *x: Tensor) -> Tensor:
        cz, cr, cq = context if context is not None else (0, 0, 0)
        inputs = torch.cat(x, dim=1)
        hx = torch.cat([h, inputs], dim=1)
        z = torch.sigmoid(self.convz(hx) + cz)
        r = torch.sigmoid(self.convr(hx) + cr)
        q = torch.tanh(self.convq(torch.cat([r * h, inputs], dim=1)) + cq)
        return (1 - z) * h + z * q


class MotionEncoder(nn.Module):
    """Correlation samples and the current flow (``flow_channels``: 1, the disparity; RAFT-Stereo's
    2, flow x and y) through two ``width``-wide stacks → ``out_channels`` channels, the last
    ``flow_channels`` of them the flow itself, as RAFT keeps it."""

    def __init__(self, corr_channels: int, width: int, out_channels: int, flow_channels: int = 1) -> None:
        super().__init__()
        self.corr = nn.Sequential(nn.Conv2d(corr_channels, width, 1), nn.ReLU(inplace=True),
                                  nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True))
        self.disp = nn.Sequential(nn.Conv2d(flow_channels, width, 7, padding=3), nn.ReLU(inplace=True),
                                  nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True))
        self.out = nn.Conv2d(2 * width, out_channels - flow_channels, 3, padding=1)

    def forward(self, corr: Tensor, flow: Tensor) -> Tensor:
        features = torch.cat([self.corr(corr), self.disp(flow)], dim=1)
        return torch.cat([torch.relu(self.out(features)), flow], dim=1)


def pool2x(x: Tensor) -> Tensor:
    """A finer GRU level's state at the next coarser level's resolution (RAFT's 3×3, stride-2 mean)."""
    return F.avg_pool2d(x, 3, stride=2, padding=1)


def resize_like(x: Tensor, like: Tensor) -> Tensor:
    """``x`` resized (bilinear, corners aligned, as RAFT) to ``like``'s height and width."""
    return F.interpolate(x, like.shape[2:], mode="bilinear", align_corners=True)


class MultiLevelUpdate(nn.Module):
    """Three GRU levels (hidden sizes finest first). ``forward`` updates all levels coarse to
    fine and returns (hidden states, disparity update B×1×h×w in pixels, mask logits)."""

    def __init__(self, hidden: Sequence[int], corr_channels: int, motion_dim: int, factor: int) -> None:
        super().__init__()
        h0, h1, h2 = hidden
        self.motion = MotionEncoder(corr_channels, motion_dim, motion_dim)
        self.gru0 = ConvGRU(h0, motion_dim + h1)
        self.gru1 = ConvGRU(h1, h0 + h2)
        self.gru2 = ConvGRU(h2, h1)
        self.disp_head = nn.Sequential(nn.Conv2d(h0, 2 * h0, 3, padding=1), nn.ReLU(inplace=True),
                                       nn.Conv2d(2 * h0, 1, 3, padding=1))
        self.mask = MaskHead(h0, factor)

    def forward(self, net: list[Tensor], context: list[Sequence[Tensor]], corr: Tensor,
                disparity: Tensor, *, with_mask: bool = True) -> tuple[list[Tensor], Tensor, Tensor | None]:
        net2 = self.gru2(net[2], context[2], pool2x(net[1]))
        net1 = self.gru1(net[1], context[1], pool2x(net[0]), resize_like(net2, net[1]))
        net0 = self.gru0(net[0], context[0], self.motion(corr, disparity), resize_like(net1, net[0]))
        mask = self.mask(net0) if with_mask else None
        return [net0, net1, net2], self.disp_head(net0), mask
