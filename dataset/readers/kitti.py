"""KITTI 2015 stereo, the training split::

    training/image_2/<id>_10.png      left
    training/image_3/<id>_10.png      right
    training/disp_occ_0/<id>_10.png   uint16 disparity × 256, 0 = invalid (all pixels)
    training/disp_noc_0/<id>_10.png   the same, non-occluded pixels only (optional)

Regions ``all`` and, where ``disp_noc_0`` exists, ``nonocc``. ``root`` is the folder holding
``training/`` or ``training/`` itself. KITTI's D1 is ``model.metrics.d1``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.formats import read_kitti_disparity, read_rgb
from dataset.readers.base import ListedReader, StereoSample, make_regions, not_layout, optional_camera, require_dir

EXPECTED = "training/{image_2,image_3,disp_occ_0}/<id>_10.png"


class KittiReader(ListedReader):
    def __init__(self, root: Path, *, fx: float | None = None, baseline: float | None = None,
                 depth_range: tuple[float, float] | None = None) -> None:
        root = require_dir(root, "kitti", EXPECTED)
        self.training = root / "training" if (root / "training").is_dir() else root
        if not (self.training / "disp_occ_0").is_dir():
            raise not_layout(root, "kitti", EXPECTED)
        self.camera = optional_camera(fx, baseline, depth_range=depth_range)
        names = [p.stem for p in sorted((self.training / "disp_occ_0").glob("*.png"))]
        if not names:
            raise not_layout(root, "kitti", f"{EXPECTED}; {self.training / 'disp_occ_0'} holds no PNG")
        super().__init__(root, names, self._read)

    def _read(self, name: str) -> StereoSample:
        left = self.training / "image_2" / f"{name}.png"
        disparity = read_kitti_disparity(self.training / "disp_occ_0" / f"{name}.png")
        noc = self.training / "disp_noc_0" / f"{name}.png"
        masks = {"nonocc": np.isfinite(read_kitti_disparity(noc))} if noc.is_file() else {}
        return StereoSample(
            name=name, left=read_rgb(left), right=read_rgb(self.training / "image_3" / f"{name}.png"),
            disparity=disparity, regions=make_regions(disparity, masks), camera=self.camera,
            meta={"left": str(left.relative_to(self.root))},
        )
