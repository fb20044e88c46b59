"""Weights in the layout of Selective-IGEV's published checkpoints, regenerated from a seed.

The golden fixture (tests/fixtures/selective_igev/) stores a key/shape list and a seed rather than the
network's 12 M weights; :func:`igev_state` turns them back into the state dict the fixture's reference
output was computed with. Scales keep 32 refinements finite and the disparity inside the cost
volume (the fixture's output spans 87–160 px): convolutions kaiming-like (std √(1/fan-in)), small biases, and
batch norms far from the identity — affine scales 0.5–1.5, shifts ±0.3, running means ±0.5 and
variances 0.3–3 — so that a norm run in training mode (batch statistics) gives another output. The
context encoder's ``norm3`` is the same module as its block's ``downsample.1``: the two share values.

Only torch is needed: the project holds none of Selective-IGEV's code.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tests import raft_golden
from tests.raft_golden import seeded_state

FIXTURES = Path(__file__).parent / "fixtures" / "selective_igev"


def igev_state(keys: Sequence[tuple[str, Sequence[int]]], seed: int) -> dict[str, torch.Tensor]:
    """The state dict for ``keys`` ((name, shape) in file order) and ``seed``."""
    generator = torch.Generator().manual_seed(seed)

    def uniform(shape: Sequence[int], low: float, high: float) -> torch.Tensor:
        return low + (high - low) * torch.rand(tuple(shape), generator=generator)

    def value(canonical: str, leaf: str, shape: Sequence[int]) -> torch.Tensor:
        if leaf == "running_mean":
            return uniform(shape, -0.5, 0.5)
        if leaf == "running_var":
            return torch.exp(uniform(shape, -1.2, 1.1))  # 0.3 … 3
        if len(shape) >= 3:  # a convolution's weights
            fan_in = int(np.prod(shape[1:]))
            if ".conv_dw." in canonical:  # depthwise: one input channel per output
                fan_in = int(np.prod(shape[2:]))
            return (1.0 / fan_in) ** 0.5 * torch.randn(tuple(shape), generator=generator)
        if leaf == "weight":  # a norm's affine scale
            return uniform(shape, 0.5, 1.5)
        if ".bn" in canonical or ".norm" in canonical or "downsample.1." in canonical:
            return uniform(shape, -0.3, 0.3)  # a norm's shift
        return 0.02 * torch.randn(tuple(shape), generator=generator)

    return seeded_state(keys, value)


def load_fixture(name: str) -> dict[str, Any]:
    """The fixture ``name``: its JSON (flags, seed, keys, iterations, crop) with the npz arrays (``left``,
    ``right`` uint8 H×W×3, ``disparity`` float32 H×W, the reference's output) added."""
    return raft_golden.load_fixture(name, FIXTURES)


def fixture_state(fixture: dict[str, Any]) -> dict[str, torch.Tensor]:
    """The fixture's weights, keys as in a published file (``module.`` prefixed)."""
    return igev_state([(key, shape) for key, shape in fixture["keys"]], fixture["seed"])
