"""File formats: PFM, PNG disparity (KITTI and the authors'), masks, PLY, float maps."""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest

from core.formats import (
    FormatError,
    disparity_point_cloud,
    read_authors_disparity,
    read_kitti_disparity,
    read_map,
    read_mask,
    read_pfm,
    read_ply,
    read_scale_factors,
    write_authors_disparity,
    write_kitti_disparity,
    write_map,
    write_mask,
    write_pfm,
    write_ply,
    write_scale_factors,
)
from core.formats.masks import cv_mask


@pytest.mark.parametrize("little_endian", [True, False])
@pytest.mark.parametrize("shape", [(5, 7), (4, 6, 3)])
def test_pfm_round_trip_keeps_every_bit(tmp_path: Path, little_endian: bool, shape: tuple[int, ...]) -> None:
    data = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    data.flat[[0, 3, 5]] = [np.nan, np.inf, -np.inf]
    path = tmp_path / "map.pfm"
    write_pfm(path, data, little_endian=little_endian)
    back = read_pfm(path)
    assert back.dtype == np.float32 and back.shape == shape
    np.testing.assert_array_equal(back.view(np.uint32), data.view(np.uint32))


def test_pfm_stores_rows_bottom_to_top_and_reads_big_endian(tmp_path: Path) -> None:
    # Hand-written big-endian gray PFM, 2 wide x 2 high: file rows are bottom first.
    path = tmp_path / "be.pfm"
    path.write_bytes(b"Pf\n2 2\n1.0\n" + np.array([3, 4, 1, 2], dtype=">f4").tobytes())
    np.testing.assert_array_equal(read_pfm(path), [[1, 2], [3, 4]])
    write_pfm(path, np.array([[1, 2], [3, 4]], dtype=np.float32))
    assert path.read_bytes() == b"Pf\n2 2\n-1.0\n" + np.array([3, 4, 1, 2], dtype="<f4").tobytes()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"P6\n2 2\n255\n", "not a PFM"),
        (b"Pf\n2 2\n-1.0\n" + b"\0" * 12, "truncated"),
        (b"Pf\n2 2\n0\n" + b"\0" * 16, "non-zero"),
    ],
)
def test_pfm_malformed_files_are_rejected(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.pfm"
    path.write_bytes(content)
    with pytest.raises(FormatError, match=message):
        read_pfm(path)


def test_pfm_refuses_bad_arrays(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="HxW or HxWx3"):
        write_pfm(tmp_path / "x.pfm", np.zeros((2, 2, 2), dtype=np.float32))


def test_kitti_png_round_trip_and_invalid_pixels(tmp_path: Path) -> None:
    disp = np.array([[0.0, 1.5, 255.99], [np.nan, -3.0, 17.00390625]], dtype=np.float32)
    path = tmp_path / "disp.png"
    write_kitti_disparity(path, disp)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16
    np.testing.assert_array_equal(raw, [[0, 384, 65533], [0, 0, 4353]])
    back = read_kitti_disparity(path)
    assert np.isnan(back[0, 0]) and np.isnan(back[1, 0]) and np.isnan(back[1, 1])
    np.testing.assert_allclose(back[[0, 0, 1], [1, 2, 2]], [1.5, 255.98828125, 17.00390625])


def test_kitti_png_refuses_out_of_range(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="does not fit uint16"):
        write_kitti_disparity(tmp_path / "d.png", np.full((2, 2), 300.0))


def test_authors_disparity_and_scale_csv(tmp_path: Path) -> None:
    disp = np.array([[0.0, 2.0], [10.03, 4095.9]])
    png = tmp_path / "frame_0001.png"
    write_authors_disparity(png, disp)
    np.testing.assert_array_equal(cv2.imread(str(png), cv2.IMREAD_UNCHANGED), [[0, 32], [160, 65534]])
    # A right view made with scale s has CSV factor s / 16: training disparity = s·d.
    s = 3.5
    factors = {"video_frame_sequence_right/v/t/frame_0001.png": s / 16, "a,b/frame_0002.png": 0.25}
    csv = tmp_path / "scale_factors.csv"
    write_scale_factors(csv, factors)
    assert csv.read_text().splitlines()[0] == "video_frame_sequence_right/v/t/frame_0001.png,0.21875"
    assert read_scale_factors(csv) == factors
    training = read_authors_disparity(png, factors["video_frame_sequence_right/v/t/frame_0001.png"])
    np.testing.assert_allclose(training, s * np.round(disp * 16) / 16, rtol=1e-6)


def test_authors_disparity_refuses_nan_and_bad_csv(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="finite"):
        write_authors_disparity(tmp_path / "d.png", np.array([[np.nan, 1.0]]))
    csv = tmp_path / "scale_factors.csv"
    csv.write_text("a.png,0.5\nb.png\n")
    with pytest.raises(FormatError, match=r"scale_factors.csv:2"):
        read_scale_factors(csv)


def test_masks_are_lossless_png(tmp_path: Path) -> None:
    mask = np.random.default_rng(0).random((31, 17)) > 0.5
    path = tmp_path / "mask.png"
    write_mask(path, mask)
    assert set(np.unique(cv2.imread(str(path), cv2.IMREAD_UNCHANGED))) <= {0, 255}
    np.testing.assert_array_equal(read_mask(path), mask)
    with pytest.raises(FormatError, match="lossless"):
        write_mask(tmp_path / "mask.jpg", mask)
    with pytest.raises(FormatError, match="bool"):
        write_mask(path, mask.astype(np.uint8))


def test_cv_mask_gives_opencv_the_layout_it_writes_into() -> None:
    column_major = np.asfortranarray(np.eye(6, 9, dtype=bool))  # how pycocotools decodes RLE
    canvas = cv_mask(column_major)
    assert canvas.flags.c_contiguous and canvas.dtype == np.uint8 and set(np.unique(canvas)) == {0, 1}
    cv2.circle(canvas, (4, 4), 2, 1, -1)  # OpenCV 5 refuses to draw into column-major arrays
    assert canvas[4, 4] == 1
    soft = cv_mask(column_major, np.float32)
    assert soft.flags.c_contiguous and soft.dtype == np.float32 and soft.sum() == 6


def test_authors_jpeg_masks_threshold_at_128(tmp_path: Path) -> None:
    gray = np.array([[0, 127, 128, 255]] * 8, dtype=np.uint8).repeat(8, axis=1)
    path = tmp_path / "m.png"  # PNG so the values stay exact; the rule is the same for JPEG
    cv2.imwrite(str(path), gray)
    np.testing.assert_array_equal(read_mask(path)[0, ::8], [False, False, True, True])
    jpeg = tmp_path / "0001-00-00-illusion.jpg"
    cv2.imwrite(str(jpeg), np.where(np.arange(64)[None, :] >= 32, 255, 0).astype(np.uint8).repeat(16, axis=0))
    back = read_mask(jpeg)
    assert back[:, 36:].all() and not back[:, :28].any()


def test_missing_image_is_a_format_error(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="not found"):
        read_mask(tmp_path / "nope.png")
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(FormatError, match="decode"):
        read_mask(tmp_path / "junk.png")


def test_ply_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (50, 3), dtype=np.uint8)
    path = tmp_path / "cloud.ply"
    write_ply(path, points, colors)
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\nelement vertex 50\n")
    back_points, back_colors = read_ply(path)
    np.testing.assert_array_equal(back_points, points)
    np.testing.assert_array_equal(back_colors, colors)
    write_ply(path, points)
    assert read_ply(path)[1] is None


