"""Binary little-endian PLY point clouds (x, y, z float32 + red, green, blue uchar)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.formats.errors import FormatError
from core.geometry.camera import backproject, disparity_to_depth

_VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
_XYZ = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])


def write_ply(path: str | Path, points: np.ndarray, colors: np.ndarray | None = None) -> None:
    """Write N x 3 ``points`` (float, any unit) with optional N x 3 uint8 RGB ``colors``."""
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.issubdtype(pts.dtype, np.number):
        raise FormatError(f"points must be an N x 3 numeric array, got {pts.dtype} {pts.shape}")
    dtype = _XYZ if colors is None else _VERTEX
    vertices = np.empty(len(pts), dtype=dtype)
    vertices["x"], vertices["y"], vertices["z"] = pts.T
    if colors is not None:
        rgb = np.asarray(colors)
        if rgb.shape != pts.shape or rgb.dtype != np.uint8:
            raise FormatError(f"colors must be uint8 with the points' shape {pts.shape}, got {rgb.dtype} {rgb.shape}")
        vertices["red"], vertices["green"], vertices["blue"] = rgb.T
    properties = "".join(f"property {'float' if name in 'xyz' else 'uchar'} {name}\n" for name in dtype.names or ())
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n{properties}end_header\n"
    Path(path).write_bytes(header.encode("ascii") + vertices.tobytes())


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a PLY written by :func:`write_ply`: (N x 3 float32 points, N x 3 uint8 colours or None)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FormatError(f"{path}: cannot read: {exc}") from None
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise FormatError(f"{path}: not a PLY file")
    lines = raw[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in lines:
        raise FormatError(f"{path}: only binary little-endian PLY is supported")
    counts = [line.split()[2] for line in lines if line.startswith("element vertex ")]
    names = tuple(line.split()[-1] for line in lines if line.startswith("property "))
    dtype = next((d for d in (_VERTEX, _XYZ) if d.names == names), None)
    if len(counts) != 1 or not counts[0].isdigit() or dtype is None:
        raise FormatError(f"{path}: expected one vertex element with x, y, z[, red, green, blue], got {names}")
    count = int(counts[0])
    body = raw[end + len(b"end_header\n") :]
    if len(body) < count * dtype.itemsize:
        raise FormatError(f"{path}: truncated: {count} vertices need {count * dtype.itemsize} bytes")
    vertices = np.frombuffer(body, dtype=dtype, count=count)
    points = np.column_stack([vertices["x"], vertices["y"], vertices["z"]]).astype(np.float32)
    colors = np.column_stack([vertices["red"], vertices["green"], vertices["blue"]]) if dtype is _VERTEX else None
    return points, colors


def disparity_point_cloud(
    image: np.ndarray,
    disparity: np.ndarray,
    *,
    focal: float,
    baseline: float,
    cx: float | None = None,
    cy: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Points (N x 3 float32, metres if ``baseline`` is) and RGB colours (N x 3 uint8) of the
    pixels with positive finite disparity. ``image``: uint8 HxWx3 (or HxW gray);
    ``disparity``: HxW pixels; ``focal``: pixels; principal point defaults to the image centre.
    """
    img = np.asarray(image)
    disp = np.asarray(disparity)
    if img.dtype != np.uint8 or img.shape[:2] != disp.shape:
        raise FormatError(f"image must be uint8 with the disparity's HxW {disp.shape}, got {img.dtype} {img.shape}")
    height, width = disp.shape
    cx = (width - 1) / 2 if cx is None else cx
    cy = (height - 1) / 2 if cy is None else cy
    depth = disparity_to_depth(disp, baseline, focal)
    K = np.array([[focal, 0, cx], [0, focal, cy], [0, 0, 1]])
    valid = depth > 0
    rgb = np.repeat(img[:, :, None], 3, axis=2) if img.ndim == 2 else img
    return backproject(depth, K)[valid], rgb[valid]
