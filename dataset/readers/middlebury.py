"""Middlebury stereo: MiddEval3 training scenes and the 2014 "perfect" scenes::

    MiddEval3/training{F,H,Q}/<scene>/{im0.png, im1.png, disp0GT.pfm, mask0nocc.png, calib.txt}
    <scene>-perfect/{im0.png, im1.png, disp0.pfm, calib.txt}                     (2014)

Infinite disparity is invalid. Regions ``all`` and, where ``mask0nocc.png`` exists, ``nonocc``
(its value 255). The camera comes from ``calib.txt``: fx from ``cam0``, ``baseline`` mm → m,
``doffs`` (depth = fx·baseline / (d + doffs)). ``root`` is the MiddEval3 folder (``resolution``
F, H or Q picks its training folder; by default the largest present), one training folder, or a
folder of 2014 ``*-perfect`` scenes.
"""

from __future__ import annotations

import re
from pathlib import Path

from core.formats import read_mask, read_pfm, read_rgb
from dataset.readers.base import Camera, ListedReader, StereoSample, make_regions, not_layout, require_dir

EXPECTED = "training{F,H,Q}/<scene>/{im0.png,im1.png,disp0GT.pfm,calib.txt} or <scene>-perfect/{im0.png,im1.png,disp0.pfm}"
RESOLUTIONS = ("F", "H", "Q")
GT_NAMES = ("disp0GT.pfm", "disp0.pfm")
_CAM0 = re.compile(r"\[\s*([-+0-9.eE]+)")


class MiddleburyReader(ListedReader):
    def __init__(self, root: Path, *, resolution: str | None = None) -> None:
        root = require_dir(root, "middlebury", EXPECTED)
        if resolution is not None and resolution not in RESOLUTIONS:
            raise ValueError(f"middlebury resolution must be one of {', '.join(RESOLUTIONS)}, got {resolution!r}")
        wanted = [resolution] if resolution else list(RESOLUTIONS)
        folder = next((root / f"training{r}" for r in wanted if (root / f"training{r}").is_dir()), root)
        if resolution and folder == root:
            raise not_layout(root, "middlebury", f"a training{resolution} folder ({EXPECTED})")
        self.scenes = {scene.name: scene for scene in sorted(folder.iterdir())
                       if scene.is_dir() and (scene / "im0.png").is_file() and any((scene / g).is_file() for g in GT_NAMES)}
        if not self.scenes:
            raise not_layout(root, "middlebury", EXPECTED)
        super().__init__(root, list(self.scenes), self._read)

    def _read(self, name: str) -> StereoSample:
        scene = self.scenes[name]
        gt = next((scene / g for g in GT_NAMES if (scene / g).is_file()), scene / GT_NAMES[0])
        disparity = read_pfm(gt)
        if disparity.ndim != 2:
            raise ValueError(f"{gt}: expected a single-channel disparity PFM, got shape {disparity.shape}")
        masks = {}
        if (scene / "mask0nocc.png").is_file():
            masks["nonocc"] = read_mask(scene / "mask0nocc.png", threshold=255)
        calib = scene / "calib.txt"
        return StereoSample(
            name=name, left=read_rgb(scene / "im0.png"), right=read_rgb(scene / "im1.png"), disparity=disparity,
            regions=make_regions(disparity, masks), camera=read_calib(calib) if calib.is_file() else None,
            meta={"scene": name, "left": str((scene / "im0.png").relative_to(self.root))},
        )


def read_calib(path: Path) -> Camera:
    """The camera of a Middlebury ``calib.txt`` (``cam0=[f 0 cx; …]``, ``doffs``, ``baseline`` in mm)."""
    try:
        fields = dict(line.split("=", 1) for line in path.read_text(encoding="utf-8").splitlines() if "=" in line)
        focal = _CAM0.match(fields["cam0"].strip())
        if focal is None:
            raise ValueError(f"cam0 {fields['cam0']!r} is not a [f 0 cx; 0 f cy; 0 0 1] matrix")
        return Camera(fx=float(focal.group(1)), baseline=float(fields["baseline"]) / 1000.0,
                      doffs=float(fields.get("doffs", 0.0)))
    except (OSError, UnicodeDecodeError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a Middlebury calib.txt with cam0, baseline (mm) and doffs: {exc}") from None
