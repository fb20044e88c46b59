"""A ``torch.utils.data.Dataset`` over one split of a native export (see ``NATIVE_FORMAT.md``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from dataset.export.errors import LayoutError
from dataset.export.manifest import read_manifest
from dataset.formats import read_mask, read_pfm, read_rgb

Item = dict[str, Any]


class IllusionStereoDataset(Dataset[Item]):
    """The samples of ``split`` as dicts of tensors (H x W of the frame):

    - ``left``, ``right``: float32 3xHxW in [0, 1] (RGB);
    - ``disparity``: float32 1xHxW, pixels, the training target (NaN and inf → 0);
    - ``valid``: bool 1xHxW, finite disparity ∧ the sample's valid mask (captures); right-view
      holes never enter it (why: ``NATIVE_FORMAT.md``, "In PyTorch");
    - ``illusion``: bool 1xHxW, the union of the sample's illusion masks;
    - ``meta``: {"id", "video", "index", "scale"} (str, str, int, float: default collation works).

    ``transform`` (optional) maps that dict to whatever the model wants.
    """

    def __init__(self, root: str | Path, split: str = "train", transform: Callable[[Item], Any] | None = None) -> None:
        self.root = Path(root)
        manifest = read_manifest(self.root)
        names = [s["name"] for s in manifest["splits"]]
        if split not in names:
            raise LayoutError(f"{self.root}: no split {split!r}; this export has {', '.join(names)}")
        self.samples = [s for s in manifest["samples"] if s["split"] == split]
        self.transform = transform

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> Any:
        entry = self.samples[i]
        files = entry["files"]
        disparity = read_pfm(self._path(files["disparity"]))
        finite = np.isfinite(disparity)
        valid = finite.copy()
        if "valid" in files:
            valid &= read_mask(self._path(files["valid"]))
        illusion = np.zeros_like(valid)
        for name, spec in files.get("masks", {}).items():
            if name.startswith("illusion_"):
                illusion |= read_mask(self._path(spec))
        item = {
            "left": _image(read_rgb(self._path(files["left"]))), "right": _image(read_rgb(self._path(files["right"]))),
            "disparity": torch.from_numpy(np.where(finite, disparity, np.float32(0))[None].astype(np.float32)),
            "valid": torch.from_numpy(valid[None]), "illusion": torch.from_numpy(illusion[None]),
            "meta": {"id": entry["id"], "video": entry["video"], "index": entry["frame"]["index"],
                     "scale": float(entry["params"].get("scale", 1.0))},
        }
        return self.transform(item) if self.transform else item

    def _path(self, spec: dict[str, str]) -> Path:
        return self.root / spec["path"]


def _image(rgb: np.ndarray) -> torch.Tensor:
    """uint8 HxWx3 → float32 3xHxW in [0, 1]."""
    return torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))).float().div_(255.0)
