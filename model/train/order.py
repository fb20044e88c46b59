"""The order training reads samples in, and every seed that depends on it.

Training reads an endless stream: epoch e is a permutation of the sample indices drawn from
``(seed, e)``, epochs follow one another, and step s (0-based) takes the global batch at stream
positions ``[s·B, (s+1)·B)``. The position is a pure function of the step, so a resumed run
reads exactly what the uninterrupted one would have, and each rank takes a contiguous share of
the global batch, so 2 ranks × B/2 read the same samples as 1 rank × B. Each sample's
augmentation and flow noise come from generators seeded by ``(seed, epoch, index)``, never from
a process-wide RNG, so they too are independent of the world size.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# Distinct first words keep the streams of permutations, augmentation and noise apart.
_PERMUTATION, _AUGMENT, _NOISE, _VALIDATION = 0, 1, 2, 3


@dataclass(frozen=True)
class SampleKey:
    """One read of one sample: its index in the reader and the epoch it is read in."""

    epoch: int
    index: int


@lru_cache(maxsize=4)
def epoch_permutation(n: int, seed: int, epoch: int) -> np.ndarray:
    """The sample indices 0..n-1 in epoch ``epoch``'s order (int64, (n,))."""
    return np.random.default_rng([_PERMUTATION, seed, epoch]).permutation(n)


def global_batch(step: int, batch_size: int, n: int, seed: int) -> list[SampleKey]:
    """The ``batch_size`` reads of 0-based step ``step`` over ``n`` samples."""
    if n < 1:
        raise ValueError("the training split has no samples")
    keys = []
    for position in range(step * batch_size, (step + 1) * batch_size):
        epoch, offset = divmod(position, n)
        keys.append(SampleKey(epoch, int(epoch_permutation(n, seed, epoch)[offset])))
    return keys


def rank_share(keys: list[SampleKey], rank: int, world_size: int) -> list[SampleKey]:
    """Rank ``rank``'s contiguous share of a global batch (its size must divide evenly)."""
    if len(keys) % world_size:
        raise ValueError(f"batch_size {len(keys)} is not divisible by the {world_size} processes")
    share = len(keys) // world_size
    return keys[rank * share:(rank + 1) * share]


def data_position(step: int, batch_size: int, n: int) -> dict[str, int]:
    """Where the stream stands before 0-based step ``step`` (for checkpoints and people)."""
    position = step * batch_size
    return {"position": position, "epoch": position // n, "offset": position % n}


def augment_rng(seed: int, key: SampleKey) -> np.random.Generator:
    """The generator of one read's augmentation (colour, scale, crop)."""
    return np.random.default_rng([_AUGMENT, seed, key.epoch, key.index])


def noise_seed(seed: int, key: SampleKey) -> int:
    """The seed of one read's flow noise generator (a torch.Generator)."""
    return _seed([_NOISE, seed, key.epoch, key.index])


def validation_noise_seed(seed: int, index: int) -> int:
    """The flow noise seed of validation sample ``index``: the same at every validation."""
    return _seed([_VALIDATION, seed, index])


def _seed(words: list[int]) -> int:
    # 63 bits: torch.Generator.manual_seed takes any int below 2**64; keep it positive.
    return int(np.random.SeedSequence(words).generate_state(1, np.uint64)[0] >> np.uint64(1))
