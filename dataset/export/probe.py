"""Cheap checks of raster files in a dataset folder: their size without decoding the pixels."""

from __future__ import annotations

import io
from pathlib import Path

from PIL import Image

from core.formats import FormatError, decode_pfm
from dataset.export.errors import LayoutError


def raster_shape(data: bytes, path: Path) -> tuple[int, int, int]:
    """(height, width, channels) of PNG/JPEG bytes (from the header) or PFM bytes."""
    if path.suffix.lower() == ".pfm":
        try:
            array = decode_pfm(data, str(path))
        except FormatError as exc:
            raise LayoutError(str(exc)) from None
        return array.shape[0], array.shape[1], 1 if array.ndim == 2 else array.shape[2]
    try:
        with Image.open(io.BytesIO(data)) as image:
            return image.height, image.width, len(image.getbands())
    except (OSError, Image.DecompressionBombError) as exc:
        raise LayoutError(f"{path}: not a readable image ({exc})") from None


def check_shape(path: Path, shape: tuple[int, int, int], height: int, width: int, channels: int | None) -> None:
    """Raise a :class:`LayoutError` naming ``path`` unless it is ``width``x``height`` with ``channels``
    (None: any number of channels)."""
    h, w, c = shape
    if (h, w) != (height, width):
        raise LayoutError(f"{path}: {w}x{h} pixels, but its frame is {width}x{height}")
    if channels is not None and c != channels:
        raise LayoutError(f"{path}: {c} channel(s), expected {channels}")
