"""Float HxW maps (disparity, depth) in files or bytes, the format chosen by the file suffix.

``.pfm`` (float32, NaN kept), ``.npy`` (real dtype kept; no pickles) and ``.png``: a 16-bit
disparity PNG in the encoding ``png`` names — ``"kitti"`` (uint16 = round(d·256), 0 = invalid ↔
NaN; what :func:`write_map` writes) or ``"authors"`` (their ``depth_rect``: disparity =
uint16 · ``scale``, 1/16 giving their unscaled disparity, no invalid marker).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Literal

import numpy as np

from core.formats.disparity_png import (
    AUTHORS_FACTOR,
    decode_authors_disparity,
    decode_kitti_disparity,
    write_kitti_disparity,
)
from core.formats.errors import FormatError
from core.formats.images import read_bytes
from core.formats.pfm import decode_pfm, write_pfm

MAP_SUFFIXES = (".pfm", ".npy", ".png")
PngEncoding = Literal["kitti", "authors"]
PNG_ENCODINGS: tuple[PngEncoding, ...] = ("kitti", "authors")


def read_map(source: str | Path | bytes, *, suffix: str | None = None, png: PngEncoding = "kitti",
             scale: float = 1 / AUTHORS_FACTOR) -> np.ndarray:
    """Read a float HxW map from a file, or from its bytes with ``suffix`` naming the format.

    ``png`` picks the PNG disparity encoding (``scale`` applies to ``"authors"`` only). Raises
    :class:`FormatError` naming the source for anything that is not a single-channel map.
    """
    if png not in PNG_ENCODINGS:
        raise FormatError(f"unknown PNG disparity encoding {png!r}; use one of {', '.join(PNG_ENCODINGS)}")
    if isinstance(source, bytes):
        if suffix is None:
            raise FormatError(f"the format of in-memory map data must be given: suffix one of {', '.join(MAP_SUFFIXES)}")
        name = "map data"
    else:
        name = str(source)
        suffix = suffix or Path(source).suffix
    suffix = suffix.lower()
    if suffix not in MAP_SUFFIXES:
        raise FormatError(f"{name}: unknown map format; use one of {', '.join(MAP_SUFFIXES)}")
    data = source if isinstance(source, bytes) else read_bytes(source)
    if suffix == ".pfm":
        array = decode_pfm(data, name)
    elif suffix == ".npy":
        array = decode_npy(data, name)
    elif png == "kitti":
        array = decode_kitti_disparity(data, name)
    else:
        array = decode_authors_disparity(data, name, scale)
    if array.ndim != 2:
        raise FormatError(f"{name}: expected a single-channel HxW map, got shape {array.shape}")
    return array


def decode_npy(data: bytes, name: str = "npy data") -> np.ndarray:
    """``.npy`` bytes → the array (real numbers only, no pickles; ``name`` goes into errors)."""
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{name}: not a readable .npy array: {exc}") from None
    if array.dtype == np.bool_ or array.dtype.kind not in "iuf":
        raise FormatError(f"{name}: expected real numbers, got dtype {array.dtype}")
    return array


def write_map(path: str | Path, array: np.ndarray) -> None:
    """Write a float HxW map as ``.pfm``, ``.npy`` or KITTI ``.png`` (by suffix)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".pfm":
        write_pfm(path, array)
    elif suffix == ".npy":
        np.save(path, np.asarray(array))
    elif suffix == ".png":
        write_kitti_disparity(path, array)
    else:
        raise FormatError(f"{path}: unknown map format; use one of {', '.join(MAP_SUFFIXES)}")
