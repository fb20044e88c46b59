"""Speed benchmark of the geometry core against straightforward reference implementations.

Inputs are synthetic and seeded, so runs are comparable; every figure is the median wall
time (ms) over ``repeats`` runs after one warm-up run. The ``reference_*`` functions are
plain implementations of the paper's algorithms, for comparison only.
"""

from __future__ import annotations

import importlib.util
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from core.geometry.inpaint import inpaint_holes
from core.geometry.plane import fit_plane_ransac
from core.geometry.reproject import reproject_depth
from core.geometry.right_view import forward_warp, search_disparity_scale, synthesize_right_view

FULL_HD = (1080, 1920)
PLANE_POINTS = 1_000_000
PLANE_OUTLIERS = 0.4
PLANE_THRESHOLD = 0.01
PLANE_HYPOTHESES = 1000
# The reference scores every hypothesis on all 1M points (~10 ms each): it is timed on this
# many and scaled linearly to PLANE_HYPOTHESES.
REFERENCE_HYPOTHESES = 50
REFERENCE_BATCH = 10


def reference_plane_fit(points: np.ndarray, threshold: float, hypotheses: int, batch: int, seed: int) -> np.ndarray:
    """Algorithm 1 as written: batches of 3-point planes scored on all points, 4x4 eigen refit."""
    rng = np.random.default_rng(seed)
    homogeneous = np.column_stack([points, np.ones(len(points))])
    best_count, best_inliers = -1, np.zeros(len(points), dtype=bool)
    for _ in range(hypotheses // batch):
        triples = points[rng.integers(0, len(points), (batch, 3))]
        normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
        planes = np.column_stack([normals, -np.einsum("ij,ij->i", normals, triples[:, 1])])
        distances = planes @ homogeneous.T / np.linalg.norm(normals, axis=1, keepdims=True)
        inliers = np.abs(distances) < threshold
        counts = inliers.sum(axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best_inliers = int(counts[k]), inliers[k]
    chosen = homogeneous[best_inliers]
    _, vectors = np.linalg.eigh(chosen.T @ chosen)
    return vectors[:, 0]


def reference_right_view(left: np.ndarray, disparity: np.ndarray, tau: float) -> np.ndarray:
    """Algorithm 2 as written: bisection for s (run to convergence), ``np.maximum.at`` splat."""
    return reference_splat(left, disparity, reference_scale(disparity, tau))


def reference_scale(disparity: np.ndarray, tau: float, iterations: int = 100) -> float:
    """Bisection on s in (0, W / (4·max d)] until the interval is under 1e-6 wide."""
    width = disparity.shape[1]
    u = np.arange(width)
    low, high = 0.0, width / (4 * float(disparity.max()))
    for _ in range(iterations):
        if high - low <= 1e-6:
            break
        s = (low + high) / 2
        target = u - s * disparity
        ratio = np.count_nonzero((target >= 0) & (target < width)) / disparity.size
        low, high = (s, high) if ratio >= tau else (low, s)
    return (low + high) / 2


def reference_splat(left: np.ndarray, disparity: np.ndarray, scale: float) -> np.ndarray:
    """Forward warp to floor/ceil of u − s·d; the largest disparity wins (z-buffer)."""
    height, width = disparity.shape
    target = np.arange(width) - scale * disparity
    rows = np.broadcast_to(np.arange(height)[:, None], disparity.shape)
    right = np.zeros_like(left)
    zbuffer = np.full(disparity.shape, -np.inf)
    for column in (np.floor(target), np.ceil(target)):
        inside = (column >= 0) & (column < width)
        np.maximum.at(zbuffer, (rows[inside], column[inside].astype(np.intp)), disparity[inside])
    for column in (np.floor(target), np.ceil(target)):
        inside = (column >= 0) & (column < width)
        r, c, d = rows[inside], column[inside].astype(np.intp), disparity[inside]
        wins = d >= zbuffer[r, c]
        right[r[wins], c[wins]] = left[inside][wins]
    return right


def plane_points(seed: int = 0) -> np.ndarray:
    """1M (u, v, d) points of a 1080p frame: a tilted plane (d noise σ = 0.002) + 40% outliers."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, FULL_HD[1], PLANE_POINTS)
    v = rng.uniform(0, FULL_HD[0], PLANE_POINTS)
    d = 0.4 + 1e-4 * u - 2e-4 * v + rng.normal(0, 0.002, PLANE_POINTS)
    outliers = rng.random(PLANE_POINTS) < PLANE_OUTLIERS
    d[outliers] = rng.random(int(outliers.sum()))
    return np.column_stack([u, v, d])


def stereo_frame(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A textured 1080p RGB image and a monocular-style disparity (float32: a slanted floor,
    a wall and a box in front), as the right-view benchmark input."""
    rng = np.random.default_rng(seed)
    height, width = FULL_HD
    noise = rng.integers(0, 256, (height // 4, width // 4, 3), dtype=np.uint8)
    left = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    v, u = np.mgrid[0:height, 0:width].astype(np.float32)
    disparity = np.maximum(0.2 + 0.6 * (v / height - 0.5), 0.2) + 0.02 * np.sin(u / 97)
    disparity[300:700, 600:1100] += 0.4
    return left, disparity.astype(np.float32)


def lidar_rig(seed: int = 0) -> dict[str, Any]:
    """An L515-like 640x480 depth map (raw units of 0.25 mm) and a 1080p colour camera."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    depth_m = 3.0 - 0.002 * v + 0.0005 * u
    depth_m[150:330, 220:420] = 1.5 + 0.001 * u[150:330, 220:420]
    angle = np.deg2rad(1.5)
    return {
        "depth_src": np.rint(depth_m / 0.00025).astype(np.uint16),
        "K_src": np.array([[460.0, 0, 319.5], [0, 460.0, 239.5], [0, 0, 1]]),
        "depth_scale": 0.00025,
        "R": np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]),
        "T": np.array([0.025, -0.01, 0.005]),
        "K_dst": np.array([[1400.0, 0, 959.5], [0, 1400.0, 539.5], [0, 0, 1]]),
        "dst_shape": FULL_HD,
        "guide": rng.integers(0, 256, (*FULL_HD, 3), dtype=np.uint8),
    }


def run_geometry_benchmark(repeats: int = 5, seed: int = 0) -> dict[str, Any]:
    """Time every geometry step on fixed-seed inputs; returns a JSON-ready dict of figures."""
    points = plane_points(seed)
    left, disparity = stereo_frame(seed)
    rig = lidar_rig(seed)
    scale = search_disparity_scale(disparity)
    warped, holes, _ = forward_warp(left, disparity, scale)

    reference_ms = _median_ms(
        lambda: reference_plane_fit(points, PLANE_THRESHOLD, REFERENCE_HYPOTHESES, REFERENCE_BATCH, seed), 1
    )
    results: dict[str, Any] = {
        "plane_fit_1m_ms": _median_ms(lambda: fit_plane_ransac(points, PLANE_THRESHOLD, PLANE_HYPOTHESES, seed), repeats),
        "plane_fit_reference_1m_ms": reference_ms * PLANE_HYPOTHESES / REFERENCE_HYPOTHESES,
        "plane_fit_reference_note": (
            f"authors' batched algorithm (batches of {REFERENCE_BATCH}) timed on {REFERENCE_HYPOTHESES} "
            f"hypotheses and scaled linearly to {PLANE_HYPOTHESES}"
        ),
        "right_view_1080p_ms": _median_ms(lambda: synthesize_right_view(left, disparity, inpaint="none"), repeats),
        "right_view_reference_1080p_ms": _median_ms(lambda: reference_right_view(left, disparity, 0.9), repeats),
        "inpaint_1080p_ms": _median_ms(lambda: inpaint_holes(warped, holes, "telea"), repeats),
        "inpaint_hole_fraction": round(float(holes.mean()), 4),
        "reproject_1080p_ms": _median_ms(lambda: reproject_depth(**rig), repeats),
    }
    if importlib.util.find_spec("open3d") is not None:
        results["plane_fit_open3d_1m_ms"] = _open3d_ms(points, repeats)
    results["plane_fit_speedup"] = results["plane_fit_reference_1m_ms"] / results["plane_fit_1m_ms"]
    results["right_view_speedup"] = results["right_view_reference_1080p_ms"] / results["right_view_1080p_ms"]
    results = {k: round(v, 2) if isinstance(v, float) else v for k, v in results.items()}
    results["machine"] = f"{platform.machine()}, {os.cpu_count()} CPUs, numpy {np.__version__}, OpenCV {cv2.__version__}"
    results["repeats"] = repeats
    results["seed"] = seed
    return results


def _open3d_ms(points: np.ndarray, repeats: int) -> float:
    import open3d  # optional: only timed when installed

    cloud = open3d.geometry.PointCloud(open3d.utility.Vector3dVector(points))
    return _median_ms(lambda: cloud.segment_plane(PLANE_THRESHOLD, 3, PLANE_HYPOTHESES), repeats)


def _median_ms(run: Callable[[], object], repeats: int) -> float:
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)
