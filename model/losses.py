"""The training loss (paper appendix "Loss"): L = L_d + w·L_c.

L_d = Σ_t γ^(T+2−t)·|D_s^t − D_G|₁ + γ·|D̃_m − D_G|₁ + |D_f − D_G|₁, with γ adjusted as the
authors' code does, γ^(15/(T−1)) for T > 1 (γ itself for T = 1). L_c is the focal loss on I_c,
α_c·(1 − e^(−L_b))^γ_c·L_b with L_b the binary cross entropy against
1[bilinear-downsampled |D_G − D_s^T| < 1.25] at the confidence map's resolution (the authors'
target, ``train.confidence_target = "threshold"``). ``"closer"`` (``lite``) trusts the stereo also
where it is no farther from D_G than the aligned mono D̃_m: the threshold alone sends every pixel
the stereo misses by 1.25 px to the mono, which a coarse relative estimate misses by more.
``"closer-fit"`` compares it with the mono fitted to the stereo per image (one scale and shift) instead
of D̃_m, whose per-pixel affine can copy the stereo. ``train.confidence_loss = "ce"`` uses the plain
cross entropy L_b times ``ce_weight`` instead of the focal term: the final L1 pulls the logits through
the blend by about |D̃_m − D_s|·c(1−c) per pixel — 5–10× the focal term's push outside mirrors and
~1000× inside them — and at c ≈ 0.84 the focal factor leaves ~1/55 of L_b's gradient.

Only valid pixels with ground truth below ``max_disparity`` count. Every term is a SUM over
this rank's pixels divided by ``valid_total``, the valid-pixel count summed over all ranks (the
focal term's by that count times the area ratio of the confidence map to the image), so the
loss is a global mean whatever the split across ranks. DDP averages gradients over ranks, so a
trainer with world size N multiplies this loss by N (or sums gradients) to get the gradient of
the global mean: 2 ranks × B/2 then give the gradient of 1 rank × B.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from model.network import FusionOutput
from model.presets import TrainConfig

CONFIDENT_ERROR_PX = 1.25  # full-resolution pixels: the confidence target's threshold


def sequence_gamma(gamma: float, iterations: int) -> float:
    """The authors' adjusted γ: γ^(15/(T−1)) for T > 1, γ for T = 1."""
    return gamma ** (15 / (iterations - 1)) if iterations > 1 else gamma


def confidence_target(error: Tensor, valid: Tensor, size: tuple[int, int],
                      mono_error: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """(target, valid) at ``size``: the full-resolution |D_G − D_s^T| (B×1×H×W pixels, invalid
    pixels ignored) downsampled bilinearly, < 1.25 → 1; with ``mono_error`` (|D_G − D̃_m|, alike)
    also 1 where the stereo is no farther from the truth than the aligned mono. A low-resolution
    pixel is valid where most of what it samples is."""
    valid_f = valid.float()
    weight = F.interpolate(valid_f, size, mode="bilinear", align_corners=False)

    def low(full: Tensor) -> Tensor:
        return F.interpolate(full * valid_f, size, mode="bilinear", align_corners=False) / weight.clamp_min(1e-6)

    stereo_error = low(error)
    confident = stereo_error < CONFIDENT_ERROR_PX
    if mono_error is not None:
        confident |= stereo_error <= low(mono_error)
    return confident.float(), weight > 0.5


def focal_terms(logits: Tensor, target: Tensor, alpha: float, gamma: float) -> Tensor:
    """Per pixel α·(1 − e^(−L_b))^γ·L_b, L_b the binary cross entropy of σ(logits) against target."""
    bce = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return alpha * (1 - torch.exp(-bce)) ** gamma * bce


def confidence_terms(logits: Tensor, target: Tensor, cfg: TrainConfig) -> Tensor:
    """Per pixel confidence loss, weighted: the focal term (``focal_weight``) or, with
    ``confidence_loss = "ce"``, the binary cross entropy times ``ce_weight``."""
    if cfg.confidence_loss == "ce":
        return cfg.ce_weight * F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return cfg.focal_weight * focal_terms(logits, target, cfg.focal_alpha, cfg.focal_gamma)


def _mono_error(out: FusionOutput, gt: Tensor, cfg: TrainConfig) -> Tensor | None:
    """|D_G − mono| for the "closer" targets (B×1×H×W pixels), None for "threshold": the aligned mono
    D̃_m ("closer"), or the mono fitted to the stereo per image ("closer-fit"). D̃_m's per-pixel affine
    sees D_s and can copy it where the confidence is high, and then the stereo always looks no farther
    from the truth than the mono: the target would keep trusting a stereo fooled by a mirror."""
    if cfg.confidence_target == "threshold":
        return None
    mono = out.mono_aligned if cfg.confidence_target == "closer" else out.mono_fitted
    if mono is None:
        raise ValueError("train.confidence_target = 'closer-fit' needs the network's fitted mono")
    return (gt - mono.detach()).abs()


def fusion_loss(out: FusionOutput, gt: Tensor, valid: Tensor, cfg: TrainConfig, *,
                valid_total: Tensor | None = None) -> tuple[Tensor, dict[str, float]]:
    """(scalar loss, parts) for ``gt`` B×1×H×W pixels and ``valid`` bool B×1×H×W. Parts:
    "stereo", "mono_aligned", "final", "confidence" (each already weighted), "total", "epe"
    (of the final disparity, over this batch's valid pixels), "valid" (this batch's count). A stereo-only
    output (model.use_mono off) is trained on its iterates alone: the other terms are 0."""
    if gt.shape != out.disparity.shape or valid.shape != gt.shape:
        raise ValueError(f"gt and valid must be {tuple(out.disparity.shape)}, got {tuple(gt.shape)}, {tuple(valid.shape)}")
    mask = valid.bool() & torch.isfinite(gt) & (gt < cfg.max_disparity)
    gt = torch.where(mask, gt, torch.zeros_like(gt))
    count = mask.sum()
    total = (count if valid_total is None else valid_total).to(gt.dtype).clamp_min(1)
    maskf = mask.to(gt.dtype)

    def l1(pred: Tensor) -> Tensor:
        return ((pred - gt).abs() * maskf).sum() / total

    iterates = out.stereo_iterates
    steps = len(iterates)
    gamma = sequence_gamma(cfg.loss_gamma, steps)
    stereo = sum(gamma ** (steps + 2 - t) * l1(pred) for t, pred in enumerate(iterates, start=1))
    if out.stereo_only:  # RAFT-Stereo's sequence loss alone: nothing else is predicted
        mono = final = confidence = torch.zeros((), dtype=gt.dtype, device=gt.device)
    else:
        mono = gamma * l1(out.mono_aligned)
        final = l1(out.disparity)
        size = out.confidence_logits.shape[2:]
        error = (gt - out.stereo.detach()).abs()
        mono_error = _mono_error(out, gt, cfg)
        target, valid_low = confidence_target(error, mask, size, mono_error)
        area = (size[0] * size[1]) / (gt.shape[2] * gt.shape[3])
        terms = confidence_terms(out.confidence_logits, target, cfg)
        confidence = (terms * valid_low).sum() / (total * area)
    loss = stereo + mono + final + confidence
    with torch.no_grad():
        epe = ((out.disparity - gt).abs() * maskf).sum() / count.clamp_min(1)
    named = {"stereo": stereo, "mono_aligned": mono, "final": final, "confidence": confidence, "total": loss,
             "epe": epe, "valid": count}
    parts = {name: float(value.detach()) for name, value in named.items()}
    return loss, parts
