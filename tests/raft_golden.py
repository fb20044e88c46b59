"""Full-width weights in the layout of RAFT-Stereo's published checkpoints, regenerated from a seed.

RAFT-Stereo's widths are fixed (hidden 128, features 256, …), so its golden fixtures
(tests/fixtures/raft_stereo/) store a key/shape list and a seed rather than megabytes of weights;
:func:`raft_state` turns them back into the state dict the fixtures' reference outputs were computed
with. Scales keep 32 GRU iterations finite: convolutions kaiming-like (std √(1/fan-in)), small biases,
the flow head's output smaller (HEAD_GAIN: disparities of a few px) or larger (``head_gain``, the wide
fixtures': hundreds of px), batch norm near identity or far from it (``far_statistics``). RAFT-Stereo's
``norm3`` is the same module as ``downsample.1`` in its residual blocks, so the two share values.

Only torch is needed: the project holds none of RAFT-Stereo's code.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

FIXTURES = Path(__file__).parent / "fixtures" / "raft_stereo"
# The flow head's last layer, scaled down: 32 updates of unit scale carry the disparity off the
# image, where the correlation lookup reads only zeros and would go untested.
HEAD_GAIN = 0.1


def shared_key(name: str) -> str:
    """The key whose values ``name`` shares: a residual block's ``norm3`` is its ``downsample.1``."""
    return name.replace(".norm3.", ".downsample.1.")


def raft_state(keys: Sequence[tuple[str, Sequence[int]]], seed: int, *, head: str = ".flow_head.conv2.",
               head_gain: float = HEAD_GAIN, far_statistics: bool = False) -> dict[str, torch.Tensor]:
    """The state dict for ``keys`` ((name, shape) in file order) and ``seed``; ``head``: the key part of
    the layer scaled by ``head_gain`` (Selective-RAFT's ``.disp_head.conv2.``; a larger gain, larger GRU updates:
    disparities of hundreds of pixels); ``far_statistics``: batch
    norm far from identity (running means ~N(0, 0.5²), variances log-uniform in [1/4, 4], scales
    ~N(1, 0.3²), shifts ~N(0, 0.2²)), so that a network that skipped or misread them would show."""
    generator = torch.Generator().manual_seed(seed)

    def normal(shape: Sequence[int], std: float, mean: float = 0.0) -> torch.Tensor:
        return mean + std * torch.randn(tuple(shape), generator=generator, dtype=torch.float32)

    def value(canonical: str, leaf: str, shape: Sequence[int]) -> torch.Tensor:
        if leaf == "running_mean":
            return normal(shape, 0.5 if far_statistics else 0.1)
        if leaf == "running_var":
            return (4.0 ** (2 * torch.rand(tuple(shape), generator=generator) - 1) if far_statistics
                    else 1.0 + 0.2 * torch.rand(tuple(shape), generator=generator))
        if len(shape) == 4:
            fan_in = shape[1] * shape[2] * shape[3]
            gain = head_gain if head in canonical else 1.0
            return normal(shape, gain * (1.0 / fan_in) ** 0.5)
        if leaf == "weight":  # a norm's affine scale
            return normal(shape, 0.3 if far_statistics else 0.1, 1.0)
        if far_statistics and (".norm" in canonical or canonical.endswith("downsample.1.bias")):
            return normal(shape, 0.2)  # a norm's affine shift
        return normal(shape, 0.02)

    return seeded_state(keys, value)


def seeded_state(keys: Sequence[tuple[str, Sequence[int]]],
                 value: Callable[[str, str, Sequence[int]], torch.Tensor]) -> dict[str, torch.Tensor]:
    """The state dict for ``keys`` ((name, shape) in file order): each value drawn, in that order, by
    ``value(key, its last part, shape)`` where the key first appears (a ``norm3`` key takes its block's
    ``downsample.1`` values, :func:`shared_key`); batch counters 0."""
    values: dict[str, torch.Tensor] = {}
    state = {}
    for name, shape in keys:
        canonical = shared_key(name)
        if canonical not in values:
            leaf = canonical.rsplit(".", 1)[-1]
            values[canonical] = (torch.tensor(0, dtype=torch.int64) if leaf == "num_batches_tracked"
                                 else value(canonical, leaf, shape))
        state[name] = values[canonical].clone()
    return state


def load_fixture(name: str, directory: Path = FIXTURES) -> dict[str, Any]:
    """One architecture's fixture in ``directory``: its JSON (flags, seed, keys, iterations) with the npz
    arrays (``disparity`` float32 H×W, the reference's output; ``left``, ``right`` uint8 H×W×3 unless
    the JSON names the pair, see :func:`motorcycle_pair`) added."""
    with open(directory / f"{name}.json", encoding="utf-8") as handle:
        fixture = json.load(handle)
    with np.load(directory / f"{name}.npz") as arrays:
        fixture.update({key: arrays[key] for key in arrays.files})
    if fixture.get("pair") == "motorcycle":
        fixture["left"], fixture["right"] = motorcycle_pair(fixture["stride"], fixture.get("rows"))
    return fixture


def fixture_state(fixture: dict[str, Any]) -> dict[str, torch.Tensor]:
    """The fixture's weights, keys as in a published file (``module.`` prefixed)."""
    return raft_state([(key, shape) for key, shape in fixture["keys"]], fixture["seed"], **fixture.get("weights", {}))


def motorcycle_pair(stride: int, rows: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """scikit-image's Middlebury 2014 Motorcycle pair (741×500, shipped in its wheel: no download), every
    ``stride``-th pixel (plain slicing, no resampling library's rounding): a real pair, uint8 H×W×3.
    Stride 3 gives 167×247, sides that are not multiples of 32; ``rows`` (first, count) keeps only those
    rows: a strip as wide as the pair at a fraction of its cost."""
    import skimage.data

    left, right, _ = skimage.data.stereo_motorcycle()
    first, count = rows if rows is not None else (0, left.shape[0])
    return (np.ascontiguousarray(left[::stride, ::stride, :3][first:first + count]),
            np.ascontiguousarray(right[::stride, ::stride, :3][first:first + count]))
