"""LaMa (big-lama) as a TorchScript export: image and mask in [0, 1], the filled image out.

The common ``big-lama.pt`` export takes (1x3xHxW RGB, 1x1xHxW mask) and needs H and W divisible
by 8: inputs are padded by reflection (image and mask alike, so padded hole pixels stay holes)
and the result cropped back.
"""

from __future__ import annotations

import hashlib
import warnings
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch

from annotation.inpaint.base import InpainterError, check_input

_LAMA_MULTIPLE = 8


class LamaInpainter:
    """Hole filling with a TorchScript LaMa file (loaded once per file and device)."""

    name = "lama"

    def __init__(self, model_path: Path, device: str = "cpu") -> None:
        path = Path(model_path).expanduser().resolve()
        try:
            self.device = torch.device(device)
        except RuntimeError as exc:
            raise InpainterError(f"bad torch device {device!r}: {exc}") from None
        if not path.is_file():
            raise InpainterError(f"LaMa model file {path} does not exist")
        stat = path.stat()
        stamp = f"{stat.st_size}:{stat.st_mtime_ns}"  # a replaced file is loaded anew and named anew
        self.model = _load(str(path), str(self.device), stamp)
        self.model_id = f"{self.name}:{path.name}:{hashlib.sha256(stamp.encode()).hexdigest()[:12]}"

    def inpaint(self, image: np.ndarray, holes: np.ndarray) -> np.ndarray:
        """``image`` (uint8 HxW or HxWx3 RGB) with ``holes`` (bool HxW) filled by LaMa."""
        image, holes = check_input(image, holes)
        rgb = np.repeat(image[:, :, None], 3, axis=2) if image.ndim == 2 else image
        h, w = holes.shape
        pad = ((0, -h % _LAMA_MULTIPLE), (0, -w % _LAMA_MULTIPLE))
        mode = "reflect" if min(h, w) > 1 else "edge"
        rgb_padded = np.pad(rgb, (*pad, (0, 0)), mode=mode)
        holes_padded = np.pad(holes, pad, mode=mode)
        x = torch.from_numpy(rgb_padded).permute(2, 0, 1)[None].float().div_(255.0).to(self.device)
        m = torch.from_numpy(holes_padded)[None, None].float().to(self.device)
        with torch.inference_mode():
            result = self.model(x, m)
        if not isinstance(result, torch.Tensor) or tuple(result.shape) != (1, 3, *holes_padded.shape):
            shape = tuple(result.shape) if isinstance(result, torch.Tensor) else type(result).__name__
            expected = "x".join(str(n) for n in (1, 3, *holes_padded.shape))
            raise InpainterError(f"LaMa model returned {shape}, expected a {expected} tensor")
        filled = result[0, :, :h, :w].permute(1, 2, 0).clamp(0, 1).mul(255).round().to(torch.uint8).cpu().numpy()
        out = rgb.copy()
        out[holes] = filled[holes]
        return out[:, :, 0].copy() if image.ndim == 2 else out


@lru_cache(maxsize=2)
def _load(path: str, device: str, stamp: str) -> Any:
    """The TorchScript module at ``path`` on ``device``; ``stamp`` (size:mtime) keys the cache."""
    try:
        with warnings.catch_warnings():
            # LaMa ships as TorchScript (big-lama.pt); newer torch deprecates the loader in
            # favour of torch.export, which cannot read these files.
            warnings.simplefilter("ignore", DeprecationWarning)
            model = torch.jit.load(path, map_location=device)
    except (RuntimeError, ValueError) as exc:
        raise InpainterError(f"{path} is not a TorchScript model: {exc}") from None
    model.eval()
    return model
