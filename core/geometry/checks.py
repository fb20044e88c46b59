"""Input validation shared by the geometry functions: one clear :class:`InputError` per problem."""

from __future__ import annotations

import numpy as np

from core.geometry.errors import InputError


def float_map(array: np.ndarray, name: str, *, allow_nan: bool = True) -> np.ndarray:
    """Return ``array`` as a float HxW map (float32 kept, other reals converted to float64).

    Raises :class:`InputError` for a non-2-D or non-real array, an empty one, one with no
    finite value, or (``allow_nan=False``) one with any non-finite value.
    """
    arr = np.asarray(array)
    if arr.ndim != 2:
        raise InputError(f"{name} must be a 2-D HxW array, got shape {arr.shape}")
    if arr.size == 0:
        raise InputError(f"{name} is empty (shape {arr.shape})")
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InputError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.dtype != np.float32:
        arr = arr.astype(np.float64, copy=False)
    finite = np.isfinite(arr)
    if not finite.any():
        raise InputError(f"{name} has no finite value (all NaN/inf)")
    if not allow_nan and not finite.all():
        raise InputError(f"{name} has {int((~finite).sum())} non-finite values")
    return arr


def mask(array: np.ndarray | None, name: str, shape: tuple[int, int]) -> np.ndarray:
    """Return ``array`` as a C-contiguous bool HxW mask of ``shape`` (OpenCV 5 refuses the
    column-major layout decoded COCO RLE has); ``None`` becomes an all-False mask.

    Only bool masks, or integer masks holding just 0 and 1 / 0 and 255, are accepted: anything
    else (e.g. a JPEG-damaged mask with values in between) is an :class:`InputError`.
    """
    if array is None:
        return np.zeros(shape, dtype=bool)
    arr = np.asarray(array)
    if arr.shape != shape:
        raise InputError(f"{name} has shape {arr.shape}, expected {shape} (the disparity's HxW)")
    if arr.dtype == np.bool_:
        return np.ascontiguousarray(arr)
    if not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name} must be bool (or 0/1, 0/255 integers), got dtype {arr.dtype}")
    top = arr.max()
    if top not in (0, 1, 255) or not ((arr == 0) | (arr == top)).all():
        raise InputError(f"{name} holds values other than 0/1 or 0/255 (min {arr.min()}, max {top})")
    return np.ascontiguousarray(arr > 0)


def image(array: np.ndarray, name: str, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Return ``array`` as a uint8 HxW or HxWx3 image, optionally checking its HxW."""
    arr = np.asarray(array)
    if arr.dtype != np.uint8:
        raise InputError(f"{name} must be uint8, got dtype {arr.dtype}")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)):
        raise InputError(f"{name} must be HxW or HxWx3, got shape {arr.shape}")
    if shape is not None and arr.shape[:2] != shape:
        raise InputError(f"{name} is {arr.shape[0]}x{arr.shape[1]} (HxW), expected {shape[0]}x{shape[1]}")
    return arr


def intrinsics(matrix: object, name: str) -> np.ndarray:
    """A 3x3 pinhole matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (float64) with fx, fy > 0."""
    K = _finite_matrix(matrix, name, (3, 3))
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(f"{name} must have positive focal lengths, got fx={K[0, 0]}, fy={K[1, 1]}")
    if not np.allclose([K[0, 1], K[1, 0], K[2, 0], K[2, 1], K[2, 2] - 1], 0):
        raise InputError(f"{name} must look like [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
    return K


def rotation(matrix: object, name: str = "R") -> np.ndarray:
    """A 3x3 rotation matrix (float64): orthonormal to 1e-4 with determinant +1."""
    R = _finite_matrix(matrix, name, (3, 3))
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise InputError(f"{name} is not a rotation matrix (R·Rᵀ ≠ I or det < 0): {R.tolist()}")
    return R


def vector3(vector: object, name: str = "T") -> np.ndarray:
    """A length-3 finite vector (float64); a 3x1 column is accepted."""
    return _finite_matrix(vector, name, (3,), reshape=True)


def positive(value: object, name: str) -> float:
    """A finite number > 0 as float."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a number, got {value!r}")
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def _finite_matrix(value: object, name: str, shape: tuple[int, ...], reshape: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except ValueError:  # ragged nested lists
        arr = np.asarray(None)
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{name} must be numeric with shape {shape}, got {value!r}")
    arr = arr.astype(np.float64)
    if reshape and arr.size == int(np.prod(shape)):
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise InputError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError(f"{name} has NaN or inf entries")
    return arr
