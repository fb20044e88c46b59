"""The one sample type every dataset reader yields, its camera, the reader protocol, and resizing.

Conventions: images RGB uint8 H×W×3; disparity float32 H×W in pixels of the left view, NaN where
there is no ground truth; regions bool H×W, each a subset of ``all`` (= finite ground truth), so a
region's pixels are exactly the pixels it is evaluated on.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import cv2
import numpy as np

from core.formats import FormatError
from core.geometry.camera import disparity_to_depth
from dataset.export.errors import LayoutError


class SampleError(LayoutError):
    """One sample cannot be read (a missing or broken file); the message names the sample and file,
    and an evaluation skips that sample and reports it."""


@dataclass(frozen=True)
class Camera:
    """What turns disparity into depth: depth = ``fx``·``baseline`` / (disparity + ``doffs``).

    ``fx`` in pixels of the sample's resolution, ``baseline`` in metres, ``doffs`` the principal
    points' x-difference in pixels (Middlebury; 0 for rectified rigs), ``depth_range`` the
    (near, far) metres of trustworthy ground truth, if the dataset defines one.
    """

    fx: float
    baseline: float
    doffs: float = 0.0
    depth_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not (self.fx > 0 and self.baseline > 0):
            raise ValueError(f"a camera needs fx > 0 px and baseline > 0 m, got fx={self.fx}, baseline={self.baseline}")

    def depth(self, disparity: np.ndarray) -> np.ndarray:
        """Depth (float32 H×W, metres) of a disparity map (pixels); 0 where disparity + doffs ≤ 0 or NaN."""
        return disparity_to_depth(np.asarray(disparity, np.float32) + np.float32(self.doffs), self.baseline, self.fx)

    def scaled(self, factor: float) -> Camera:
        """The camera of the images resized by ``factor`` (focal length and doffs scale, the baseline does not)."""
        return replace(self, fx=self.fx * factor, doffs=self.doffs * factor)


@dataclass
class StereoSample:
    """One rectified stereo pair with its ground truth (see the module docstring for units)."""

    name: str  # stable relative id within its dataset, e.g. "Adirondack" or "video_3/000007"
    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    regions: dict[str, np.ndarray]
    mono: np.ndarray | None = None  # float32 H×W relative (affine-invariant) disparity, if carried
    camera: Camera | None = None
    meta: dict[str, Any] = field(default_factory=dict)  # source paths ("left" relative to the root), ids, kind…

    def __post_init__(self) -> None:
        shape = self.disparity.shape
        if self.left.shape != (*shape, 3) or self.right.shape != self.left.shape:
            raise ValueError(f"{self.name}: left {self.left.shape}, right {self.right.shape} and disparity {shape} "
                             "do not match (expected H×W×3, H×W×3, H×W)")
        if "all" not in self.regions or any(m.shape != shape or m.dtype != np.bool_ for m in self.regions.values()):
            raise ValueError(f"{self.name}: regions must be bool H×W masks including 'all'")
        if self.mono is not None and self.mono.shape != shape:
            raise ValueError(f"{self.name}: mono {self.mono.shape} does not match disparity {shape}")


@runtime_checkable
class Reader(Protocol):
    """A dataset: names listed at open, a sample read only when asked for."""

    names: list[str]

    def __len__(self) -> int: ...

    def __getitem__(self, i: int) -> StereoSample: ...


class ListedReader:
    """A reader over a list of names and one loader per name; wraps any file problem into a
    :class:`SampleError` naming the sample (the file is named by the underlying error)."""

    default_factor = 1.0  # the resolution a benchmark is evaluated at by convention (Booster: 1/4)

    def __init__(self, root: Path, names: list[str], load: Callable[[str], StereoSample]) -> None:
        self.root, self.names, self._load = root, names, load

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, i: int) -> StereoSample:
        name = self.names[i]
        try:
            return self._load(name)
        except SampleError:
            raise
        except (FormatError, LayoutError, ValueError, OSError) as exc:
            raise SampleError(f"sample {name!r}: {exc}") from None


def make_regions(disparity: np.ndarray, masks: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """``all`` = finite disparity, and each given mask restricted to it."""
    valid = np.isfinite(disparity)
    return {"all": valid, **{name: np.asarray(mask, bool) & valid for name, mask in (masks or {}).items()}}


def invalidate(disparity: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """float32 disparity with NaN wherever ``valid`` is false or the value is not finite."""
    disp = np.asarray(disparity, np.float32)
    return np.where(valid & np.isfinite(disp), disp, np.float32(np.nan))


def optional_camera(fx: float | None, baseline: float | None, *, doffs: float = 0.0,
                    depth_range: tuple[float, float] | None = None) -> Camera | None:
    """A camera from reader options, or None when neither ``fx`` nor ``baseline`` is given."""
    if fx is None and baseline is None:
        return None
    if fx is None or baseline is None:
        raise LayoutError(f"a camera needs both fx (px) and baseline (m); got fx={fx}, baseline={baseline}")
    return Camera(float(fx), float(baseline), float(doffs), None if depth_range is None else
                  (float(depth_range[0]), float(depth_range[1])))


def require_dir(root: Path, fmt: str, expected: str) -> Path:
    """``root`` as an absolute folder, or a :class:`LayoutError` that says which layout was expected."""
    root = Path(root).absolute()
    if not root.is_dir():
        raise LayoutError(f"{root}: no such folder (expected a {fmt} dataset: {expected})")
    return root


def not_layout(root: Path, fmt: str, expected: str) -> LayoutError:
    return LayoutError(f"{root}: not a {fmt} dataset; expected {expected}")


def resample_disparity(disparity: np.ndarray, resample: Callable[[np.ndarray, int], np.ndarray],
                       factor: float) -> np.ndarray:
    """Disparity (float32, NaN = invalid) through ``resample(array, cv2 interpolation)`` (a resize
    or a warp), values × ``factor``. Interpolation is normalised by the valid neighbours (invalid
    pixels never blend in as zeros), and a pixel is valid iff its nearest source pixel is, so NaN
    stays invalid and no new holes open."""
    disp = np.asarray(disparity, np.float32)
    valid = np.isfinite(disp)
    weight = resample(valid.astype(np.float32), cv2.INTER_LINEAR)
    total = resample(np.where(valid, disp, 0).astype(np.float32), cv2.INTER_LINEAR)
    keep = resample(valid.astype(np.uint8), cv2.INTER_NEAREST).astype(bool) & (weight > 1e-6)
    out = np.full(weight.shape, np.nan, np.float32)
    out[keep] = total[keep] / weight[keep] * np.float32(factor)
    return out


def resize_disparity(disparity: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Disparity (float32 H×W, NaN = invalid) resized to ``size`` = (height, width), values × the
    width ratio (:func:`resample_disparity`; area-averaged when shrinking)."""
    height, width = size
    shrink = width < disparity.shape[1]

    def resize(array: np.ndarray, interpolation: int) -> np.ndarray:
        if shrink and interpolation == cv2.INTER_LINEAR:
            interpolation = cv2.INTER_AREA
        return cv2.resize(array, (width, height), interpolation=interpolation)

    if (height, width) == disparity.shape:
        return np.asarray(disparity, np.float32).copy()
    return resample_disparity(disparity, resize, width / disparity.shape[1])


