"""The confidence map (paper section 4, "Confidence Map Generation"): a flow from Gaussian noise
to a latent confidence state, K Euler steps y ← y + (1/K)·v(y, k, c_e), the velocity from a
stack of transformer blocks (time embedding by adaptive norm, self-attention over the state's
tokens, cross-attention to the VLM condition c_e); the final state, reshaped to 2D, is decoded
to the stereo working resolution (the role of the paper's VAE decoder), concatenated with the
cost volume sampled around the stereo disparity, and convolutions with a sigmoid give I_c.

It trains end to end through the K unrolled steps. With ``flow_noise`` off the flow starts from zeros
instead of noise: a deterministic flow, whose final state the condition alone decides. With
``use_vlm`` off the flow is skipped and the decoder input is the left view's matching features (the
paper's "PF" ablation); with ``confidence_image_features`` (``lite``) the head sees those features
beside the flow's state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor, nn

from model.presets import ModelConfig
from model.vlm import VlmResult, sincos_2d


def time_embedding(k: Tensor, dim: int) -> Tensor:
    """B k∈[0, 1] → B×dim sinusoidal features."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=k.device, dtype=torch.float32) / half)
    angles = 1000.0 * k.float().view(-1, 1) * freqs
    return nn.functional.pad(torch.cat([angles.sin(), angles.cos()], dim=1), (0, dim - 2 * half))


class FlowBlock(nn.Module):
    """DiT-style block: time-modulated self-attention, cross-attention to the condition, MLP."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, elementwise_affine=False)
        self.attn = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.norm2 = nn.LayerNorm(dim)
        self.cross = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.norm3 = nn.LayerNorm(dim, elementwise_affine=False)
        self.mlp = nn.Sequential(nn.Linear(dim, 4 * dim), nn.GELU(), nn.Linear(4 * dim, dim))
        self.modulation = nn.Linear(dim, 6 * dim)
        # Near-zero modulation: each block starts close to a plain pre-norm block (DiT's adaLN-zero,
        # kept slightly off zero so the time embedding gets gradients from the first step).
        nn.init.normal_(self.modulation.weight, std=1e-3)
        nn.init.zeros_(self.modulation.bias)

    def forward(self, x: Tensor, t: Tensor, condition: Tensor) -> Tensor:
        shift1, scale1, gate1, shift2, scale2, gate2 = self.modulation(t).unsqueeze(1).chunk(6, dim=-1)
        h = self.norm1(x) * (1 + scale1) + shift1
        x = x + (1 + gate1) * self.attn(h, h, h, need_weights=False)[0]
        x = x + self.cross(self.norm2(x), condition, condition, need_weights=False)[0]
        h = self.norm3(x) * (1 + scale2) + shift2
        return x + (1 + gate2) * self.mlp(h)


class VelocityField(nn.Module):
    """v(y, k, c_e): B×N×latent state on an h×w token grid → B×N×latent velocity."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        dim = config.flow_dim
        self.dim = dim
        self.inp = nn.Linear(config.flow_latent, dim)
        self.time = nn.Sequential(nn.Linear(dim, dim), nn.SiLU(), nn.Linear(dim, dim))
        self.blocks = nn.ModuleList(FlowBlock(dim, config.flow_heads) for _ in range(config.flow_depth))
        self.norm = nn.LayerNorm(dim)
        self.out = nn.Linear(dim, config.flow_latent)

    def forward(self, y: Tensor, k: Tensor, condition: Tensor, grid: tuple[int, int]) -> Tensor:
        x = self.inp(y) + sincos_2d(*grid, self.dim, y.device)
        t = self.time(time_embedding(k, self.dim))
        for block in self.blocks:
            x = block(x, t, condition)
        return self.out(self.norm(x))


def gaussian_noise(shape: tuple[int, ...], noise: torch.Generator | Sequence[torch.Generator] | None,
                   device: torch.device) -> Tensor:
    """B×… standard normal noise: from one generator for the batch, one generator per sample
    (so a sample's noise does not depend on its batch), or the global RNG when None."""
    if noise is None:
        return torch.randn(shape, device=device)
    if isinstance(noise, torch.Generator):
        return torch.randn(shape, generator=noise, device=noise.device).to(device)
    generators = list(noise)
    if len(generators) != shape[0]:
        raise ValueError(f"noise: {len(generators)} generators for a batch of {shape[0]}")
    return torch.cat([torch.randn((1, *shape[1:]), generator=g, device=g.device).to(device) for g in generators])


class Decoder(nn.Module):
    """B×in×h×w at 1/2**token_downsample → B×out×H/2**n×W/2**n: ×2 upsampling + convs per octave."""

    def __init__(self, in_channels: int, out_channels: int, octaves: int) -> None:
        super().__init__()
        layers: list[nn.Module] = [nn.Conv2d(in_channels, out_channels, 3, padding=1), nn.ReLU(inplace=True)]
        for _ in range(octaves):
            layers += [nn.Upsample(scale_factor=2, mode="bilinear", align_corners=False),
                       nn.Conv2d(out_channels, out_channels, 3, padding=1), nn.ReLU(inplace=True)]
        self.net = nn.Sequential(*layers)

    def forward(self, x: Tensor) -> Tensor:
        return self.net(x)


