"""Reading and writing raster files through OpenCV with clear errors (shared by the formats)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from core.formats.errors import FormatError


def read_bytes(path: str | Path) -> bytes:
    """A file's bytes; :class:`FormatError` naming the file when it is missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: cannot read: file not found")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise FormatError(f"{path}: cannot read: {exc}") from None


def read_image(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """``cv2.imread`` that raises :class:`FormatError` for a missing or undecodable file."""
    return decode_image(read_bytes(path), str(path), flags)


def decode_image(data: bytes, name: str, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """``cv2.imdecode`` of a file's bytes; :class:`FormatError` naming ``name`` if undecodable."""
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flags) if data else None
    if image is None:
        raise FormatError(f"{name}: not an image OpenCV can decode")
    return image


def read_rgb(path: str | Path) -> np.ndarray:
    """An 8-bit colour image as uint8 HxWx3 in RGB order."""
    return cv2.cvtColor(read_image(path, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def write_rgb(path: str | Path, image: np.ndarray) -> None:
    """Write uint8 HxWx3 RGB (or HxW gray) losslessly; the suffix must be ``.png``."""
    data = np.asarray(image)
    write_png(path, cv2.cvtColor(data, cv2.COLOR_RGB2BGR) if data.ndim == 3 else data)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write a uint8/uint16 image as PNG; other suffixes are refused (lossless only)."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise FormatError(f"{path}: must be a .png file (lossless)")
    if image.dtype not in (np.uint8, np.uint16):
        raise FormatError(f"{path}: PNG stores uint8/uint16, got {image.dtype}")
    if not cv2.imwrite(str(path), image):
        raise FormatError(f"{path}: OpenCV could not write the PNG")
