"""Depth reprojection (Algorithm 3), depth ↔ disparity and the rig calibration file."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from core.geometry import (
    CalibrationError,
    InputError,
    depth_to_disparity,
    disparity_to_depth,
    load_calibration,
    parse_calibration,
    reproject_depth,
    save_calibration,
)


def _K(f: float, width: int, height: int) -> np.ndarray:
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])


def _rot_y(degrees: float) -> np.ndarray:
    a = np.deg2rad(degrees)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


@settings(max_examples=25, deadline=None)
@given(
    size=st.tuples(st.integers(8, 40), st.integers(8, 40)),
    focal=st.floats(20, 300),
    base=st.floats(0.5, 8.0),
    slope=st.tuples(st.floats(-0.01, 0.01), st.floats(-0.01, 0.01)),
    depth_scale=st.sampled_from([1.0, 0.001, 0.00025]),
)
def test_identity_extrinsics_return_the_input_depth(
    size: tuple[int, int], focal: float, base: float, slope: tuple[float, float], depth_scale: float
) -> None:
    height, width = size
    v, u = np.mgrid[0:height, 0:width]
    metres = base + slope[0] * u + slope[1] * v  # smooth: the noise filter keeps every pixel
    assume(metres.min() > 0.1)  # a wall in front of the camera (a steep slope on a near one goes behind it)
    raw = (metres / depth_scale).astype(np.float32)
    K = _K(focal, width, height)
    out = reproject_depth(raw, K, depth_scale, np.eye(3), np.zeros(3), K, (height, width))
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, raw.astype(np.float64) * depth_scale, rtol=1e-5)


# --- a synthetic rig: a tilted wall and a box, ray-cast in both cameras -------------------

WALL_NORMAL = np.array([0.15, -0.1, 1.0]) / np.linalg.norm([0.15, -0.1, 1.0])
WALL_OFFSET = 4.0 * WALL_NORMAL[2]  # n·X = c passes through (0, 0, 4)
BOX = (np.array([-0.45, -0.35, 2.0]), np.array([0.35, 0.3, 2.6]))


def _first_hit(origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Ray parameter t of the first surface hit (rays o + t·w; w has z = 1, so t is the depth
    along the camera whose rays these are); inf if none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_wall = (WALL_OFFSET - WALL_NORMAL @ origin) / (directions @ WALL_NORMAL)
        t_wall = np.where(t_wall > 0, t_wall, np.inf)
        lo = (BOX[0] - origin) / directions
        hi = (BOX[1] - origin) / directions
    t_near = np.nanmax(np.minimum(lo, hi), axis=1)
    t_far = np.nanmin(np.maximum(lo, hi), axis=1)
    t_box = np.where((t_near <= t_far) & (t_near > 0), t_near, np.inf)
    return np.minimum(t_wall, t_box)


def _render_depth(K: np.ndarray, shape: tuple[int, int], R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Depth (metres) seen by a camera whose coordinates are X_cam = R·X_scene + T."""
    height, width = shape
    v, u = np.mgrid[0:height, 0:width]
    rays_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], axis=-1).reshape(-1, 3)
    depth = _first_hit(-R.T @ T, rays_cam @ R)  # (Rᵀ·r)ᵀ = rᵀ·R, scene-frame directions
    return depth.reshape(shape)