class ConfidenceHead(nn.Module):
    """I_c = σ(F_c([G_c(y'_1), V(D_s)])) at the stereo working resolution."""

    def __init__(self, config: ModelConfig, condition_dim: int) -> None:
        super().__init__()
        self.use_vlm, self.steps, self.noisy = config.use_vlm, config.flow_steps, config.flow_noise
        self.token_factor = 2 ** (config.token_downsample - config.n_downsample)
        dim = config.confidence_dim
        # Image features beside the flow's state: the decoder of the no-VLM network (named as there),
        # or a second input of the VLM network's head with ``confidence_image_features``.
        self.image: nn.Module | None = None
        if self.use_vlm:
            self.connector = nn.Linear(condition_dim, config.flow_dim)
            self.velocity = VelocityField(config)
            self.latent = config.flow_latent
            self.decoder = Decoder(config.flow_latent, dim, config.token_downsample - config.n_downsample)
            if config.confidence_image_features:
                self.image = _feature_encoder(config.feature_dim, dim)
        else:
            self.decoder = _feature_encoder(config.feature_dim, dim)
        self.sees_mono = config.confidence_sees_mono
        inputs = (dim * (2 if self.image is not None else 1) + config.corr_levels * (2 * config.corr_radius + 1)
                  + (len(MONO_VIEW) if self.sees_mono else 0))
        self.head = nn.Sequential(nn.Conv2d(inputs, dim, 3, padding=1), nn.ReLU(inplace=True),
                                  nn.Conv2d(dim, dim, 3, padding=1), nn.ReLU(inplace=True),
                                  nn.Conv2d(dim, 1, 1))

    def flow(self, vlm: VlmResult, grid: tuple[int, int],
             noise: torch.Generator | Sequence[torch.Generator] | None) -> Tensor:
        """The K Euler steps from y_0 ~ N(0, I) (zeros without ``flow_noise``; B×h·w×latent) to y_1,
        reshaped to B×latent×h×w."""
        condition = self.connector(torch.cat([vlm.tokens, vlm.prompt], dim=1))
        batch = condition.shape[0]
        shape = (batch, grid[0] * grid[1], self.latent)
        y = gaussian_noise(shape, noise, condition.device) if self.noisy else condition.new_zeros(shape)
        for i in range(self.steps):
            k = torch.full((batch,), i / self.steps, device=y.device)
            y = y + self.velocity(y, k, condition, grid) / self.steps
        return y.transpose(1, 2).reshape(batch, self.latent, *grid)

    def forward(self, cost: Tensor, *, vlm: VlmResult | None = None, features: Tensor | None = None,
                noise: torch.Generator | Sequence[torch.Generator] | None = None,
                disparities: tuple[Tensor, Tensor] | None = None) -> Tensor:
        """Confidence logits B×1×h×w. ``cost``: B×corr×h×w correlations sampled around D_s;
        ``vlm`` (use_vlm) and/or ``features`` (B×feature_dim×h×w left matching features: without
        the VLM, or with ``confidence_image_features``); ``disparities`` (``confidence_sees_mono``):
        D_s and the mono fitted to it, B×1×h×w working-resolution pixels each (:func:`mono_view`)."""
        height, width = cost.shape[2:]
        if self.use_vlm:
            assert vlm is not None
            grid = (height // self.token_factor, width // self.token_factor)
            decoded = [self.decoder(self.flow(vlm, grid, noise))]
            if self.image is not None:
                assert features is not None
                decoded.append(self.image(features))
        else:
            assert features is not None
            decoded = [self.decoder(features)]
        if self.sees_mono:
            if disparities is None:
                raise ValueError("model.confidence_sees_mono: the confidence head needs D_s and the fitted mono")
            decoded.append(mono_view(*disparities))
        return self.head(torch.cat([*decoded, cost], dim=1))


MONO_VIEW = ("stereo", "fitted", "difference")  # the channels of mono_view


def mono_view(stereo: Tensor, fitted: Tensor) -> Tensor:
    """B×3×h×w: D_s, the fitted mono and D_s minus it (B×1×h×w pixels each, no gradient back into them),
    each over the image's stereo spread (its standard deviation, at least 1 px): scale-free, as the
    fusion's own inputs are."""
    stereo, fitted = stereo.detach(), fitted.detach()
    spread = stereo.flatten(1).std(1).view(-1, 1, 1, 1).clamp_min(1.0)
    return torch.cat([stereo, fitted, stereo - fitted], dim=1) / spread


def _feature_encoder(in_channels: int, out_channels: int) -> nn.Module:
    return nn.Sequential(nn.Conv2d(in_channels, out_channels, 3, padding=1), nn.ReLU(inplace=True))
