"""The on-disk embedding cache: keys, LRU eviction within the budget, atomic concurrent writes."""

from __future__ import annotations

import hashlib
import multiprocessing
import os
from pathlib import Path

import numpy as np
import pytest

from annotation.segment import EmbeddingCache, cached_embedding, image_sha256, make_segmenter


def sha(n: int) -> str:
    return hashlib.sha256(str(n).encode()).hexdigest()


def age(cache: EmbeddingCache, key: str, model: str, seconds_ago: float) -> None:
    """Make an entry look last used ``seconds_ago`` (deterministic LRU order without sleeping)."""
    path = cache.path(key, model)
    when = path.stat().st_mtime - seconds_ago
    os.utime(path, (when, when))


def test_put_get_keyed_by_content_and_model(tmp_path: Path) -> None:
    cache = EmbeddingCache(tmp_path, budget_bytes=1 << 20)
    assert cache.get(sha(1), "m1") is None
    cache.put(sha(1), "m1", b"one")
    cache.put(sha(1), "sam2:dir/with:colons", b"other model")
    assert cache.get(sha(1), "m1") == b"one"
    assert cache.get(sha(1), "sam2:dir/with:colons") == b"other model"
    assert cache.get(sha(2), "m1") is None
    cache.put(sha(1), "m1", b"replaced")
    assert cache.get(sha(1), "m1") == b"replaced"
    assert cache.usage() == len(b"replaced") + len(b"other model")
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.parametrize("bad", ["", "abc", sha(1).upper(), "../" + sha(1)[3:], sha(1)[:-1] + "g"])
def test_rejects_keys_that_are_not_sha256(tmp_path: Path, bad: str) -> None:
    with pytest.raises(ValueError, match="64 lowercase hex"):
        EmbeddingCache(tmp_path, 100).get(bad, "m")


def test_evicts_least_recently_used_beyond_budget(tmp_path: Path) -> None:
    cache = EmbeddingCache(tmp_path, budget_bytes=300)
    for n in range(3):
        cache.put(sha(n), "m", bytes(100))
        age(cache, sha(n), "m", 100 - n)  # 0 oldest, 2 newest
    assert cache.get(sha(0), "m") is not None  # a hit makes 0 the most recent
    cache.put(sha(3), "m", bytes(100))  # 400 > 300: the least recent (1) goes
    assert cache.get(sha(1), "m") is None
    assert all(cache.get(sha(n), "m") is not None for n in (0, 2, 3))
    assert cache.usage() == 300
    cache.put(sha(4), "m", bytes(1000))  # larger than the whole budget: everything goes
    assert cache.usage() == 0


def test_stale_temporary_files_are_cleaned(tmp_path: Path) -> None:
    cache = EmbeddingCache(tmp_path, budget_bytes=1000)
    cache.put(sha(1), "m", b"x")
    stale = cache.path(sha(1), "m").with_name(".dead-writer.tmp")
    stale.write_bytes(b"partial")
    os.utime(stale, (1, 1))
    cache.put(sha(2), "m", b"y")
    assert not stale.exists()


def _writer(root: str, worker: int) -> None:
    cache = EmbeddingCache(Path(root), budget_bytes=20_000)
    rng = np.random.default_rng(worker)
    for n in range(40):
        key = sha(n % 25)  # workers overlap on keys
        cache.put(key, "m", key.encode() * int(rng.integers(10, 40)))
        data = cache.get(sha(int(rng.integers(25))), "m")
        assert data is None or (len(data) % 64 == 0 and data[:64] in {sha(k).encode() for k in range(25)})


def test_concurrent_writers_keep_entries_whole_and_budget(tmp_path: Path) -> None:
    ctx = multiprocessing.get_context("spawn")
    workers = [ctx.Process(target=_writer, args=(str(tmp_path), w)) for w in range(4)]
    for p in workers:
        p.start()
    for p in workers:
        p.join(60)
    assert [p.exitcode for p in workers] == [0, 0, 0, 0]
    cache = EmbeddingCache(tmp_path, budget_bytes=20_000)
    cache.put(sha(99), "m", b"final")  # one last eviction pass after the race
    assert 0 < cache.usage() <= 20_000
    for path in tmp_path.rglob("*.emb"):
        data = path.read_bytes()
        key = path.stem.encode()
        assert data == b"final" or data == key * (len(data) // 64)
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]


def test_cached_embedding_encodes_once_and_survives_damage(tmp_path: Path) -> None:
    segmenter = make_segmenter("classical")
    cache = EmbeddingCache(tmp_path, budget_bytes=50_000_000)
    image = np.zeros((60, 80, 3), np.uint8)
    image[10:40, 20:60] = 200
    first, hit = cached_embedding(segmenter, cache, image)
    assert not hit
    second, hit = cached_embedding(segmenter, cache, image)
    assert hit and second.to_bytes() == first.to_bytes()
    cache.path(image_sha256(image), segmenter.model_id).write_bytes(b"damaged")
    third, hit = cached_embedding(segmenter, cache, image)
    assert not hit and third.to_bytes() == first.to_bytes()


def test_image_hash_sees_shape_dtype_and_pixels() -> None:
    a = np.zeros((4, 6, 3), np.uint8)
    b = a.copy()
    b[0, 0, 0] = 1
    assert len({image_sha256(a), image_sha256(b), image_sha256(a.reshape(6, 4, 3)),
                image_sha256(a.astype(np.uint16))}) == 4
    assert image_sha256(a) == image_sha256(a.copy())
