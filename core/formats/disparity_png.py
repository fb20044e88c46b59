"""16-bit PNG disparity: KITTI's ×256 encoding and the authors' ×16 + scale CSV.

KITTI: uint16 = round(d·256), 0 = invalid. Authors' ``depth_rect``: uint16 = round(d·16) of
the unscaled disparity d; ``meta_data/scale_factors.csv`` (no header, ``<right_image>,<scale>``)
holds per frame the factor with training disparity = uint16 · scale. For a right view made
with scale s (right = left at u − s·d) that factor is s / 16.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from core.formats.errors import FormatError
from core.formats.images import decode_image, read_bytes, write_png

KITTI_FACTOR = 256
AUTHORS_FACTOR = 16
_UINT16_MAX = np.iinfo(np.uint16).max


def write_kitti_disparity(path: str | Path, disparity: np.ndarray) -> None:
    """Write disparity (HxW, pixels) as KITTI uint16 ×256; NaN/inf or ≤ 0 become 0 (invalid).

    Raises :class:`FormatError` when a value exceeds 255.99 px (not representable).
    """
    disp = _float_map(disparity)
    valid = np.isfinite(disp) & (disp > 0)
    write_png(path, _encode(np.where(valid, disp, 0), KITTI_FACTOR, path))


def read_kitti_disparity(path: str | Path) -> np.ndarray:
    """Read a KITTI disparity PNG as float32 HxW pixels, NaN where invalid (stored 0)."""
    return decode_kitti_disparity(read_bytes(path), str(path))


def decode_kitti_disparity(data: bytes, name: str = "KITTI disparity PNG") -> np.ndarray:
    """KITTI PNG bytes → float32 HxW pixels, NaN where invalid (``name`` goes into errors)."""
    raw = _decode_uint16(data, name)
    return np.where(raw > 0, raw.astype(np.float32) / KITTI_FACTOR, np.float32(np.nan))


def write_authors_disparity(path: str | Path, disparity: np.ndarray) -> None:
    """Write unscaled disparity (HxW, ≥ 0, finite) as the authors' uint16 round(d·16) PNG."""
    disp = _float_map(disparity)
    if not np.isfinite(disp).all() or (disp < 0).any():
        raise FormatError("the authors' ×16 PNG has no invalid marker: disparity must be finite and ≥ 0")
    write_png(path, _encode(disp, AUTHORS_FACTOR, path))


def read_authors_disparity(path: str | Path, scale: float) -> np.ndarray:
    """Read an authors' ``depth_rect`` PNG as float32 training disparity = uint16 · ``scale``."""
    return decode_authors_disparity(read_bytes(path), str(path), scale)


def decode_authors_disparity(data: bytes, name: str = "authors' disparity PNG", scale: float = 1 / AUTHORS_FACTOR) -> np.ndarray:
    """Authors' PNG bytes → float32 HxW disparity = uint16 · ``scale`` (1/16: their unscaled d)."""
    if not (np.isfinite(scale) and scale > 0):
        raise FormatError(f"scale must be a finite number > 0, got {scale}")
    return _decode_uint16(data, name).astype(np.float32) * np.float32(scale)


def read_scale_factors(path: str | Path) -> dict[str, float]:
    """Read ``scale_factors.csv``: ``<right_image_path>,<scale>`` per line, no header."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: cannot read: {exc}") from None
    factors: dict[str, float] = {}
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        # Split at the last comma: image paths may themselves contain commas.
        name, sep, value = line.rpartition(",")
        try:
            scale = float(value)
        except ValueError:
            scale = float("nan")
        if not sep or not name or not (np.isfinite(scale) and scale > 0):
            raise FormatError(f"{path}:{number}: expected '<right_image_path>,<scale > 0>', got {line!r}")
        factors[name] = scale
    return factors


def write_scale_factors(path: str | Path, factors: dict[str, float]) -> None:
    """Write ``scale_factors.csv`` (no header), one ``<right_image_path>,<scale>`` per line."""
    lines = []
    for name, scale in factors.items():
        if "\n" in name or "\r" in name or not name:
            raise FormatError(f"image path {name!r} cannot be stored in a CSV line")
        if not (np.isfinite(scale) and scale > 0):
            raise FormatError(f"scale for {name} must be a finite number > 0, got {scale}")
        lines.append(f"{name},{float(scale)!r}\n")
    Path(path).write_text("".join(lines), encoding="utf-8")


def _float_map(disparity: np.ndarray) -> np.ndarray:
    disp = np.asarray(disparity)
    if disp.ndim != 2 or not np.issubdtype(disp.dtype, np.floating):
        raise FormatError(f"disparity must be a float HxW array, got {disp.dtype} {disp.shape}")
    return disp


def _encode(disp: np.ndarray, factor: int, path: str | Path) -> np.ndarray:
    scaled = np.rint(disp.astype(np.float64) * factor)
    if scaled.max() > _UINT16_MAX:
        raise FormatError(
            f"{path}: disparity up to {disp.max():.3f} px does not fit uint16 at ×{factor} "
            f"(max {_UINT16_MAX / factor:.3f})"
        )
    return scaled.astype(np.uint16)


def _decode_uint16(data: bytes, name: str) -> np.ndarray:
    raw = decode_image(data, name, cv2.IMREAD_UNCHANGED)
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise FormatError(f"{name}: expected a single-channel 16-bit PNG, got {raw.dtype} with shape {raw.shape}")
    return raw
