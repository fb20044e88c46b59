"""Right-view synthesis (Algorithm 2): scale search, z-buffered splatting, holes, inpainting."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.geometry import (
    InpaintError,
    InputError,
    ScaleSearchError,
    forward_warp,
    search_disparity_scale,
    synthesize_right_view,
)
from core.geometry.benchmark import reference_scale, reference_splat
from core.geometry.right_view import MAX_DISPARITY_FRACTION
from dataset.synthetic import render_video


def _valid_ratio(disparity: np.ndarray, s: float) -> float:
    target = np.arange(disparity.shape[1]) - s * disparity.astype(np.float32)
    return float(np.mean((target >= 0) & (target < disparity.shape[1])))


def _textured(h: int, w: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


# --- scale search ----------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    tau=st.floats(0.5, 0.99),
    width=st.integers(8, 120),
    height=st.integers(1, 20),
)
def test_scale_is_the_largest_that_keeps_tau_in_view(seed: int, tau: float, width: int, height: int) -> None:
    rng = np.random.default_rng(seed)
    disparity = rng.uniform(0.01, 1.0, (height, width)).astype(np.float32)
    if tau > 1 - 1 / width:
        # Column 0 leaves the image for any s > 0 when d > 0.
        with pytest.raises(ScaleSearchError, match="cannot|can stay"):
            search_disparity_scale(disparity, tau)
        return
    s = search_disparity_scale(disparity, tau)
    cap = width * MAX_DISPARITY_FRACTION / disparity.max()
    assert 0 < s <= cap * (1 + 1e-9)
    assert _valid_ratio(disparity, s) >= tau
    if s < cap * (1 - 1e-6):
        # Converged: a hair more and the ratio drops below tau.
        assert _valid_ratio(disparity, s * (1 + 1e-5)) < tau


def test_scale_matches_a_converged_bisection() -> None:
    disparity = np.random.default_rng(0).uniform(0.1, 1.0, (50, 400))
    s = search_disparity_scale(disparity, 0.9)
    low, high = 0.0, 400 / (4 * disparity.max())
    while high - low > 1e-9:
        mid = (low + high) / 2
        low, high = (mid, high) if _valid_ratio(disparity, mid) >= 0.9 else (low, mid)
    assert s == pytest.approx(low, rel=1e-5)


def test_unreachable_tau_is_an_error() -> None:
    disparity = np.ones((10, 10))
    disparity[:, :2] = np.nan  # 20% of the pixels can never land in the image
    with pytest.raises(ScaleSearchError, match="at most 80.0% can stay"):
        search_disparity_scale(disparity, 0.9)
    with pytest.raises(ScaleSearchError, match="no positive value"):
        search_disparity_scale(np.zeros((4, 4)), 0.9)
    with pytest.raises(InputError, match="tau"):
        search_disparity_scale(np.ones((4, 4)), 1.5)


# --- splatting -------------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(shift=st.one_of(st.integers(0, 12).map(float), st.floats(0.0, 12.0)), seed=st.integers(0, 2**16))
def test_constant_disparity_is_a_pure_shift(shift: float, seed: int) -> None:
    width = 40
    left = _textured(6, width, seed)
    result = synthesize_right_view(left, np.full((6, width), shift), scale=1.0, inpaint="none")
    k = int(np.floor(shift + 0.5))  # each pixel takes its nearest source: round half up
    np.testing.assert_array_equal(result.image[:, : width - k], left[:, k:])
    # Past the last source's reach, nothing landed: holes, left black.
    reach = int(np.ceil(width - 1 - shift))
    np.testing.assert_array_equal(result.holes, np.broadcast_to(np.arange(width) > reach, (6, width)))
    assert (result.image[result.holes] == 0).all()


def test_largest_disparity_wins() -> None:
    left = np.zeros((1, 12), dtype=np.uint8)
    left[0, 3] = 50  # background: d = 1 lands on column 2
    left[0, 8] = 200  # foreground: d = 6 lands on column 2 too
    disparity = np.zeros((1, 12))
    disparity[0, 3], disparity[0, 8] = 1.0, 6.0
    warped, holes, _ = forward_warp(left, disparity, 1.0)
    assert warped[0, 2] == 200 and not holes[0, 2]
    # The other way round in the row order: the left source is the nearer one.
    left2 = np.zeros((1, 12), dtype=np.uint8)
    left2[0, 4], left2[0, 5] = 200, 50
    disparity2 = np.zeros((1, 12))
    disparity2[0, 4], disparity2[0, 5] = 2.4, 0.8  # targets 1.6 and 4.2: no overlap
    disparity2[0, 6] = 3.7  # target 2.3 shares column 2 with the source at 4 (d 2.4)
    left2[0, 6] = 99
    warped2, _, _ = forward_warp(left2, disparity2, 1.0)
    assert warped2[0, 2] == 99  # d = 3.7 beats d = 2.4 on column 2


def _brute_force_warp(left: np.ndarray, disparity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per target pixel: the source with the largest disparity, ties to the nearer one."""
    height, width = disparity.shape
    best: dict[tuple[int, int], tuple[float, float, int]] = {}
    for v in range(height):
        for u in range(width):
            x = u - disparity[v, u]
            for p in {int(np.floor(x)), int(np.ceil(x))}:
                if 0 <= p < width:
                    key = (disparity[v, u], -abs(x - p), u)
                    if (v, p) not in best or key > best[(v, p)]:
                        best[(v, p)] = key
    image = np.zeros_like(left)
    holes = np.ones((height, width), dtype=bool)
    for (v, p), (_, _, u) in best.items():
        image[v, p] = left[v, u]
        holes[v, p] = False
    return image, holes


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_splat_matches_a_brute_force_z_buffer(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Disparities on a 1 px grid plus one offset per row (integral, half or any): two sources
    # either tie or differ by ≥ 1 px, where the z-buffer rule is unambiguous.
    offsets = rng.choice([0.0, 0.5, rng.uniform(0, 1)], size=(4, 1))
    disparity = rng.integers(0, 6, (4, 24)) + offsets
    left = _textured(4, 24, seed)
    warped, holes, _ = forward_warp(left, disparity, 1.0)
    expected_image, expected_holes = _brute_force_warp(left, disparity)
    np.testing.assert_array_equal(holes, expected_holes)
    np.testing.assert_array_equal(warped, expected_image)


def test_matches_the_reference_implementation() -> None:
    rng = np.random.default_rng(5)
    left = _textured(30, 200)
    disparity = rng.uniform(0.05, 1.0, (30, 200))
    s = search_disparity_scale(disparity, 0.9)
    assert s == pytest.approx(reference_scale(disparity, 0.9), rel=1e-5)
    # Integer disparities: one target per source and no ties, so the z-buffer winner is unique.
    integral = rng.integers(0, 40, (30, 200)).astype(np.float64)
    warped, _, _ = forward_warp(left, integral, 1.0)
    np.testing.assert_array_equal(warped, reference_splat(left, integral, 1.0))


def test_nan_disparities_are_not_warped() -> None:
    left = _textured(3, 10)
    disparity = np.ones((3, 10))
    disparity[1, 4] = np.nan
    warped, holes, ratio = forward_warp(left, disparity, 1.0)
    assert holes[1, 3]  # only the NaN source would have landed there
    assert ratio == pytest.approx(26 / 30)


# --- inpainting and the public entry point ----------------------------------------------------


@pytest.mark.parametrize("method", ["telea", "ns"])
def test_inpainting_fills_only_the_holes(method: str) -> None:
    left = np.tile(np.linspace(0, 255, 64, dtype=np.uint8)[None, :, None], (32, 1, 3))
    disparity = np.full((32, 64), 2.0)
    disparity[8:24, 20:30] = 8.0  # a box in front: disocclusion holes to its right
    result = synthesize_right_view(left, disparity, scale=1.0, inpaint=method)
    bare = synthesize_right_view(left, disparity, scale=1.0, inpaint="none")
    assert result.holes.any()
    np.testing.assert_array_equal(result.holes, bare.holes)
    np.testing.assert_array_equal(result.image[~result.holes], bare.image[~bare.holes])
    assert (result.image[result.holes] > 0).all()  # filled from the gradient around


def test_scale_search_is_used_without_scale() -> None:
    left = _textured(20, 100)
    disparity = np.random.default_rng(1).uniform(0.2, 1.0, (20, 100))
    result = synthesize_right_view(left, disparity, tau=0.8, inpaint="none")
    assert result.scale == pytest.approx(search_disparity_scale(disparity, 0.8))
    assert result.valid_ratio >= 0.8


@pytest.mark.parametrize(
    ("left", "disparity", "kwargs", "error", "message"),
    [
        (np.zeros((4, 5, 3), np.uint8), np.ones((4, 6)), {}, InputError, "4x5"),
        (np.zeros((4, 5, 3), np.float32), np.ones((4, 5)), {}, InputError, "uint8"),
        (np.zeros((4, 5, 4), np.uint8), np.ones((4, 5)), {}, InputError, "HxWx3"),
        (np.zeros((4, 5, 3), np.uint8), np.full((4, 5), np.nan), {}, InputError, "no finite value"),
        (np.zeros((4, 5, 3), np.uint8), np.ones((4, 5)), {"scale": -1.0}, InputError, "scale"),
        (np.zeros((4, 5, 3), np.uint8), np.ones((4, 5)), {"inpaint": "magic"}, InpaintError, "unknown inpainting"),
        (np.zeros((4, 5, 3), np.uint8), np.ones((4, 5)), {"inpaint": "lama"}, InpaintError, "LaMa is a model"),
    ],
)
def test_bad_input_is_rejected(
    left: np.ndarray, disparity: np.ndarray, kwargs: dict, error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        synthesize_right_view(left, disparity, **kwargs)


# --- accuracy on the synthetic illusion scenes (dataset.synthetic) -----------------------


def _psnr(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    mse = np.mean((a[where].astype(float) - b[where].astype(float)) ** 2)
    return float(10 * np.log10(255**2 / mse))


def test_right_view_from_true_disparity_matches_the_rendered_one() -> None:
    """Warping the left view with the true disparity (s = 1) reproduces the exactly rendered
    right view on non-hole pixels at ≥ 33 dB PSNR (measured: 35.3–37.3 dB on seeds 0–3).

    Why 33 dB: nearest-source splatting is off by up to half a pixel, so the result cannot
    be exact; the same warp with the disparity off by just 0.5 px scores 30–31.5 dB and the
    unwarped left image ~20–21 dB. 33 dB therefore certifies sub-half-pixel registration,
    and the test also checks the margin over the 0.5 px-error warp directly.
    """
    for seed in range(2):
        frame = render_video(seed, n_frames=1).frames[0]
        exact = synthesize_right_view(frame.left, frame.disparity, scale=1.0, inpaint="none")
        off = synthesize_right_view(frame.left, frame.disparity + 0.5, scale=1.0, inpaint="none")
        psnr = _psnr(exact.image, frame.right, ~exact.holes)
        assert exact.holes.mean() < 0.05
        assert psnr >= 33.0, psnr
        assert psnr >= _psnr(off.image, frame.right, ~off.holes) + 3.0
