"""``illusion-studio geometry …`` and ``bench geometry`` on real files."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from core.formats import read_map, read_mask, write_map, write_mask, write_rgb
from core.geometry import RigCalibration, save_calibration
from webapp.cli.bench import bench
from webapp.cli.geometry import geometry
from webapp.cli.state import CliState


def _run(args: list[str], obj: CliState | None = None) -> tuple[int, str, dict | None]:
    result = CliRunner().invoke(geometry, args, obj=obj)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    lines = result.output.strip().splitlines()
    figures = json.loads(lines[-1]) if result.exit_code == 0 else None
    return result.exit_code, result.output, figures


@pytest.fixture()
def frame(tmp_path: Path) -> dict[str, Path]:
    rng = np.random.default_rng(0)
    left = cv2.resize(rng.integers(0, 256, (12, 20, 3), dtype=np.uint8), (80, 48))
    v, u = np.mgrid[0:48, 0:80]
    disparity = (4 + 0.02 * u + 0.03 * v).astype(np.float32)
    illusion = np.zeros((48, 80), dtype=bool)
    illusion[14:34, 25:55] = True
    support = np.zeros((48, 80), dtype=bool)
    support[8:40, 18:62] = True
    support &= ~illusion
    fooled = disparity.copy()
    fooled[illusion] += 3.0
    paths = {name: tmp_path / name for name in ("left.png", "disp.pfm", "fooled.pfm", "ill.png", "sup.png")}
    write_rgb(paths["left.png"], left)
    write_map(paths["disp.pfm"], disparity)
    write_map(paths["fooled.pfm"], fooled)
    write_mask(paths["ill.png"], illusion)
    write_mask(paths["sup.png"], support)
    return paths


def test_right_view_writes_image_and_holes(frame: dict[str, Path], tmp_path: Path) -> None:
    out, holes = tmp_path / "right.png", tmp_path / "holes.png"
    code, output, figures = _run(
        ["right-view", str(frame["left.png"]), str(frame["disp.pfm"]), "--out", str(out), "--holes", str(holes)]
    )
    assert code == 0, output
    assert figures is not None and figures["inpaint"] == "telea" and figures["valid_ratio"] >= 0.9
    assert cv2.imread(str(out)).shape == (48, 80, 3)
    assert read_mask(holes).mean() == pytest.approx(figures["hole_fraction"], abs=1e-6)


def test_right_view_with_a_fixed_scale(frame: dict[str, Path], tmp_path: Path) -> None:
    code, _, figures = _run(
        ["right-view", str(frame["left.png"]), str(frame["disp.pfm"]), "--out", str(tmp_path / "r.png"),
         "--scale", "1", "--inpaint", "none"]
    )  # fmt: skip
    assert code == 0 and figures is not None
    assert figures["scale"] == 1.0 and figures["inpaint"] == "none"


def test_right_view_takes_defaults_from_the_data_dir(frame: dict[str, Path], tmp_path: Path) -> None:
    data_dir = tmp_path / "workspace"
    data_dir.mkdir()
    (data_dir / "illusion-studio.toml").write_text('inpaint_backend = "ns"\n')
    code, output, figures = _run(
        ["right-view", str(frame["left.png"]), str(frame["disp.pfm"]), "--out", str(tmp_path / "r.png")],
        obj=CliState(data_dir),
    )
    assert code == 0, output
    assert figures is not None and figures["inpaint"] == "ns"


def test_right_view_errors_are_one_line(frame: dict[str, Path], tmp_path: Path) -> None:
    code, output, _ = _run(
        ["right-view", str(frame["left.png"]), str(frame["disp.pfm"]), "--out", str(tmp_path / "r.png"),
         "--inpaint", "lama"]
    )  # fmt: skip
    assert code == 1 and output.startswith("Error: LaMa inpainting needs a TorchScript model path")
    small = tmp_path / "small.pfm"
    write_map(small, np.ones((10, 10), dtype=np.float32))
    code, output, _ = _run(["right-view", str(frame["left.png"]), str(small), "--out", str(tmp_path / "r.png")])
    assert code == 1 and "is 48x80 (HxW), expected 10x10" in output
    code, output, _ = _run(
        ["right-view", str(frame["left.png"]), str(frame["disp.pfm"]), "--out", str(tmp_path / "r.jpg")]
    )
    assert code == 1 and "lossless" in output


def test_rectify_fixes_the_illusion(frame: dict[str, Path], tmp_path: Path) -> None:
    out, qa = tmp_path / "rect.pfm", tmp_path / "qa.json"
    code, output, figures = _run(
        ["rectify", str(frame["fooled.pfm"]), "--pair", str(frame["ill.png"]), str(frame["sup.png"]),
         "--pair", str(frame["ill.png"]), "-", "--image", str(frame["left.png"]), "--out", str(out), "--qa", str(qa)]
    )  # fmt: skip
    assert code == 0, output
    assert figures is not None and figures["rectified"] == 2
    assert [p["support_source"] for p in figures["pairs"]] == ["mask", "ring"]
    assert json.loads(qa.read_text()) == figures
    truth = read_map(frame["disp.pfm"])
    illusion = read_mask(frame["ill.png"])
    error = np.abs(read_map(out) - truth)[illusion]  # from 3 px before
    assert error.mean() < 0.01 and error.max() < 0.1  # the seam band follows the image a little


def test_rectify_strict_fails_on_a_tiny_mask(frame: dict[str, Path], tmp_path: Path) -> None:
    tiny = tmp_path / "tiny.png"
    mask = np.zeros((48, 80), dtype=bool)
    mask[0:3, 0:3] = True
    write_mask(tiny, mask)
    args = ["rectify", str(frame["fooled.pfm"]), "--pair", str(tiny), "-", "--out", str(tmp_path / "r.npy")]
    code, _, figures = _run(args)
    assert code == 0 and figures is not None and figures["pairs"][0]["status"] == "skipped"
    code, output, _ = _run([*args, "--strict"])
    assert code == 1 and "illusion mask has 9 px (< 100)" in output


@pytest.fixture()
def rig(tmp_path: Path) -> dict[str, Path]:
    K_depth = np.array([[40.0, 0, 31.5], [0, 40.0, 23.5], [0, 0, 1]])
    K_color = np.array([[80.0, 0, 63.5], [0, 80.0, 47.5], [0, 0, 1]])
    calibration = RigCalibration(
        K_depth=K_depth, depth_shape=(48, 64), K_color=K_color, color_shape=(96, 128),
        R=np.eye(3), T=np.array([0.01, 0.0, 0.0]), baseline=0.06, depth_scale=0.001,
    )  # fmt: skip
    paths = {"calib": tmp_path / "rig.json", "depth": tmp_path / "depth.png"}
    save_calibration(calibration, paths["calib"])
    cv2.imwrite(str(paths["depth"]), np.full((48, 64), 2500, dtype=np.uint16))
    return paths


def test_reproject_writes_depth_and_disparity(rig: dict[str, Path], tmp_path: Path) -> None:
    out, disp = tmp_path / "depth.pfm", tmp_path / "disp.png"
    code, output, figures = _run(
        ["reproject", str(rig["depth"]), "--calib", str(rig["calib"]), "--out", str(out), "--disparity", str(disp)]
    )
    assert code == 0, output
    depth = read_map(out)
    assert depth.shape == (96, 128) and figures is not None and figures["valid_fraction"] > 0.9
    np.testing.assert_allclose(depth[depth > 0], 2.5, atol=1e-5)
    # KITTI PNG: disparity = B·f/Z = 0.06·80/2.5 = 1.92 px, stored ×256 (rounded).
    disparity = read_map(disp)
    np.testing.assert_allclose(disparity[depth > 0], 1.921875, atol=1e-6)


def test_reproject_rejects_mismatches(rig: dict[str, Path], tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.png"
    cv2.imwrite(str(wrong), np.full((40, 64), 2500, dtype=np.uint16))
    code, output, _ = _run(["reproject", str(wrong), "--calib", str(rig["calib"]), "--out", str(tmp_path / "d.pfm")])
    assert code == 1 and "(40, 64)" in output and "(48, 64)" in output
    code, output, _ = _run(["reproject", str(rig["depth"]), "--calib", str(rig["calib"]), "--out", str(tmp_path / "d.png")])
    assert code == 2 and ".pfm or .npy" in output
    broken = tmp_path / "broken.json"
    broken.write_text("{}")
    code, output, _ = _run(["reproject", str(rig["depth"]), "--calib", str(broken), "--out", str(tmp_path / "d.pfm")])
    assert code == 1 and "broken.json: calibration is missing" in output


@pytest.mark.slow
def test_bench_geometry_prints_one_json_object() -> None:
    result = CliRunner().invoke(bench, ["geometry", "--json", "--repeats", "1"])
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output)
    for key in (
        "plane_fit_1m_ms",
        "plane_fit_reference_1m_ms",
        "right_view_1080p_ms",
        "right_view_reference_1080p_ms",
        "inpaint_1080p_ms",
        "reproject_1080p_ms",
    ):
        assert figures[key] > 0, key
    assert "plane_fit_reference_note" in figures
