"""The training data order: a pure function of (seed, step), shared out across ranks."""

from __future__ import annotations

import numpy as np
import pytest

from model.train.order import (
    SampleKey,
    augment_rng,
    data_position,
    epoch_permutation,
    global_batch,
    noise_seed,
    rank_share,
    validation_noise_seed,
)


def test_epochs_are_permutations_and_the_stream_visits_each_sample_once_per_epoch() -> None:
    n, batch = 7, 3
    keys = [k for step in range(7) for k in global_batch(step, batch, n, seed=5)]  # 21 reads = 3 epochs
    for epoch in range(3):
        assert sorted(k.index for k in keys if k.epoch == epoch) == list(range(n))
        assert [k.index for k in keys if k.epoch == epoch] == list(epoch_permutation(n, 5, epoch))
    assert list(epoch_permutation(n, 5, 0)) != list(epoch_permutation(n, 5, 1))
    assert list(epoch_permutation(n, 5, 0)) != list(epoch_permutation(n, 6, 0))


def test_a_step_reads_the_same_samples_whatever_came_before_and_more_than_an_epoch_fits() -> None:
    assert global_batch(11, 4, 5, seed=1) == global_batch(11, 4, 5, seed=1)
    big = global_batch(0, 5, 2, seed=0)  # batch larger than the split: epochs 0, 1 and part of 2
    assert [k.epoch for k in big] == [0, 0, 1, 1, 2]
    assert len({(k.epoch, k.index) for k in big}) == 5  # no read repeats its (epoch, index)
    with pytest.raises(ValueError, match="no samples"):
        global_batch(0, 2, 0, seed=0)


def test_ranks_share_out_the_global_batch_contiguously() -> None:
    keys = global_batch(3, 6, 10, seed=2)
    shares = [rank_share(keys, r, 3) for r in range(3)]
    assert [k for share in shares for k in share] == keys and all(len(s) == 2 for s in shares)
    with pytest.raises(ValueError, match="batch_size 6 is not divisible by the 4 processes"):
        rank_share(keys, 0, 4)


def test_data_position() -> None:
    assert data_position(7, 3, 5) == {"position": 21, "epoch": 4, "offset": 1}


def test_seeds_depend_on_the_read_only() -> None:
    a, b = SampleKey(1, 4), SampleKey(2, 4)
    assert np.array_equal(augment_rng(9, a).random(4), augment_rng(9, a).random(4))
    assert not np.array_equal(augment_rng(9, a).random(4), augment_rng(9, b).random(4))
    seeds = {noise_seed(9, SampleKey(e, i)) for e in range(3) for i in range(5)}
    assert len(seeds) == 15 and all(0 <= s < 2**63 for s in seeds)
    assert noise_seed(9, a) == noise_seed(9, a) != noise_seed(8, a)
    assert validation_noise_seed(9, 0) == validation_noise_seed(9, 0) != validation_noise_seed(9, 1)
