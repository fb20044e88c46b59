"""SceneFlow (FlyingThings3D, Driving, Monkaa), also a training source (the paper pretrains on it)::

    <subset>/frames_cleanpass|frames_finalpass/<…>/left/<n>.png    (and …/right/<n>.png)
    <subset>/disparity/<…>/left/<n>.pfm                            float32 px of the left view

``<…>`` is ``TRAIN|TEST/<A|B|C>/<seq>`` (FlyingThings3D), ``<focal>/<direction>/<speed>``
(Driving) or ``<scene>`` (Monkaa). Every ``frames_<pass>`` folder up to two levels under
``root`` is read (``root`` may be one subset or the folder of all three). Options: ``passes``
(``("clean",)``, ``("final",)`` or both), ``split`` (``TRAIN``/``TEST``: only FlyingThings3D
has them, so the other subsets are left out when a split is asked for). Regions: ``all``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from core.formats import read_pfm, read_rgb
from dataset.readers.base import ListedReader, StereoSample, make_regions, not_layout, optional_camera, require_dir

EXPECTED = "[<subset>/]frames_cleanpass|frames_finalpass/…/left/*.png with disparity/…/left/*.pfm"
PASSES = ("clean", "final")
SPLITS = ("TRAIN", "TEST")


class SceneFlowReader(ListedReader):
    def __init__(self, root: Path, *, passes: Sequence[str] = ("clean",), split: str | None = None,
                 fx: float | None = None, baseline: float | None = None) -> None:
        root = require_dir(root, "sceneflow", EXPECTED)
        if not passes or any(p not in PASSES for p in passes):
            raise ValueError(f"sceneflow passes must be among {', '.join(PASSES)}, got {list(passes)}")
        if split is not None and split not in SPLITS:
            raise ValueError(f"sceneflow split must be one of {', '.join(SPLITS)}, got {split!r}")
        self.camera = optional_camera(fx, baseline)
        names = []
        for name in sorted(f"frames_{p}pass" for p in passes):
            for frames in sorted(root.glob(name)) + sorted(root.glob(f"*/{name}")) + sorted(root.glob(f"*/*/{name}")):
                for left in sorted(frames.rglob("left/*.png")):
                    rel = left.relative_to(root)
                    if split is None or split in rel.relative_to(frames.relative_to(root)).parts[:1]:
                        names.append(rel.with_suffix("").as_posix())
        if not names:
            raise not_layout(root, "sceneflow", EXPECTED + (f" (split {split})" if split else ""))
        super().__init__(root, names, self._read)

    def _read(self, name: str) -> StereoSample:
        left = self.root / f"{name}.png"
        parts = list(Path(name).parts)
        pass_at = max(i for i, p in enumerate(parts) if p.startswith("frames_") and p.endswith("pass"))
        right = Path(*parts[:-2], "right", parts[-1] + ".png")
        gt = Path(*parts[:pass_at], "disparity", *parts[pass_at + 1:]).with_suffix(".pfm")
        disparity = read_pfm(self.root / gt)
        if disparity.ndim != 2:
            raise ValueError(f"{self.root / gt}: expected a single-channel disparity PFM, got shape {disparity.shape}")
        return StereoSample(
            name=name, left=read_rgb(left), right=read_rgb(self.root / right), disparity=disparity,
            regions=make_regions(disparity), camera=self.camera, meta={"left": f"{name}.png", "pass": parts[pass_at]},
        )
