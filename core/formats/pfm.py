"""PFM (Portable Float Map): float32 gray ("Pf") or RGB ("PF") images, either endianness.

The file stores rows bottom to top; arrays here are top to bottom (row 0 = image top).
NaN and inf values are kept bit for bit.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from core.formats.errors import FormatError
from core.formats.images import read_bytes

# Magic, width, height and scale, each followed by whitespace; the data starts one byte later.
_HEADER = re.compile(rb"\A(P[Ff])\s+(\d+)\s+(\d+)\s+([-+0-9.eE]+)\s")


def read_pfm(path: str | Path) -> np.ndarray:
    """Read a PFM file as float32 HxW ("Pf") or HxWx3 ("PF"), native byte order."""
    return decode_pfm(read_bytes(path), str(path))


def decode_pfm(raw: bytes, name: str = "PFM data") -> np.ndarray:
    """PFM bytes → float32 HxW or HxWx3 (``name`` goes into error messages)."""
    path = name
    match = _HEADER.match(raw[:256])
    if match is None:
        raise FormatError(f"{path}: not a PFM file (expected 'PF'/'Pf', width, height, scale header)")
    magic, width, height, scale_text = match.groups()
    try:
        scale = float(scale_text)
    except ValueError:
        raise FormatError(f"{path}: bad PFM scale {scale_text!r}") from None
    if scale == 0:
        raise FormatError(f"{path}: PFM scale must be non-zero (its sign gives the byte order)")
    channels = 3 if magic == b"PF" else 1
    shape = (int(height), int(width)) + ((3,) if channels == 3 else ())
    count = int(height) * int(width) * channels
    data = raw[match.end() :]
    if len(data) < 4 * count:
        raise FormatError(f"{path}: truncated PFM data: {len(data)} bytes for {shape} (needs {4 * count})")
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    array = np.frombuffer(data, dtype=dtype, count=count).reshape(shape)
    return np.flipud(array).astype(np.float32)


def write_pfm(path: str | Path, array: np.ndarray, *, little_endian: bool = True) -> None:
    """Write float HxW (gray) or HxWx3 (colour) data as PFM, in the chosen byte order."""
    Path(path).write_bytes(encode_pfm(array, little_endian=little_endian))


def encode_pfm(array: np.ndarray, *, little_endian: bool = True) -> bytes:
    """Float HxW or HxWx3 → PFM bytes."""
    data = np.asarray(array)
    if not (np.issubdtype(data.dtype, np.floating) or np.issubdtype(data.dtype, np.integer)) or data.dtype == np.bool_:
        raise FormatError(f"PFM stores real numbers, got dtype {data.dtype}")
    if not (data.ndim == 2 or (data.ndim == 3 and data.shape[2] == 3)) or data.size == 0:
        raise FormatError(f"PFM stores HxW or HxWx3 arrays, got shape {data.shape}")
    magic = "PF" if data.ndim == 3 else "Pf"
    dtype = np.dtype("<f4" if little_endian else ">f4")
    header = f"{magic}\n{data.shape[1]} {data.shape[0]}\n{-1.0 if little_endian else 1.0}\n".encode("ascii")
    return header + np.ascontiguousarray(np.flipud(data), dtype=dtype).tobytes()