def test_ply_from_image_and_disparity() -> None:
    image = np.zeros((4, 6, 3), dtype=np.uint8)
    image[1, 2] = [10, 20, 30]
    disp = np.full((4, 6), np.nan)
    disp[1, 2] = 5.0
    disp[3, 5] = 10.0
    points, colors = disparity_point_cloud(image, disp, focal=100.0, baseline=0.1, cx=2.0, cy=2.0)
    # Z = f·B/d; X = (u − cx)·Z/f, Y = (v − cy)·Z/f.
    np.testing.assert_allclose(points, [[0.0, -0.02, 2.0], [0.03, 0.01, 1.0]], atol=1e-6)
    np.testing.assert_array_equal(colors, [[10, 20, 30], [0, 0, 0]])


def test_ply_malformed(tmp_path: Path) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(FormatError, match="little-endian"):
        read_ply(path)


@pytest.mark.parametrize("suffix", [".pfm", ".npy", ".png"])
def test_float_maps_by_suffix(tmp_path: Path, suffix: str) -> None:
    disp = np.array([[1.5, 2.25], [np.nan, 100.0]], dtype=np.float32)
    path = tmp_path / f"d{suffix}"
    write_map(path, disp)
    np.testing.assert_array_equal(read_map(path), disp)


def test_float_maps_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="unknown map format"):
        write_map(tmp_path / "d.tiff", np.zeros((2, 2)))
    (tmp_path / "rgb.pfm").write_bytes(b"PF\n1 1\n-1.0\n" + b"\0" * 12)
    with pytest.raises(FormatError, match="single-channel"):
        read_map(tmp_path / "rgb.pfm")


