"""Float HxW maps (disparity, depth) on disk, the format chosen by the file suffix.

``.pfm`` (float32, NaN kept), ``.npy`` (dtype kept) and ``.png`` (KITTI uint16 disparity
×256, invalid = 0 ↔ NaN; disparity only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dataset.formats.disparity_png import read_kitti_disparity, write_kitti_disparity
from dataset.formats.errors import FormatError
from dataset.formats.pfm import read_pfm, write_pfm

MAP_SUFFIXES = (".pfm", ".npy", ".png")


def read_map(path: str | Path) -> np.ndarray:
    """Read a float HxW map from ``.pfm``, ``.npy`` or KITTI ``.png``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".pfm":
        data = read_pfm(path)
    elif suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FormatError(f"{path}: not a readable .npy array: {exc}") from None
    elif suffix == ".png":
        data = read_kitti_disparity(path)
    else:
        raise FormatError(f"{path}: unknown map format; use one of {', '.join(MAP_SUFFIXES)}")
    if data.ndim != 2:
        raise FormatError(f"{path}: expected a single-channel HxW map, got shape {data.shape}")
    return data


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
