"""Robust plane fitting in (u, v, d) space: the paper's Algorithm 1 (RANSAC + eigen refit).

A plane in camera space stays a plane in (u, v, d) (u, v in pixels, d disparity), so no
intrinsics are needed: α·u + β·v + δ·d + γ = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.geometry.errors import DegenerateSupportError, InputError

# Hypotheses are scored on this many points, like the paper's per-iteration sub-sample M:
# scoring 1000 hypotheses on all of 1M points would be 1e9 distance evaluations.
DEFAULT_SCORE_SAMPLE = 4096
# Inliers whose scatter has a second eigenvalue this small (relative) lie on a line.
_COLLINEAR_RATIO = 1e-9
# Refits on the scoring sample before the passes over all points.
_SAMPLE_REFITS = 10
# Golden-ratio style weights of (u, v, d) for the order-free sample hash; d is typically
# normalised to [0, 1], hence its large weight.
_HASH_WEIGHTS = np.array([0.7548776662466927, 0.5698402909980532, 6180.339887498949])


@dataclass(frozen=True)
class PlaneFit:
    """A fitted plane and its support.

    ``params`` is ``(α, β, δ, γ)`` (float64, shape (4,)) with α²+β²+δ² = 1 and δ ≥ 0, in the
    units of the fitted points; ``inliers`` is a bool mask of shape (N,) over the input
    points; ``residual`` is the RMS point-to-plane distance of the inliers (point units).
    """

    params: np.ndarray
    inliers: np.ndarray
    residual: float

    @property
    def inlier_ratio(self) -> float:
        """Fraction of the input points that are inliers, in [0, 1]."""
        return float(self.inliers.mean())

    def disparity_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The plane's d at pixel coordinates ``u`` (column), ``v`` (row); any broadcastable shapes.

        Raises :class:`DegenerateSupportError` when the plane is parallel to the d axis
        (δ ≈ 0), where d is not a function of (u, v).
        """
        alpha, beta, delta, gamma = self.params
        if abs(delta) < 1e-12:
            raise DegenerateSupportError("the fitted plane contains the disparity axis (δ ≈ 0)")
        return -(alpha * np.asarray(u) + beta * np.asarray(v) + gamma) / delta


def fit_plane_ransac(
    points: np.ndarray,
    threshold: float,
    hypotheses: int = 1000,
    seed: int = 0,
    *,
    score_sample: int = DEFAULT_SCORE_SAMPLE,
    refine_iterations: int = 1,
) -> PlaneFit:
    """Fit α·u + β·v + δ·d + γ = 0 to ``points`` (N x 3: u, v, d) robustly.

    Algorithm 1 of the paper: ``hypotheses`` random 3-point planes (cross-product normals),
    each scored by its number of points closer than ``threshold`` (point-to-plane distance,
    in point units) on a fixed subsample of ``score_sample`` points chosen by a hash of their
    coordinates, so the fit does not depend on the order of the points. The best plane's
    inliers are refitted by the smallest eigenvector of their centred scatter, repeated until
    the inlier set stops changing or would shrink: on the subsample, then on *all* points (at
    most ``refine_iterations`` refits). The returned inliers are those of the final plane.
    Deterministic for a given ``seed``.

    Raises :class:`InputError` for a non-(N, 3) or non-finite input and
    :class:`DegenerateSupportError` when fewer than 3 points are given or the points (or the
    best inliers) are collinear or coincident.
    """
    pts = _as_points(points)
    if not threshold > 0:
        raise InputError(f"threshold must be > 0, got {threshold}")
    if hypotheses < 1:
        raise InputError(f"hypotheses must be >= 1, got {hypotheses}")
    n = len(pts)
    if n < 3:
        raise DegenerateSupportError(f"a plane needs at least 3 support points, got {n}")
    rng = np.random.default_rng(seed)
    sample = _canonical_sample(pts, score_sample, seed)
    # Centring keeps float32 scoring exact enough when u, v are in the thousands.
    centre = sample.mean(axis=0)
    sample = (sample - centre).astype(np.float32)
    normal, offset = _best_hypothesis(sample, threshold, hypotheses, rng)
    # Local optimisation on the sample first (cheap), so that the passes over all points
    # start from an almost converged plane and rarely need more than one refit.
    normal, offset, _ = _converge(sample.astype(np.float64), normal, offset, threshold, _SAMPLE_REFITS, np.zeros(3))
    offset -= float(normal @ centre)
    normal, offset, distances = _converge(pts, normal, offset, threshold, refine_iterations, centre)
    inliers = np.abs(distances) < threshold
    count = int(np.count_nonzero(inliers))
    if count < 3:
        raise DegenerateSupportError(f"only {count} points lie on the fitted plane; a plane needs 3")
    inlier_distances = np.compress(inliers, distances)
    # One sign convention (δ ≥ 0) so that equal planes have equal parameters.
    sign = -1.0 if normal[2] < 0 or (normal[2] == 0 and normal[0] < 0) else 1.0
    return PlaneFit(
        params=sign * np.append(normal, offset),
        inliers=inliers,
        residual=float(np.sqrt(inlier_distances @ inlier_distances / count)),
    )