def test_synthetic_rig_with_a_wall_and_a_box() -> None:
    K_src, src_shape = _K(60.0, 80, 60), (60, 80)
    K_dst, dst_shape = _K(125.0, 160, 120), (120, 160)
    R, T = _rot_y(4.0), np.array([0.12, 0.03, -0.05])
    src_depth = _render_depth(K_src, src_shape, np.eye(3), np.zeros(3))
    raw = np.rint(src_depth * 1000).astype(np.uint16)  # millimetres, like a sensor
    truth = _render_depth(K_dst, dst_shape, R, T)

    out = reproject_depth(raw, K_src, 0.001, R, T, K_dst, dst_shape, epsilon=0.05)

    # Where the source camera also sees the point the destination sees (not occluded, in view).
    v, u = np.mgrid[0:120, 0:160]
    rays = np.stack([(u - K_dst[0, 2]) / K_dst[0, 0], (v - K_dst[1, 2]) / K_dst[1, 1], np.ones(u.shape)], -1)
    points = (rays * truth[..., None]).reshape(-1, 3) @ R - T @ R  # Rᵀ·(X − T) per row
    seen_dir = points / points[:, 2:3]
    col = K_src[0, 0] * seen_dir[:, 0] + K_src[0, 2]
    row = K_src[1, 1] * seen_dir[:, 1] + K_src[1, 2]
    in_view = (col > 0.5) & (col < 78.5) & (row > 0.5) & (row < 58.5)
    unoccluded = _first_hit(np.zeros(3), seen_dir) >= points[:, 2] - 1e-6
    visible = (in_view & unoccluded).reshape(dst_shape)
    valid = out > 0
    error = np.abs(out - truth)

    assert visible.mean() > 0.5
    assert valid[visible].mean() > 0.9  # dense where it can be
    assert np.median(error[valid]) < 0.01  # within a centimetre typically
    assert np.mean(error[valid] < 0.05) > 0.99  # and within ε almost everywhere
    footprint = ((col > -1) & (col < 80) & (row > -1) & (row < 60)).reshape(dst_shape)
    assert not (valid & ~footprint).any()  # nothing invented outside the sensor's view
    # The box hides a strip of wall from the sensor but not from the colour camera: the strip
    # stays mostly empty, and the only wrong depths are the box's silhouette grown by at most
    # 2 px, never box depth spread over the hidden wall. (A sensor pixel straddling the box
    # edge carries the box depth over its whole footprint, 2.1 px wide here, half of which
    # may lie beyond the edge; the 4-neighbour splat adds under a pixel.)
    hidden = ~unoccluded.reshape(dst_shape) & in_view.reshape(dst_shape)
    assert hidden.sum() > 100
    assert (hidden & ~valid).sum() >= 0.6 * hidden.sum()
    box = truth < 3.0
    box_edge = cv2.dilate(box.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~box
    wrong = valid & (error >= 0.05)
    assert not (wrong & ~box_edge).any()


@pytest.mark.parametrize(("size", "filled"), [(10, True), (150, False)])
def test_gaps_up_to_the_area_limit_are_filled(size: int, filled: bool) -> None:
    # Without upsampling, a 2.5x finer destination gets gap lines between the projected
    # points: short lines (10 px) are small holes and get filled; 150 px lines are not.
    src = np.full((size * 2 // 5, size * 2 // 5), 2000, dtype=np.uint16)  # 2 m in mm
    K_src = _K(0.4 * size, src.shape[1], src.shape[0])
    K_dst = _K(float(size), size, size)
    out = reproject_depth(src, K_src, 0.001, np.eye(3), np.zeros(3), K_dst, (size, size), upsample=1)
    inner = out[2:-2, 2:-2]
    if filled:
        np.testing.assert_allclose(inner, 2.0, atol=1e-3)
    else:
        assert (inner == 0).any() and np.allclose(inner[inner > 0], 2.0, atol=1e-6)
    upsampled = reproject_depth(src, K_src, 0.001, np.eye(3), np.zeros(3), K_dst, (size, size))
    np.testing.assert_allclose(upsampled[2:-2, 2:-2], 2.0, atol=1e-3)  # densified: no gaps


def test_depth_to_disparity_and_back() -> None:
    depth = np.array([[2.0, 0.0], [np.nan, 4.0]])
    disparity = depth_to_disparity(depth, baseline=0.1, focal=500.0)
    np.testing.assert_allclose(disparity, [[25.0, 0.0], [0.0, 12.5]])
    np.testing.assert_allclose(disparity_to_depth(disparity, 0.1, 500.0), [[2.0, 0.0], [0.0, 4.0]])
    with pytest.raises(InputError, match="baseline"):
        depth_to_disparity(depth, baseline=0.0, focal=500.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"R": np.diag([1.0, 1.0, 2.0])}, "rotation"),
        ({"R": -np.eye(3)}, "rotation"),
        ({"T": np.zeros(2)}, "T must have shape"),
        ({"K_dst": np.eye(3) * -1}, "focal"),
        ({"dst_shape": (0, 10)}, "dst_shape"),
        ({"depth_scale": 0}, "depth_scale"),
        ({"depth_src": np.full((10, 12), np.nan)}, "no finite value"),
        ({"depth_src": np.zeros((10, 12))}, "no valid pixel"),
        ({"guide": np.zeros((5, 5, 3), np.uint8)}, "guide"),
    ],
)
def test_bad_input_is_rejected(kwargs: dict, message: str) -> None:
    args = {
        "depth_src": np.ones((10, 12)),
        "K_src": _K(10.0, 12, 10),
        "depth_scale": 1.0,
        "R": np.eye(3),
        "T": np.zeros(3),
        "K_dst": _K(10.0, 12, 10),
        "dst_shape": (10, 12),
    }
    args.update(kwargs)
    with pytest.raises(InputError, match=message):
        reproject_depth(**args)


