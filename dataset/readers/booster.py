"""Booster (Ramirez et al.), the ``train/balanced`` split::

    train/balanced/<scene>/camera_00/im<k>.png     left views (one per illumination)
    train/balanced/<scene>/camera_02/im<k>.png     right views
    train/balanced/<scene>/disp_00.npy             float disparity of camera_00, 0 = invalid
    train/balanced/<scene>/mask_00.png             Booster's valid mask (used with ``valid_mask=True``)
    train/balanced/<scene>/mask_cat.png            material class per pixel (3 = transparent / mirror)

One sample per image pair (``<scene>/im<k>``), all of a scene sharing its ground truth. Valid:
finite and > ``min_disparity`` (0; the authors' script uses 1). Regions ``all``, ``trans``
(``mask_cat == 3``, as the authors' script), ``nontrans`` and ``class_<c>`` for every class
present. The benchmark is evaluated at quarter resolution by convention (``default_factor``).
``root`` is the dataset folder, ``train/`` or ``train/balanced`` itself.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from core.formats import read_image, read_map, read_mask, read_rgb
from dataset.readers.base import ListedReader, StereoSample, invalidate, make_regions, not_layout, optional_camera, require_dir

EXPECTED = "train/balanced/<scene>/{camera_00,camera_02}/im*.png with disp_00.npy and mask_cat.png"
TRANS_CLASS = 3


class BoosterReader(ListedReader):
    default_factor = 0.25

    def __init__(self, root: Path, *, min_disparity: float = 0.0, valid_mask: bool = False,
                 fx: float | None = None, baseline: float | None = None,
                 depth_range: tuple[float, float] | None = None) -> None:
        root = require_dir(root, "booster", EXPECTED)
        self.balanced = next((d for d in (root / "train" / "balanced", root / "balanced", root)
                              if any(d.glob("*/camera_00"))), None)
        if self.balanced is None:
            raise not_layout(root, "booster", EXPECTED)
        self.min_disparity, self.valid_mask = float(min_disparity), valid_mask
        self.camera = optional_camera(fx, baseline, depth_range=depth_range)
        names = [f"{left.parent.parent.name}/{left.stem}"
                 for left in sorted(self.balanced.glob("*/camera_00/im*.png"))]
        if not names:
            raise not_layout(root, "booster", f"{EXPECTED}; no camera_00/im*.png under {self.balanced}")
        super().__init__(root, names, self._read)

    def _read(self, name: str) -> StereoSample:
        scene, image = name.split("/")
        folder = self.balanced / scene
        raw = read_map(folder / "disp_00.npy").astype(np.float32)
        valid = np.isfinite(raw) & (raw > self.min_disparity)
        if self.valid_mask:
            valid &= read_mask(folder / "mask_00.png")
        disparity = invalidate(raw, valid)
        classes = read_image(folder / "mask_cat.png", cv2.IMREAD_GRAYSCALE)
        if classes.shape != disparity.shape:
            raise ValueError(f"{folder / 'mask_cat.png'}: {classes.shape[::-1]} pixels, but disp_00.npy is "
                             f"{disparity.shape[::-1]}")
        trans = classes == TRANS_CLASS
        masks = {"trans": trans, "nontrans": ~trans, **{f"class_{c}": classes == c for c in np.unique(classes)}}
        left = folder / "camera_00" / f"{image}.png"
        return StereoSample(
            name=name, left=read_rgb(left), right=read_rgb(folder / "camera_02" / f"{image}.png"), disparity=disparity,
            regions=make_regions(disparity, masks), camera=self.camera,
            meta={"scene": scene, "kind": "capture", "left": str(left.relative_to(self.root))},
        )
