"""RANSAC plane fitting in (u, v, d) space (Algorithm 1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.geometry import DegenerateSupportError, InputError, fit_plane_ransac


def _plane_points(rng: np.random.Generator, n: int, outliers: float, noise: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Points of d = 0.4 + 1e-4·u − 2e-4·v (a 640x480 frame, d normalised), some replaced by outliers."""
    u = rng.uniform(0, 640, n)
    v = rng.uniform(0, 480, n)
    d = 0.4 + 1e-4 * u - 2e-4 * v + rng.normal(0, noise, n) if noise else 0.4 + 1e-4 * u - 2e-4 * v
    is_outlier = rng.random(n) < outliers
    d = np.where(is_outlier, rng.random(n), d)
    return np.column_stack([u, v, d]), ~is_outlier


def _unit(params: np.ndarray) -> np.ndarray:
    params = np.asarray(params, dtype=float)
    params = params / np.linalg.norm(params[:3])
    return params * np.sign(params[2])


TRUE_PLANE = _unit(np.array([1e-4, -2e-4, -1.0, 0.4]))


def test_exact_on_noise_free_plane() -> None:
    points, _ = _plane_points(np.random.default_rng(0), 5000, outliers=0.0)
    fit = fit_plane_ransac(points, threshold=0.01)
    assert fit.inliers.all()
    np.testing.assert_allclose(fit.params, TRUE_PLANE, atol=1e-12)
    assert fit.residual < 1e-12
    assert np.linalg.norm(fit.params[:3]) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("outliers", [0.5, 0.7])
def test_robust_to_majority_outliers(outliers: float) -> None:
    points, true_inliers = _plane_points(np.random.default_rng(1), 20_000, outliers, noise=0.002)
    fit = fit_plane_ransac(points, threshold=0.01)
    np.testing.assert_allclose(fit.params, TRUE_PLANE, atol=2e-4)
    # Every true inlier is found; the extra ones are outliers that happen to lie within 0.01.
    assert fit.inliers[true_inliers].mean() > 0.99
    assert fit.inliers[~true_inliers].mean() < 0.03
    assert 0.0018 < fit.residual < 0.003  # noise σ = 0.002 plus the outliers that fall inside


def test_deterministic_for_a_seed() -> None:
    points, _ = _plane_points(np.random.default_rng(2), 3000, 0.4, noise=0.003)
    first = fit_plane_ransac(points, 0.01, seed=7)
    second = fit_plane_ransac(points, 0.01, seed=7)
    np.testing.assert_array_equal(first.params, second.params)
    np.testing.assert_array_equal(first.inliers, second.inliers)
    other_seed = fit_plane_ransac(points, 0.01, seed=8)
    np.testing.assert_allclose(other_seed.params, first.params, atol=1e-4)


def test_disparity_at_evaluates_the_plane() -> None:
    points, _ = _plane_points(np.random.default_rng(3), 500, 0.0)
    fit = fit_plane_ransac(points, 0.01)
    assert fit.disparity_at(np.array([100.0]), np.array([50.0]))[0] == pytest.approx(0.4 + 0.01 - 0.01)
    assert fit.inlier_ratio == 1.0


@settings(max_examples=25, deadline=None)
@given(
    normal=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.3, 1)),
    distance=st.floats(0.5, 20),
    focal=st.tuples(st.floats(200, 2000), st.floats(200, 2000)),
    centre=st.tuples(st.floats(100, 500), st.floats(100, 400)),
    baseline=st.floats(0.01, 0.5),
    seed=st.integers(0, 2**16),
)
def test_3d_planes_stay_planes_in_disparity_space(
    normal: tuple[float, float, float],
    distance: float,
    focal: tuple[float, float],
    centre: tuple[float, float],
    baseline: float,
    seed: int,
) -> None:
    """A 3-D plane n·X = c seen by a pinhole camera gives exactly planar (u, v, d) points,
    with d = B·(fx + fy)/2 / Z as in the paper, and the fit recovers that plane."""
    n = np.asarray(normal) / np.linalg.norm(normal)
    fx, fy = focal
    cx, cy = centre
    mean_focal = (fx + fy) / 2
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 640, 400)
    v = rng.uniform(0, 480, 400)
    rays = np.column_stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)])
    facing = rays @ n
    keep = facing > 0.05  # rays that hit the plane in front of the camera
    z = distance / facing[keep]
    d = baseline * mean_focal / z
    points = np.column_stack([u[keep], v[keep], d])
    if len(points) < 10:
        return
    fit = fit_plane_ransac(points, threshold=1e-6 * d.max(), seed=seed)
    assert fit.inliers.all()
    # n·X = c with X = Z·ray and 1/Z = d/(B·f̄): n·ray − c·d/(B·f̄) = 0, linear in (u, v, d).
    analytic = np.array([n[0] / fx, n[1] / fy, -distance / (baseline * mean_focal), n[2] - n[0] * cx / fx - n[1] * cy / fy])
    np.testing.assert_allclose(fit.params, _unit(analytic), atol=1e-7)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), outliers=st.floats(0.0, 0.6), noise=st.sampled_from([0.0, 0.002]))
def test_fit_ignores_point_order(seed: int, outliers: float, noise: float) -> None:
    points, _ = _plane_points(np.random.default_rng(seed), 6000, outliers, noise)
    order = np.random.default_rng(seed + 1).permutation(len(points))
    fit = fit_plane_ransac(points, 0.01)
    shuffled = fit_plane_ransac(points[order], 0.01)
    # Same plane up to floating-point summation order, same inliers.
    np.testing.assert_allclose(shuffled.params, fit.params, atol=1e-9)
    np.testing.assert_array_equal(shuffled.inliers, fit.inliers[order])


def test_collinear_points_are_degenerate() -> None:
    t = np.linspace(0, 100, 500)
    line = np.column_stack([t, 2 * t + 1, 0.01 * t])
    with pytest.raises(DegenerateSupportError, match="collinear"):
        fit_plane_ransac(line, 0.01)


def test_coincident_points_are_degenerate() -> None:
    with pytest.raises(DegenerateSupportError):
        fit_plane_ransac(np.tile([[3.0, 4.0, 0.5]], (200, 1)), 0.01)


def test_too_few_points() -> None:
    with pytest.raises(DegenerateSupportError, match="at least 3"):
        fit_plane_ransac(np.zeros((2, 3)), 0.01)


@pytest.mark.parametrize(
    ("points", "message"),
    [
        (np.zeros((10, 2)), r"shape \(N, 3\)"),
        (np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), "NaN"),
        (np.array([["a", "b", "c"]] * 3), "real numbers"),
    ],
)
def test_bad_points_are_rejected(points: np.ndarray, message: str) -> None:
    with pytest.raises(InputError, match=message):
        fit_plane_ransac(points, 0.01)


def test_bad_threshold_is_rejected() -> None:
    with pytest.raises(InputError, match="threshold"):
        fit_plane_ransac(np.random.default_rng(0).random((10, 3)), 0.0)
