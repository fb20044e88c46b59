"""Global fusion (paper section 4, "Global Fusion"): per-pixel affine parameters s_m, t_m align
the mono disparity D_m to the stereo disparity D_s; where the confidence I_c < 0.5 they are
replaced by a confidence-weighted pooling of confident neighbours (the image's confident mean
where no neighbour is confident); D̃_m = s_m·D_m + t_m; [D̃_m, D_s, I_c] → convolutions and
convex upsampling → the final disparity.

``fusion_rule = "released"`` is the authors' released rule instead: unconfident (a, b) become
the global confident mean and D = c·D_s + (1−c)·(a·D_m + b), upsampled with the stereo
branch's convex mask. ``fusion_gate`` replaces the blend by a hard gate with the blend's gradient
(:func:`blend`). Everything here is at the working resolution, disparities in its pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.presets import ModelConfig
from model.stereo.upsample import MaskHead, convex_upsample


@dataclass
class FusionResult:
    disparity: Tensor  # B×1×H×W final disparity, full-resolution pixels
    scale: Tensor  # B×1×h×w s_m (working-resolution pixels per unit of normalised D_m)
    shift: Tensor  # B×1×h×w t_m (working-resolution pixels)


def least_squares_affine(mono: Tensor, stereo: Tensor) -> tuple[Tensor, Tensor]:
    """Per image (s, t) = argmin Σ (s·mono + t − stereo)² (the paper's alignment), B×1×1×1 each."""
    m, d = mono.flatten(1), stereo.flatten(1)
    m_mean, d_mean = m.mean(1, keepdim=True), d.mean(1, keepdim=True)
    var = ((m - m_mean) ** 2).mean(1, keepdim=True)
    s = ((m - m_mean) * (d - d_mean)).mean(1, keepdim=True) / var.clamp_min(1e-6)
    t = d_mean - s * m_mean
    return s.view(-1, 1, 1, 1), t.view(-1, 1, 1, 1)


def confident_mean(values: Tensor, weight: Tensor) -> Tensor:
    """Per image weighted mean of B×C×h×w ``values`` (B×C×1×1); the plain mean where the
    weights sum to zero (no confident pixel)."""
    total = weight.sum((2, 3), keepdim=True)
    weighted = (values * weight).sum((2, 3), keepdim=True) / total.clamp_min(1e-6)
    return torch.where(total > 1e-6, weighted, values.mean((2, 3), keepdim=True))


def refine_affine(params: Tensor, confidence: Tensor, *, kernel: int | None) -> Tensor:
    """B×C×h×w parameters with the pixels of confidence < 0.5 replaced: by the confidence-weighted
    mean over confident pixels of the ``kernel``×``kernel`` neighbourhood (falling back to the
    image's confident mean where there are none), or by the image's confident mean (``kernel``
    None, the released rule)."""
    confident = confidence >= 0.5
    weight = confidence * confident
    fallback = confident_mean(params, weight).expand_as(params)
    if kernel is None:
        pooled = fallback
    else:
        pad = kernel // 2
        mass = F.avg_pool2d(weight, kernel, stride=1, padding=pad, count_include_pad=True)
        local = F.avg_pool2d(params * weight, kernel, stride=1, padding=pad, count_include_pad=True)
        pooled = torch.where(mass > 1e-6, local / mass.clamp_min(1e-6), fallback)
    return torch.where(confident, params, pooled)


def blend(stereo: Tensor, aligned: Tensor, confidence: Tensor, *, gate: bool) -> Tensor:
    """c·D_s + (1−c)·D̃_m (B×1×h×w each); with ``gate`` the value is D_s where c ≥ 0.5 and D̃_m
    elsewhere, each branch's gradient flowing only where it was chosen, and the confidence's gradient
    the soft blend's, D_s − D̃_m (straight-through): training still tells the confidence which way to
    move, but a pixel stereo gets right is never pulled towards a mono that errs on its side."""
    if not gate:
        return confidence * stereo + (1 - confidence) * aligned
    hard = torch.where(confidence >= 0.5, stereo, aligned)
    return hard + (confidence - confidence.detach()) * (stereo - aligned).detach()


class GlobalFusion(nn.Module):
    """Fuses D_m (normalised, B×1×h×w) and D_s (B×1×h×w pixels) under I_c (B×1×h×w)."""

    def __init__(self, config: ModelConfig, hidden_channels: int) -> None:
        super().__init__()
        dim = config.fusion_dim
        self.rule, self.kernel, self.gate = config.fusion_rule, config.fusion_pool_kernel, config.fusion_gate
        self.factor, self.border = 2**config.n_downsample, config.upsample_border
        # Convolutions on [D_m, D_s] (and the least-squares fit) predict s_m, t_m as corrections to the
        # per-image least-squares solution, in units of the image's disparity spread: ≈ 0 at start.
        self.affine = nn.Sequential(nn.Conv2d(3, dim, 3, padding=1), nn.ReLU(inplace=True),
                                    nn.Conv2d(dim, dim, 3, padding=1), nn.ReLU(inplace=True),
                                    nn.Conv2d(dim, 2, 3, padding=1))
        _near_zero(self.affine[-1])
        if self.rule == "paper":
            self.fuse = nn.Sequential(nn.Conv2d(3 + hidden_channels, dim, 3, padding=1), nn.ReLU(inplace=True),
                                      nn.Conv2d(dim, dim, 3, padding=1), nn.ReLU(inplace=True))
            self.residual = nn.Conv2d(dim, 1, 3, padding=1)
            _near_zero(self.residual)
            self.mask = MaskHead(dim, self.factor)
            self.mask_from_stereo = config.fusion_mask_from_stereo
            if self.mask_from_stereo:
                _near_zero(self.mask.net[-1])

    def forward(self, mono: Tensor, stereo: Tensor, confidence: Tensor, hidden: Tensor,
                stereo_mask: Tensor) -> FusionResult:
        """``hidden``: the finest GRU state (B×C×h×w); ``stereo_mask``: its convex-upsampling logits."""
        s0, t0 = least_squares_affine(mono, stereo)
        spread = stereo.detach().flatten(1).std(1).view(-1, 1, 1, 1).clamp_min(1.0)
        fitted = s0 * mono + t0
        delta = self.affine(torch.cat([mono, stereo / spread, fitted / spread], dim=1)) * spread
        params = torch.cat([s0 + delta[:, :1], t0 + delta[:, 1:]], dim=1)
        params = refine_affine(params, confidence, kernel=self.kernel if self.rule == "paper" else None)
        scale, shift = params[:, :1], params[:, 1:]
        aligned = scale * mono + shift
        blended = blend(stereo, aligned, confidence, gate=self.gate)
        if self.rule == "released":
            return FusionResult(convex_upsample(blended, stereo_mask, self.factor, self.border), scale, shift)
        features = self.fuse(torch.cat([aligned / spread, stereo / spread, confidence, hidden], dim=1))
        low = blended + self.residual(features) * spread
        mask = self.mask(features) + (stereo_mask if self.mask_from_stereo else 0)
        return FusionResult(convex_upsample(low, mask, self.factor, self.border), scale, shift)


def _near_zero(conv: nn.Conv2d) -> None:
    """Start a correction head at ≈ 0 (slightly off, so layers before it get gradients at once)."""
    nn.init.normal_(conv.weight, std=1e-3)
    nn.init.zeros_(conv.bias)