# --- calibration file --------------------------------------------------------------------


def _calibration_json() -> dict:
    return {
        "depth_camera": {"K": _K(460.0, 640, 480).tolist(), "width": 640, "height": 480},
        "color_camera": {"K": _K(1400.0, 1920, 1080).tolist(), "width": 1920, "height": 1080},
        "R": _rot_y(1.0).tolist(),
        "T": [0.03, 0.0, 0.001],
        "baseline": 0.0628167,
        "depth_scale": 0.00025,
    }


def test_calibration_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(_calibration_json()))
    rig = load_calibration(path)
    assert rig.depth_shape == (480, 640) and rig.color_shape == (1080, 1920)
    assert rig.focal == 1400.0 and rig.baseline == 0.0628167
    save_calibration(rig, tmp_path / "again.json")
    assert json.loads((tmp_path / "again.json").read_text()) == json.loads(json.dumps(rig.to_json()))
    np.testing.assert_array_equal(load_calibration(tmp_path / "again.json").R, rig.R)


def _broken(edit) -> dict:  # type: ignore[no-untyped-def]
    data = _calibration_json()
    edit(data)
    return data


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (_broken(lambda d: d.pop("baseline")), "missing baseline"),
        (_broken(lambda d: d.update(extra=1)), "unknown keys extra"),
        (_broken(lambda d: d["color_camera"].pop("K")), "color_camera is missing K"),
        (_broken(lambda d: d["depth_camera"].update(width=0)), "depth_camera.width must be a positive integer"),
        (_broken(lambda d: d.update(R=[[1, 0, 0], [0, 1, 0]])), r"R must have shape \(3, 3\)"),
        (_broken(lambda d: d.update(R=[[1, 0, 0], [0, 2, 0], [0, 0, 1]])), "not a rotation"),
        (_broken(lambda d: d.update(T="0.03")), "T must be numeric"),
        (_broken(lambda d: d.update(baseline=-0.06)), "baseline must be a finite number > 0"),
        (_broken(lambda d: d.update(depth_scale=True)), "depth_scale must be a number"),
        (_broken(lambda d: d["depth_camera"].update(K=[[0, 0, 1], [0, 1, 1], [0, 0, 1]])), "depth_camera.K"),
        ([1, 2, 3], "must be a JSON object"),
    ],
)
def test_malformed_calibrations_are_rejected(data: object, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        parse_calibration(data)


def test_calibration_file_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="not found"):
        load_calibration(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(CalibrationError, match=r"bad.json: not valid JSON"):
        load_calibration(bad)
    bad.write_text(json.dumps(_broken(lambda d: d.pop("R"))))
    with pytest.raises(CalibrationError, match=r"bad.json: calibration is missing R"):
        load_calibration(bad)
