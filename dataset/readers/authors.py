"""The authors' released real test set (DESIGN.md, ``dataset/export/authors_layout.py``)::

    testing/{left,right}/<scene>_<obj>/frame_<id>.png
    testing/disp/<scene>_<obj>/frame_<id>.pfm        float32 px; inf / ≤ 0 = no measurement
    testing/mask/<scene>_<obj>/frame_<id>.jpg|png    255 = illusion (thresholded at 128)
    meta_data/testing_enter.pkl                      {(scene, obj, id): {left, right, disp, mask}} (optional)

``root`` is the dataset folder (``testing/`` or ``real_data/testing/`` inside) or ``testing/``
itself. With the index pickle (read as plain data only) its entries are the samples, else every
``left/*/frame_*.png``. Their evaluation's camera by default: fx = 1450.4127 px, baseline
0.0628167 m, valid ground-truth depth in (0.3, 5) m — outside it a pixel is no ground truth
(``depth_range=None`` keeps every positive disparity). Regions ``all``, ``illusion``, ``non_illusion``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.formats import read_mask, read_pfm, read_rgb
from dataset.export.authors_import import TESTING_ROOTS, load_testing_index, testing_files
from dataset.export.authors_layout import TESTING, TESTING_INDEX
from dataset.readers.base import ListedReader, StereoSample, invalidate, make_regions, not_layout, optional_camera, require_dir

AUTHORS_FX, AUTHORS_BASELINE, AUTHORS_DEPTH_RANGE = 1450.4127, 0.0628167, (0.3, 5.0)  # px, m, m
EXPECTED = "testing/{left,right}/<scene>_<obj>/frame_<id>.png, testing/disp/…/frame_<id>.pfm, testing/mask/…"
MASK_SUFFIXES = (".jpg", ".jpeg", ".png")


class AuthorsReader(ListedReader):
    """The test frames at ``root``; the camera (``fx`` px, ``baseline`` m, valid ``depth_range`` m,
    None for none) defaults to the authors' evaluation; masks are thresholded at ``mask_threshold``."""

    def __init__(self, root: Path, *, fx: float = AUTHORS_FX, baseline: float = AUTHORS_BASELINE,
                 depth_range: tuple[float, float] | None = AUTHORS_DEPTH_RANGE, mask_threshold: int = 128) -> None:
        root = require_dir(root, "authors", EXPECTED)
        self.camera = optional_camera(fx, baseline, depth_range=depth_range)
        self.mask_threshold = mask_threshold
        self.files = _listing(root)
        super().__init__(root, sorted(self.files), self._read)

    def _read(self, name: str) -> StereoSample:
        paths = self.files[name]
        raw = read_pfm(paths["disp"])
        if raw.ndim != 2:
            raise ValueError(f"{paths['disp']}: expected a single-channel disparity PFM, got shape {raw.shape}")
        valid = np.isfinite(raw) & (raw > 0)
        if self.camera is not None and self.camera.depth_range is not None:
            near, far = self.camera.depth_range
            depth = self.camera.depth(np.where(valid, raw, np.float32(np.nan)))
            valid &= (depth > near) & (depth < far)
        disparity = invalidate(raw, valid)
        illusion = read_mask(paths["mask"], threshold=self.mask_threshold)
        if illusion.shape != disparity.shape:
            raise ValueError(f"{paths['mask']}: {illusion.shape[::-1]} pixels, but its disparity is {disparity.shape[::-1]}")
        return StereoSample(
            name=name, left=read_rgb(paths["left"]), right=read_rgb(paths["right"]), disparity=disparity,
            regions=make_regions(disparity, {"illusion": illusion, "non_illusion": ~illusion}),
            camera=self.camera, meta={"kind": "capture", "left": str(paths["left"].relative_to(self.root)),
                                      "scene_obj": name.rpartition("/")[0]},
        )


def _listing(root: Path) -> dict[str, dict[str, Path]]:
    """{"<scene>_<obj>/frame_<id>": {left, right, disp, mask: path}} from the index, else from the folders."""
    index = root / TESTING_INDEX
    if index.is_file():
        return {_name(paths["left"]): paths
                for key, entry in load_testing_index(index).items()
                for paths in [testing_files(root, entry, key)]}
    testing = next((root / t for t in TESTING_ROOTS if (root / t / "left").is_dir()), root)
    if not (testing / "left").is_dir():
        raise not_layout(root, "authors", f"{EXPECTED} (or {TESTING}/ given directly)")
    files = {}
    for left in sorted((testing / "left").glob("*/frame_*.png")):
        folder, stem = left.parent.name, left.stem
        masks = [testing / "mask" / folder / (stem + s) for s in MASK_SUFFIXES]
        files[f"{folder}/{stem}"] = {"left": left, "right": testing / "right" / folder / left.name,
                                     "disp": testing / "disp" / folder / f"{stem}.pfm",
                                     "mask": next((m for m in masks if m.is_file()), masks[0])}
    if not files:
        raise not_layout(root, "authors", f"{EXPECTED}; {testing / 'left'} holds no <scene>_<obj>/frame_<id>.png")
    return files


def _name(left: Path) -> str:
    return f"{left.parent.name}/{left.stem}"
