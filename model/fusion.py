"""Global fusion (paper section 4, "Global Fusion"): per-pixel affine parameters s_m, t_m align
the mono disparity D_m to the stereo disparity D_s; where the confidence I_c < 0.5 they are
replaced by a confidence-weighted pooling of confident neighbours (the image's confident mean
where no neighbour is confident); D̃_m = s_m·D_m + t_m; [D̃_m, D_s, I_c] → convolutions and
upsampling → the final disparity.

The per-pixel parameters are corrections to one robust fit per image (iteratively reweighted
least squares of Eq. 3's objective), not to the plain least-squares one: illusions are exactly
where D_m and D_s disagree, and a plain fit lets them tilt the alignment of every other pixel.

The final disparity is blended at full resolution, D = g·D_s + (1−g)·D̃_m + r, with the gate g =
σ(logit I_c + a learned correction) and a learned residual r, both from the convolutions at the
working resolution. Blending at the working resolution and upsampling (the released rule) would
throw away the detail that the full-resolution D_m carries.

``fusion_rule = "released"`` is the authors' released rule instead: unconfident (a, b) become
the global confident mean and D = c·D_s + (1−c)·(a·D_m + b), upsampled with the stereo
branch's convex mask. Disparities are in working-resolution pixels unless said otherwise.
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
    aligned: Tensor  # B×1×H×W D̃_m = s_m·D_m + t_m, full-resolution pixels
    scale: Tensor  # B×1×h×w s_m (working-resolution pixels per unit of normalised D_m)
    shift: Tensor  # B×1×h×w t_m (working-resolution pixels)


def least_squares_affine(mono: Tensor, stereo: Tensor, weight: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """Per image (s, t) = argmin Σ w·(s·mono + t − stereo)² (the paper's alignment; w = 1 by
    default), B×1×1×1 each, for B×1×h×w inputs."""
    m, d = mono.flatten(1), stereo.flatten(1)
    w = torch.ones_like(m) if weight is None else weight.flatten(1)
    w = w / w.sum(1, keepdim=True).clamp_min(1e-6)
    m_mean, d_mean = (w * m).sum(1, keepdim=True), (w * d).sum(1, keepdim=True)
    var = (w * (m - m_mean) ** 2).sum(1, keepdim=True)
    s = (w * (m - m_mean) * (d - d_mean)).sum(1, keepdim=True) / var.clamp_min(1e-6)
    t = d_mean - s * m_mean
    return s.view(-1, 1, 1, 1), t.view(-1, 1, 1, 1)


def robust_affine(mono: Tensor, stereo: Tensor, *, iterations: int = 3,
                  min_scale: float = 0.25) -> tuple[Tensor, Tensor]:
    """(s, t) per image by iteratively reweighted least squares with Cauchy weights
    1 / (1 + (r / 2σ)²), σ = 1.4826·median |r| (at least ``min_scale`` pixels): pixels where mono
    and stereo disagree (illusions, occlusions) stop pulling the fit. The weights are not
    differentiated; the final weighted fit is."""
    s, t = least_squares_affine(mono, stereo)
    for _ in range(iterations):
        with torch.no_grad():
            residual = (s * mono + t - stereo).abs()
            sigma = 1.4826 * residual.flatten(1).median(1).values.view(-1, 1, 1, 1)
            weight = 1 / (1 + (residual / (2 * sigma.clamp_min(min_scale))) ** 2)
        s, t = least_squares_affine(mono, stereo, weight)
    return s, t


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


class GlobalFusion(nn.Module):
    """Fuses the normalised D_m (B×1×H×W) and D_s (B×1×h×w working-resolution pixels, and its
    upsampled B×1×H×W) under the confidence logits (B×1×h×w)."""

    def __init__(self, config: ModelConfig, hidden_channels: int) -> None:
        super().__init__()
        dim = config.fusion_dim
        self.rule, self.kernel = config.fusion_rule, config.fusion_pool_kernel
        self.factor = 2**config.n_downsample
        # Convolutions on [D_m, D_s] (and the robust fit) predict s_m, t_m as corrections to the
        # per-image robust solution, in units of the image's disparity spread: ≈ 0 at start.
        self.affine = nn.Sequential(nn.Conv2d(3, dim, 3, padding=1), nn.ReLU(inplace=True),
                                    nn.Conv2d(dim, dim, 3, padding=1), nn.ReLU(inplace=True),
                                    nn.Conv2d(dim, 2, 3, padding=1))
        _near_zero(self.affine[-1])
        if self.rule == "paper":
            self.fuse = nn.Sequential(nn.Conv2d(4 + hidden_channels, dim, 3, padding=1), nn.ReLU(inplace=True),
                                      nn.Conv2d(dim, dim, 3, padding=1), nn.ReLU(inplace=True))
            # Channel 0 corrects the gate's logit, channel 1 is the residual; both start at ≈ 0,
            # so an untrained fusion is the confidence-weighted blend.
            self.heads = nn.Conv2d(dim, 2, 3, padding=1)
            _near_zero(self.heads)
            self.mask = MaskHead(dim, self.factor)

    def forward(self, mono: Tensor, stereo: Tensor, stereo_full: Tensor, confidence_logits: Tensor,
                hidden: Tensor, stereo_mask: Tensor) -> FusionResult:
        """``hidden``: the finest GRU state (B×C×h×w); ``stereo_mask``: its convex-upsampling logits."""
        confidence = torch.sigmoid(confidence_logits)
        mono_low = F.avg_pool2d(mono, self.factor)
        s0, t0 = robust_affine(mono_low, stereo)
        spread = stereo.detach().flatten(1).std(1).view(-1, 1, 1, 1).clamp_min(1.0)
        fitted = s0 * mono_low + t0
        delta = self.affine(torch.cat([mono_low, stereo / spread, fitted / spread], dim=1)) * spread
        params = torch.cat([s0 + delta[:, :1], t0 + delta[:, 1:]], dim=1)
        params = refine_affine(params, confidence, kernel=self.kernel if self.rule == "paper" else None)
        scale, shift = params[:, :1], params[:, 1:]
        full = mono.shape[2:]
        aligned = self.factor * (_resize(scale, full) * mono + _resize(shift, full))
        if self.rule == "released":
            blend = confidence * stereo + (1 - confidence) * (scale * mono_low + shift)
            return FusionResult(convex_upsample(blend, stereo_mask, self.factor), aligned, scale, shift)
        aligned_low = scale * mono_low + shift
        features = self.fuse(torch.cat([aligned_low / spread, stereo / spread, (aligned_low - stereo) / spread,
                                        confidence, hidden], dim=1))
        gate_delta, residual = self.heads(features).chunk(2, dim=1)
        gate = torch.sigmoid(_resize(confidence_logits + gate_delta, full))
        correction = convex_upsample(residual * spread, self.mask(features), self.factor)
        return FusionResult(gate * stereo_full + (1 - gate) * aligned + correction, aligned, scale, shift)


def _resize(x: Tensor, size: tuple[int, int]) -> Tensor:
    """Bilinear resize of a B×C×h×w map (values unchanged: not for disparities)."""
    return F.interpolate(x, size, mode="bilinear", align_corners=False)


def _near_zero(conv: nn.Conv2d) -> None:
    """Start a correction head at ≈ 0 (slightly off, so layers before it get gradients at once)."""
    nn.init.normal_(conv.weight, std=1e-3)
    nn.init.zeros_(conv.bias)
