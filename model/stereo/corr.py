"""The 1D correlation pyramid: dot products of left and right features along each row, pooled
over the right image's x into ``levels`` levels, looked up in a window of ±radius around the
current disparity."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor


class CorrPyramid1D:
    """All-pairs 1D correlation of B×D×h×w features; ``lookup(disparity)`` gives
    B×(levels·(2·radius+1))×h×w. Disparities are positive pixels at the features' resolution:
    left x matches right x − d. Positions outside the right image correlate as 0."""

    def __init__(self, left: Tensor, right: Tensor, *, levels: int, radius: int) -> None:
        batch, dim, height, width = left.shape
        volume = torch.einsum("bdhx,bdhy->bhxy", left.float(), right.float()) / math.sqrt(dim)
        volume = volume.reshape(batch * height * width, 1, 1, width)
        self.levels, self.radius, self.shape = levels, radius, (batch, height, width)
        self.pyramid = [volume]
        for _ in range(levels - 1):
            volume = F.avg_pool2d(volume, (1, 2), stride=(1, 2))
            self.pyramid.append(volume)

    @property
    def channels(self) -> int:
        return self.levels * (2 * self.radius + 1)

    def lookup(self, disparity: Tensor) -> Tensor:
        """Correlations around ``disparity`` (B×1×h×w, pixels at this resolution)."""
        batch, height, width = self.shape
        x = torch.arange(width, device=disparity.device, dtype=torch.float32).view(1, 1, 1, width)
        target = (x - disparity.float()).permute(0, 2, 3, 1).reshape(-1, 1, 1, 1)  # (B·h·w)×1×1×1
        offsets = torch.arange(-self.radius, self.radius + 1, device=disparity.device, dtype=torch.float32)
        out = []
        for level, volume in enumerate(self.pyramid):
            positions = target / 2**level + offsets.view(1, 1, -1, 1)
            size = volume.shape[-1]
            grid_x = 2 * positions / max(size - 1, 1) - 1
            grid = torch.cat([grid_x, torch.zeros_like(grid_x)], dim=-1)
            sampled = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=True)
            out.append(sampled.view(batch, height, width, -1))
        return torch.cat(out, dim=-1).permute(0, 3, 1, 2).contiguous()
