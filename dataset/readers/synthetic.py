"""Synthetic scenes as `illusion-studio synth` writes them (dataset/synthetic/io.py)::

    <root>/<video>/{scene.json, frames/<index:06d>/{left.png, right.png, disparity.npy, mono_disparity.npy, …}}

(or ``<root>`` one such video folder). Ground truth is the exact disparity (a mirror counts as its glass);
regions ``all``, ``illusion`` (pictures and mirrors), one per illusion type and ``non_illusion``; ``mono``
the realistic monocular disparity the frame carries; the camera from ``scene.json`` (fx, baseline), so
depth metrics are reported too. The same conversion serves the fusion benchmark's rendered pairs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dataset.readers.base import Camera, ListedReader, StereoSample, make_regions, not_layout, require_dir
from dataset.synthetic.io import read_frame, read_scene
from dataset.synthetic.records import SyntheticFrame

EXPECTED = "<video>/scene.json with frames/<index>/{left.png,right.png,disparity.npy} (`illusion-studio synth`)"


def frame_sample(video: str, seed: int, frame: SyntheticFrame, camera: Camera | None = None,
                 mono: np.ndarray | None = None) -> StereoSample:
    """One rendered frame as a sample named ``video/index`` (4 digits): disparity in pixels (HxW), the
    regions above, ``mono`` (default: the frame's realistic monocular disparity), meta ``seed``."""
    masks = {pair.illusion_type: pair.illusion for pair in frame.regions}
    illusion = np.logical_or.reduce(list(masks.values())) if masks else np.zeros(frame.disparity.shape, bool)
    return StereoSample(name=f"{video}/{frame.index:04d}", left=frame.left, right=frame.right, disparity=frame.disparity,
                        regions=make_regions(frame.disparity, {"illusion": illusion, **masks, "non_illusion": ~illusion}),
                        mono=frame.mono_disparity if mono is None else mono, camera=camera, meta={"seed": seed})


class SyntheticReader(ListedReader):
    """The frames of every video folder under ``root`` (or of ``root`` itself), video by video."""

    def __init__(self, root: Path) -> None:
        root = require_dir(root, "synthetic", EXPECTED)
        folders = [root] if (root / "scene.json").is_file() else sorted(
            p for p in root.iterdir() if p.is_dir() and (p / "scene.json").is_file())
        if not folders:
            raise not_layout(root, "synthetic", EXPECTED)
        self.videos: dict[str, tuple[Path, dict]] = {}
        names = []
        for folder in folders:
            try:
                scene = read_scene(folder)
            except ValueError as exc:
                raise not_layout(root, "synthetic", f"{EXPECTED} ({exc})") from None
            self.videos[folder.name] = (folder, scene)
            names += [f"{folder.name}/{entry['index']:04d}" for entry in scene["frames"]]
        super().__init__(root, names, self._read)

    def _read(self, name: str) -> StereoSample:
        video, index = name.rsplit("/", 1)
        folder, scene = self.videos[video]
        entry = next(e for e in scene["frames"] if e["index"] == int(index))
        camera = Camera(fx=float(scene["intrinsics"]["fx"]), baseline=float(scene["baseline_m"]))
        sample = frame_sample(video, int(scene["seed"]), read_frame(folder, scene, entry), camera)
        sample.meta["left"] = f"{video}/frames/{entry['index']:06d}/left.png"
        return sample