def resize_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A bool H×W mask resized nearest to ``size`` = (height, width)."""
    height, width = size
    return cv2.resize(mask.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST).astype(bool)


def resize_image(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """An image (or float map without NaN) resized to ``size`` = (height, width): area when shrinking, linear else."""
    height, width = size
    interpolation = cv2.INTER_AREA if width < image.shape[1] else cv2.INTER_LINEAR
    return cv2.resize(image, (width, height), interpolation=interpolation)


def resize_sample(sample: StereoSample, factor: float) -> StereoSample:
    """The sample at ``factor`` × its resolution: images area/linear, disparity × the width ratio
    (:func:`resize_disparity`), regions nearest (kept inside ``all``), mono resized with its
    values kept, the camera's focal length scaled."""
    if not factor > 0:
        raise ValueError(f"resize factor must be > 0, got {factor}")
    h, w = sample.disparity.shape
    size = (max(1, round(h * factor)), max(1, round(w * factor)))
    if size == (h, w):
        return sample
    disparity = resize_disparity(sample.disparity, size)
    regions = make_regions(disparity, {k: resize_mask(m, size) for k, m in sample.regions.items() if k != "all"})
    mono = None
    if sample.mono is not None:
        mono = resize_disparity(sample.mono, size) / np.float32(size[1] / w)  # relative: values kept
    camera = sample.camera.scaled(size[1] / w) if sample.camera is not None else None
    return replace(sample, left=resize_image(sample.left, size), right=resize_image(sample.right, size),
                   disparity=disparity, regions=regions, mono=mono, camera=camera,
                   meta={**sample.meta, "resize_factor": factor})
