"""Convex upsampling (RAFT): each full-resolution pixel is a softmax-weighted mix of the 3×3
coarse neighbours around it, the weights predicted per pixel by a small head."""

from __future__ import annotations

from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn


class MaskHead(nn.Module):
    """B×C×h×w features → B×(9·factor²)×h×w upsampling weights (logits, scaled down by 4 to
    balance gradients as RAFT does), through ``width`` hidden channels (default 2·C)."""

    def __init__(self, channels: int, factor: int, width: int | None = None) -> None:
        super().__init__()
        width = width or 2 * channels
        self.net = nn.Sequential(nn.Conv2d(channels, width, 3, padding=1), nn.ReLU(inplace=True),
                                 nn.Conv2d(width, 9 * factor * factor, 1))

    def forward(self, x: Tensor) -> Tensor:
        return 0.25 * self.net(x)


Border = Literal["edge", "zeros"]


def convex_upsample(disparity: Tensor, mask: Tensor, factor: int, border: Border = "edge") -> Tensor:
    """B×1×h×w disparity (pixels at 1/factor) → B×1×(h·factor)×(w·factor), pixels at full
    resolution (values × factor). Past the image border the 3×3 window sees the edge value
    (``edge``, replicated) or 0 (``zeros``, as RAFT, whose zero padding pulls the outer ``factor``
    pixels of each side towards 0: what RAFT-Stereo's published weights were trained with)."""
    batch, _, height, width = disparity.shape
    weights = torch.softmax(mask.view(batch, 1, 9, factor, factor, height, width), dim=2)
    edged = F.pad(factor * disparity, (1, 1, 1, 1), mode="replicate" if border == "edge" else "constant")
    patches = F.unfold(edged, (3, 3)).view(batch, 1, 9, 1, 1, height, width)
    up = (weights * patches).sum(dim=2)  # B×1×f×f×h×w
    return up.permute(0, 1, 4, 2, 5, 3).reshape(batch, 1, factor * height, factor * width)


def upsample_bilinear(x: Tensor, factor: int) -> Tensor:
    """B×C×h×w → B×C×(h·factor)×(w·factor), values unchanged (for maps that are not disparities)."""
    return F.interpolate(x, scale_factor=factor, mode="bilinear", align_corners=False)
