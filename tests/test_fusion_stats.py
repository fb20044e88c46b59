"""The fusion benchmark's intervals and per-pixel gate sums (benchmarks.fusion_stats): a bootstrap over
scenes and seeds that decides a real difference either way, leaves no difference undecided, and gains no
power from repeating a scene's frames."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import fusion_stats as stats


def _differences(effect: float, scenes: int = 100, frames: int = 2, seeds: int = 3, noise: float = 0.3,
                 seed: int = 0) -> tuple[np.ndarray, list[int]]:
    """Per-frame differences (seeds, scenes x frames): ``effect`` plus a scene's own offset (shared by its
    frames and seeds) plus a little per-frame noise."""
    rng = np.random.default_rng(seed)
    per_scene = rng.normal(effect, noise, scenes)
    values = np.repeat(per_scene, frames)[None, :] + rng.normal(0, 0.02, (seeds, scenes * frames))
    return values, [s for s in range(scenes) for _ in range(frames)]


@pytest.mark.parametrize(("effect", "verdict"), [(-0.2, "lower"), (0.2, "higher"), (0.0, "undecided")])
def test_a_real_difference_is_decided_either_way_and_none_is_not(effect: float, verdict: str) -> None:
    values, scenes = _differences(effect)
    found = stats.mean_interval(values, scenes)
    assert found["low"] < found["value"] < found["high"]
    assert found["value"] == pytest.approx(np.mean(values))
    assert stats.decided(found) == verdict
    assert found["high"] - found["low"] == pytest.approx(2 * 1.96 * 0.3 / 10, rel=0.25)  # ~ the scenes' standard error


def test_repeating_a_scenes_frames_buys_no_power() -> None:
    """The unit is the scene: ten copies of each frame leave the interval as wide as one."""
    values, scenes = _differences(0.05, frames=1)
    once = stats.mean_interval(values, scenes)
    tenfold = stats.mean_interval(np.repeat(values, 10, axis=1), [s for s in scenes for _ in range(10)])
    assert tenfold["high"] - tenfold["low"] == pytest.approx(once["high"] - once["low"], rel=0.05)
    # while treating every frame as its own scene would claim far more certainty than there is
    as_frames = stats.mean_interval(np.repeat(values, 10, axis=1), list(range(10 * len(scenes))))
    assert as_frames["high"] - as_frames["low"] < 0.5 * (once["high"] - once["low"])


def test_seeds_that_disagree_widen_the_interval() -> None:
    values, scenes = _differences(0.1, seeds=1)
    agreeing = np.repeat(values, 3, axis=0)
    disagreeing = agreeing + np.array([[-0.3], [0.0], [0.3]])
    narrow, wide = (stats.mean_interval(v, scenes) for v in (agreeing, disagreeing))
    assert wide["value"] == pytest.approx(narrow["value"])
    assert wide["high"] - wide["low"] > 2 * (narrow["high"] - narrow["low"])


def test_frames_without_the_region_are_left_out_and_shapes_must_match() -> None:
    values = np.array([[1.0, np.nan, 3.0, np.nan]])
    assert stats.mean_interval(values, [0, 0, 1, 1])["value"] == 2.0
    assert np.isnan(stats.mean_interval(np.full((1, 2), np.nan), [0, 1])["value"])
    with pytest.raises(ValueError, match="do not match"):
        stats.bootstrap_ratio(np.ones((1, 3)), np.ones((1, 3)), [0, 1])


def test_the_interval_is_reproducible() -> None:
    values, scenes = _differences(0.1)
    assert stats.mean_interval(values, scenes) == stats.mean_interval(values, scenes)


def test_region_figures_and_gate_sums_per_pixel() -> None:
    truth = np.full((2, 3), 10.0)
    prediction = np.array([[10.5, 13.0, np.nan], [10.0, 9.0, 12.5]])
    errors = stats.frame_errors(prediction, truth)
    assert errors.tolist() == [[0.5, 3.0, 10.0], [0.0, 1.0, 2.5]]  # a missing prediction counts as 0 px
    where = np.array([[True, True, False], [True, True, True]])
    figures = stats.region_figures(errors, where)
    assert figures == {"epe": pytest.approx(1.4), "bad2": pytest.approx(40.0), "pixels": 5}
    assert stats.region_figures(errors, np.zeros((2, 3), bool))["pixels"] == 0

    stereo, mono, fused = np.array([4.0, 1.0, 3.0]), np.array([1.0, 2.0, 3.0]), np.array([2.0, 1.0, 3.0])
    sums = stats.gate_sums(stereo, fused, mono, np.ones(3, bool))
    # the oracle takes 1 + 1 + 3; only the first pixel has headroom (3 px), of which the gate took 2
    assert sums == {"oracle": 5.0, "headroom": 3.0, "gain": 2.0}
    assert stats.bootstrap_ratio(np.array([[2.0]]), np.array([[3.0]]), [0])["value"] == pytest.approx(2 / 3)
    assert "gain" not in stats.gate_sums(stereo, None, mono, np.ones(3, bool))
