"""augment_pair: deterministic from its generator, crop shapes with padding, disparity scaled with the image."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from dataset.readers.base import Camera, StereoSample, make_regions
from model.augment import augment_pair


@dataclass(frozen=True)
class Cfg:  # the fields of TrainConfig that augmentation reads
    scale: tuple[float, float] = (-0.2, 0.4)
    saturation: tuple[float, float] = (0.0, 1.4)
    color_jitter: bool = True


def pair(h: int = 40, w: int = 64) -> StereoSample:
    rng = np.random.default_rng(5)
    x = np.arange(w, dtype=np.float32)
    disparity = np.tile(4.0 + 0.25 * x, (h, 1))  # a ramp: d(x) = 4 + x/4
    disparity[:5, :7] = np.nan
    left = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    illusion = np.zeros((h, w), bool)
    illusion[20:, 30:] = True
    return StereoSample("s", left, left[:, ::-1].copy(), disparity, make_regions(disparity, {"illusion": illusion}),
                        mono=np.tile(x / w, (h, 1)), camera=Camera(100.0, 0.1))


def test_same_generator_same_sample_and_views_jittered_alike() -> None:
    a = augment_pair(pair(), (32, 48), Cfg(), np.random.default_rng(1))
    b = augment_pair(pair(), (32, 48), Cfg(), np.random.default_rng(1))
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert np.array_equal(a.disparity, b.disparity, equal_nan=True) and a.meta["augment"] == b.meta["augment"]
    c = augment_pair(pair(), (32, 48), Cfg(), np.random.default_rng(2))
    assert c.meta["augment"] != a.meta["augment"]
    # one jitter for both views: a pair whose views are equal stays equal
    same = pair()
    same.right[:] = same.left
    out = augment_pair(same, (32, 48), Cfg(), np.random.default_rng(3))
    assert np.array_equal(out.left, out.right) and not np.array_equal(out.left, same.left[:32, :48])


@pytest.mark.parametrize("seed", range(6))
def test_shapes_and_validity(seed: int) -> None:
    out = augment_pair(pair(), (32, 48), Cfg(), np.random.default_rng(seed))
    assert out.left.shape == out.right.shape == (32, 48, 3) and out.left.dtype == np.uint8
    assert out.disparity.shape == out.mono.shape == (32, 48) and out.disparity.dtype == np.float32
    assert np.array_equal(out.regions["all"], np.isfinite(out.disparity))
    assert not (out.regions["illusion"] & ~out.regions["all"]).any()


def test_padding_where_the_pair_is_smaller_than_the_crop() -> None:
    out = augment_pair(pair(20, 30), (64, 96), Cfg(scale=(0.0, 0.0), color_jitter=False), np.random.default_rng(0))
    assert out.left.shape == (64, 96, 3) and out.meta["augment"]["crop_origin"] == [0, 0]
    assert (out.left[20:] == 0).all() and (out.left[:, 30:] == 0).all()
    assert np.isnan(out.disparity[20:]).all() and np.isnan(out.disparity[:, 30:]).all()
    assert np.array_equal(out.left[:20, :30], pair(20, 30).left)  # no scale, no jitter: the pixels unchanged


@pytest.mark.parametrize("log2_scale", [-0.2, 0.4])
def test_disparity_scales_with_the_image(log2_scale: float) -> None:
    cfg = Cfg(scale=(log2_scale, log2_scale), color_jitter=False)
    out = augment_pair(pair(), (24, 32), cfg, np.random.default_rng(4))
    s = out.meta["augment"]["scale"]
    assert s == pytest.approx(2**log2_scale)
    y0, x0 = out.meta["augment"]["crop_origin"]
    # the ramp d(x) = 4 + x/4 becomes s·d(x/s) = 4s + x/4 at scaled column x (pixel centres)
    cols = x0 + np.arange(32)
    src = (cols + 0.5) / s - 0.5
    expected = s * (4.0 + 0.25 * src)
    valid = out.regions["all"][-1]
    inner = valid & (src > 1) & (src < 62)
    assert np.allclose(out.disparity[-1][inner], expected[inner], atol=0.05)
    assert out.camera.fx == pytest.approx(100.0 * s)


def test_nan_stays_invalid_after_resizing() -> None:
    sample = pair()
    out = augment_pair(sample, (48, 76), Cfg(scale=(0.25, 0.25), color_jitter=False), np.random.default_rng(0))
    y0, x0 = out.meta["augment"]["crop_origin"]
    assert y0 == 0 and x0 == 0  # the scaled pair is 47×76: one place to crop
    hole = ~out.regions["all"]
    assert hole[:5, :7].all() and not hole[8:].any() and not hole[:, 10:].any()


def test_the_source_window_gives_the_pixels_of_warping_the_whole_pair() -> None:
    sample = pair(40, 64)
    for seed in range(4):
        out = augment_pair(sample, (16, 24), Cfg(color_jitter=False), np.random.default_rng(seed))
        s, (y0, x0) = out.meta["augment"]["scale"], out.meta["augment"]["crop_origin"]
        whole = np.array([[1 / s, 0, (x0 + 0.5) / s - 0.5], [0, 1 / s, (y0 + 0.5) / s - 0.5]])
        reference = cv2.warpAffine(sample.left, whole, (24, 16), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        assert np.array_equal(out.left, reference)
