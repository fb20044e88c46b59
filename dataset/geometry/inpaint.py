"""Hole filling for synthesized views: OpenCV Telea / Navier–Stokes, none, or LaMa (TorchScript).

LaMa is the only torch user in the geometry core; torch is imported lazily inside it so the
rest of the package runs without torch installed.
"""

from __future__ import annotations

import warnings
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal, get_args

import cv2
import numpy as np

from dataset.geometry import checks
from dataset.geometry.errors import InpaintError

InpaintMethod = Literal["telea", "ns", "none", "lama"]
INPAINT_METHODS: tuple[str, ...] = get_args(InpaintMethod)
_OPENCV_FLAGS = {"telea": cv2.INPAINT_TELEA, "ns": cv2.INPAINT_NS}
# The common big-lama TorchScript export needs H and W divisible by 8.
_LAMA_MULTIPLE = 8


def inpaint_holes(
    image: np.ndarray,
    holes: np.ndarray,
    method: InpaintMethod = "telea",
    *,
    lama_model: str | Path | None = None,
    radius: int = 3,
) -> np.ndarray:
    """Fill the ``holes`` (bool HxW) of ``image`` (uint8 HxW or HxWx3); returns a new uint8 image.

    ``telea``/``ns``: OpenCV's inpainting with a ``radius``-px neighbourhood; ``none``: holes
    are left as they are; ``lama``: the TorchScript LaMa model at ``lama_model`` (RGB order
    expected). Pixels outside ``holes`` are never changed.
    """
    img = checks.image(image, "image")
    hole_mask = checks.mask(holes, "holes", img.shape[:2])
    check_method(method, lama_model)
    if method == "none" or not hole_mask.any():
        return img.copy()
    if method == "lama":
        return _lama(img, hole_mask, Path(lama_model))  # type: ignore[arg-type]
    return cv2.inpaint(img, hole_mask.astype(np.uint8), radius, _OPENCV_FLAGS[method])


def _lama(image: np.ndarray, holes: np.ndarray, model_path: Path) -> np.ndarray:
    import torch

    model = _load_lama(str(model_path.expanduser().resolve()))
    rgb = np.repeat(image[:, :, None], 3, axis=2) if image.ndim == 2 else image
    h, w = holes.shape
    pad = ((0, -h % _LAMA_MULTIPLE), (0, -w % _LAMA_MULTIPLE))
    # The same padding for image and mask, so padded hole pixels stay marked as holes.
    mode = "reflect" if min(h, w) > 1 else "edge"
    rgb_padded = np.pad(rgb, (*pad, (0, 0)), mode=mode)
    holes_padded = np.pad(holes, pad, mode=mode)
    x = torch.from_numpy(rgb_padded).permute(2, 0, 1)[None].float().div_(255.0)
    m = torch.from_numpy(holes_padded)[None, None].float()
    with torch.inference_mode():
        result = model(x, m)
    if not isinstance(result, torch.Tensor) or tuple(result.shape) != (1, 3, *holes_padded.shape):
        shape = tuple(result.shape) if isinstance(result, torch.Tensor) else type(result).__name__
        raise InpaintError(f"LaMa model returned {shape}, expected a 1x3x{holes_padded.shape[0]}x{holes_padded.shape[1]} tensor")
    filled = result[0, :, :h, :w].permute(1, 2, 0).clamp(0, 1).mul(255).round().to(torch.uint8).numpy()
    out = rgb.copy()
    out[holes] = filled[holes]
    return out[:, :, 0].copy() if image.ndim == 2 else out


@lru_cache(maxsize=2)
def _load_lama(path: str) -> Any:
    import torch

    if not Path(path).is_file():
        raise InpaintError(f"LaMa model file {path} does not exist")
    try:
        with warnings.catch_warnings():
            # LaMa ships as TorchScript (big-lama.pt); newer torch deprecates the loader in
            # favour of torch.export, which cannot read these files.
            warnings.simplefilter("ignore", DeprecationWarning)
            model = torch.jit.load(path, map_location="cpu")
    except (RuntimeError, ValueError) as exc:
        raise InpaintError(f"{path} is not a TorchScript model: {exc}") from None
    model.eval()
    return model


def check_method(method: str, lama_model: str | Path | None = None) -> InpaintMethod:
    """``method`` as an :data:`InpaintMethod`; :class:`InpaintError` for an unknown one or
    for ``lama`` without a model path."""
    if method not in INPAINT_METHODS:
        raise InpaintError(f"unknown inpainting method {method!r}; choose one of {', '.join(INPAINT_METHODS)}")
    if method == "lama" and lama_model is None:
        raise InpaintError("LaMa inpainting needs a TorchScript model path (--lama-model / lama_model_path)")
    return method  # type: ignore[return-value]