def test_float_maps_from_paths_and_bytes_in_both_png_encodings(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    disparity = rng.uniform(0, 100, (12, 20)).astype(np.float32)
    write_authors_disparity(tmp_path / "d.png", disparity)
    authors = read_map(tmp_path / "d.png", png="authors")
    assert authors.dtype == np.float32 and np.abs(authors - disparity).max() <= 1 / 32 + 1e-4  # round(d·16)/16
    np.testing.assert_allclose(read_map(tmp_path / "d.png", png="authors", scale=0.5), authors * 8)
    assert np.array_equal(read_map((tmp_path / "d.png").read_bytes(), suffix=".png", png="authors"), authors)
    # The same uint16 values read as KITTI: ×1/256 instead of ×1/16, zero → NaN.
    np.testing.assert_allclose(read_map(tmp_path / "d.png"), np.where(authors > 0, authors / 16, np.nan))

    disparity[0, 0] = np.nan
    write_pfm(tmp_path / "d.pfm", disparity)
    np.testing.assert_array_equal(read_map(tmp_path / "d.pfm"), disparity)  # NaN kept
    np.save(tmp_path / "d.npy", disparity.astype(np.float64))
    from_npy = read_map(tmp_path / "d.npy")
    assert from_npy.dtype == np.float64  # dtype kept
    np.testing.assert_array_equal(from_npy, disparity)
    assert np.array_equal(read_map((tmp_path / "d.npy").read_bytes(), suffix=".npy"), from_npy, equal_nan=True)


def test_float_maps_refuse_what_they_cannot_read(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "eight.png"), np.zeros((4, 4), np.uint8))
    np.save(tmp_path / "rgb.npy", np.zeros((4, 4, 3), np.float32))
    np.save(tmp_path / "objects.npy", np.array([{"a": 1}], dtype=object))
    buf = io.BytesIO()
    np.save(buf, np.zeros((4, 4), bool))
    for source, options, message in [
        (tmp_path / "eight.png", {"png": "authors"}, "single-channel 16-bit PNG"),
        (tmp_path / "eight.png", {}, "single-channel 16-bit PNG"),
        (tmp_path / "rgb.npy", {}, r"single-channel HxW map, got shape \(4, 4, 3\)"),
        (tmp_path / "objects.npy", {}, "not a readable .npy array"),
        (buf.getvalue(), {"suffix": ".npy"}, "expected real numbers, got dtype bool"),
        (b"Pf\n4 4\n-1\n", {"suffix": ".pfm"}, "truncated PFM data"),
        (b"\x89PNG", {}, "must be given"),
        (b"\x89PNG", {"suffix": ".png"}, "not an image OpenCV can decode"),
        (tmp_path / "d.tiff", {}, "unknown map format"),
        (tmp_path / "missing.pfm", {}, "cannot read"),
        (tmp_path / "eight.png", {"png": "jpeg"}, "unknown PNG disparity encoding"),
        (tmp_path / "eight.png", {"png": "authors", "scale": 0.0}, "scale must be a finite number > 0"),
    ]:
        with pytest.raises(FormatError, match=message):
            read_map(source, **options)