def _as_points(points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3) for (u, v, d), got {pts.shape}")
    if not (np.issubdtype(pts.dtype, np.floating) or np.issubdtype(pts.dtype, np.integer)):
        raise InputError(f"points must be real numbers, got dtype {pts.dtype}")
    if pts.dtype not in (np.float32, np.float64):
        pts = pts.astype(np.float64)
    if not np.isfinite(pts).all():
        raise InputError("points contain NaN or inf; drop invalid disparities before fitting")
    return pts


def _canonical_sample(pts: np.ndarray, size: int, seed: int) -> np.ndarray:
    """Up to ``size`` of the points, chosen and ordered by their coordinates alone.

    A hash of each point's values (a low-discrepancy weighting, shifted by ``seed``) picks
    the sample and a lexicographic sort orders it, so the same point set in any order
    yields the same sample, hypotheses and fit.
    """
    if len(pts) > size:
        hashed = pts @ _HASH_WEIGHTS + seed * _HASH_WEIGHTS[0]
        hashed -= np.floor(hashed)
        pts = pts[np.argpartition(hashed, size)[:size]]
    return pts[np.lexsort(pts.T[::-1])]


def _best_hypothesis(
    sample: np.ndarray, threshold: float, hypotheses: int, rng: np.random.Generator
) -> tuple[np.ndarray, float]:
    """Normal (unit, float64) and offset of the 3-point plane with the most sample inliers."""
    triples = sample[rng.integers(0, len(sample), (hypotheses, 3))]
    edge1 = triples[:, 1] - triples[:, 0]
    edge2 = triples[:, 2] - triples[:, 0]
    normals = np.cross(edge1, edge2)
    norms = np.linalg.norm(normals, axis=1)
    # A near-zero cross product relative to the edge lengths means a (near-)collinear triple.
    scale = np.linalg.norm(edge1, axis=1) * np.linalg.norm(edge2, axis=1)
    usable = norms > 1e-6 * scale
    if not usable.any():
        raise DegenerateSupportError(
            "support points are collinear or coincident: no 3 of them span a plane"
        )
    normals = normals[usable] / norms[usable, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[usable, 0])
    # One BLAS product scores every hypothesis on every sample point at once.
    distances = sample @ normals.T
    distances += offsets
    counts = np.count_nonzero(np.abs(distances) < threshold, axis=0)
    best = int(np.argmax(counts))
    return normals[best].astype(np.float64), float(offsets[best])


def _converge(
    pts: np.ndarray, normal: np.ndarray, offset: float, threshold: float, iterations: int, centre: np.ndarray
) -> tuple[np.ndarray, float, np.ndarray]:
    """Refit on the inliers of the current plane until the inlier set stops changing (at most
    ``iterations`` times); returns the plane and its signed distances to ``pts``.

    The first refit is always taken (the starting plane is only approximate); a later one
    only if it keeps at least as many inliers, so the consensus never drifts down.
    """
    distances = _distances(pts, normal, offset)
    inliers = np.abs(distances) < threshold
    for iteration in range(iterations):
        new_normal, new_offset = _refit(np.compress(inliers, pts, axis=0), centre)
        new_distances = _distances(pts, new_normal, new_offset)
        refined = np.abs(new_distances) < threshold
        if iteration and np.count_nonzero(refined) < np.count_nonzero(inliers):
            break
        normal, offset, distances = new_normal, new_offset, new_distances
        if np.array_equal(refined, inliers):
            break
        inliers = refined
    return normal, offset, distances


def _distances(pts: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Signed point-to-plane distances, shape (N,), in the points' dtype."""
    distances = pts @ normal.astype(pts.dtype)
    distances += offset
    return distances


def _refit(inlier_pts: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane with α²+β²+δ² = 1: the smallest eigenvector of the centred scatter.

    (The paper's 4x4 scatter of [P, 1] constrains |(α, β, δ, γ)| = 1 instead, which is badly
    conditioned with u, v in pixels; centring gives the exact constrained minimiser.)
    ``inlier_pts`` is a scratch copy (shifted in place by the approximate ``centre`` so that
    the one-pass scatter below does not cancel catastrophically).
    """
    count = len(inlier_pts)
    if count < 3:
        raise DegenerateSupportError(f"only {count} inliers; a plane needs 3")
    shifted = inlier_pts.astype(np.float64, copy=False)
    shifted -= centre
    # BLAS products: much faster than mean(axis=0) over an (N, 3) array.
    mean_shift = np.ones(count) @ shifted / count
    scatter = shifted.T @ shifted - count * np.outer(mean_shift, mean_shift)
    eigenvalues, eigenvectors = np.linalg.eigh(scatter)
    if eigenvalues[1] <= _COLLINEAR_RATIO * eigenvalues[2]:
        raise DegenerateSupportError("the plane's inliers are collinear: the plane is undetermined")
    normal = eigenvectors[:, 0]
    return normal, -float(normal @ (centre + mean_shift))
