"""The capture folder: a stereo camera's rectified pairs and a depth sensor's raw depth, one frame per stem.

::

    DIR/left/<stem>.png    left colour image (8-bit; .png, .jpg or .jpeg), the calibration's colour size
    DIR/right/<stem>.png   right colour image, same size
    DIR/depth/<stem>.png   depth sensor frame: single-channel uint16 PNG, value · depth_scale = metres,
                           0 = no return, the calibration's depth-camera size
    DIR/mask/<stem>.png    optional: one illusion mask (8-bit PNG, 0 / 255) of the left view, or
    DIR/mask/<stem>/*.png  several, stored as illusion_00, illusion_01, … in file-name order

Files are matched by stem (``left/0042.png`` ↔ ``right/0042.png`` ↔ ``depth/0042.png``); every
stem needs all three, and a mask needs its frame. Frames are numbered 0, 1, … in natural stem
order (``frame_2`` before ``frame_10``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dataset.capture.errors import CaptureError
from dataset.capture.files import files_by_stem, matched_stems, names, natural_key

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
PNG = (".png",)


@dataclass(frozen=True)
class CaptureFrame:
    """One frame's files; ``masks`` in illusion order (possibly empty)."""

    stem: str
    left: Path
    right: Path
    depth: Path
    masks: tuple[Path, ...]

    @property
    def files(self) -> tuple[Path, ...]:
        """Every file of the frame, in a fixed order."""
        return (self.left, self.right, self.depth, *self.masks)


def scan_capture(root: str | Path) -> list[CaptureFrame]:
    """The frames of capture folder ``root`` in natural stem order; :class:`CaptureError` for a
    missing folder, unmatched files, or masks without a frame."""
    root = Path(root)
    if not root.is_dir():
        raise CaptureError(f"{root}: capture folder not found")
    groups = {"left": files_by_stem(root / "left", IMAGE_SUFFIXES), "right": files_by_stem(root / "right", IMAGE_SUFFIXES),
              "depth": files_by_stem(root / "depth", PNG)}
    stems = matched_stems(groups)
    masks = _masks(root / "mask")
    orphans = sorted(masks.keys() - set(stems), key=natural_key)
    if orphans:
        raise CaptureError(f"{root / 'mask'}: masks without a frame: {names(orphans)}")
    return [CaptureFrame(stem, groups["left"][stem], groups["right"][stem], groups["depth"][stem], masks.get(stem, ()))
            for stem in stems]


def _masks(folder: Path) -> dict[str, tuple[Path, ...]]:
    """``{stem: mask files}`` from ``mask/<stem>.png`` files and ``mask/<stem>/`` folders."""
    if not folder.is_dir():
        return {}
    masks = {stem: (path,) for stem, path in files_by_stem(folder, PNG).items()}
    for sub in sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")):
        if sub.name in masks:
            raise CaptureError(f"{folder}: both {sub.name}.png and the folder {sub.name}/ hold masks for {sub.name!r}")
        files = files_by_stem(sub, PNG)
        if not files:
            raise CaptureError(f"{sub}: mask folder holds no .png file")
        masks[sub.name] = tuple(files[stem] for stem in sorted(files, key=natural_key))
    return masks
