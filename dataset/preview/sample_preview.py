"""A sample's previews, made from its stored outputs on first request and cached on disk.

``sample`` is the dict of :func:`dataset.services.sample_review.get_sample`. Both disparities are
shown in pixels of the synthesized stereo pair: after = ``disparity`` (the training target,
scale · rectified), before = scale · ``disparity_mono``, so one colour bar and one 3D scale fit both.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dataset.media import MediaStore
from dataset.preview import images
from dataset.preview.cache import RenderCache
from dataset.preview.cloud import VirtualCamera, disparity_cloud
from dataset.preview.scene import SCENE_VERSION, export_scene
from dataset.samples import load_output

# Bump when a render changes, so cached PNGs are rebuilt.
RENDER_VERSION = 1
THUMB_WIDTH = 384
MAX_POINTS = 200_000
STAGES = ("after", "before")  # the first is the default
# view → the outputs it needs (``right_holes`` marks holes only where the sample has them)
VIEWS: dict[str, tuple[str, ...]] = {
    "disparity_before": ("disparity_mono",),
    "disparity_after": ("disparity",),
    "masks": ("left",),
    "right_holes": ("right",),
    "anaglyph": ("left", "right"),
}
_STAGE_OUTPUT = {"after": "disparity", "before": "disparity_mono"}


class SamplePreview:
    """Renders and 3D scenes of samples from ``media``, cached in ``cache``."""

    def __init__(self, media: MediaStore, cache: RenderCache) -> None:
        self.media = media
        self.cache = cache

    def views(self, sample: dict[str, Any]) -> list[str]:
        """The 2D views this sample's outputs allow, in display order."""
        return [view for view, needs in VIEWS.items() if all(name in sample["files"] for name in needs)]

    def stages(self, sample: dict[str, Any]) -> list[str]:
        """``after`` and/or ``before``: the point clouds this sample's outputs allow."""
        return [stage for stage in STAGES if _STAGE_OUTPUT[stage] in sample["files"]]

    def disparity_range(self, sample: dict[str, Any]) -> tuple[float, float]:
        """(min, max) in px over the before and after disparities: the colour bar's ends."""
        def make() -> bytes:
            lo, hi = images.value_range(*(self._disparity_px(sample, stage) for stage in self.stages(sample)))
            return json.dumps({"lo": lo, "hi": hi}).encode()

        data = json.loads(self.cache.get_or_make(["range", RENDER_VERSION, *_source(sample)], "json", make).read_text())
        return data["lo"], data["hi"]

    def render(self, sample: dict[str, Any], view: str, thumb: bool = False) -> Path:
        """The PNG of ``view`` (one of :meth:`views`), ``THUMB_WIDTH`` px wide if ``thumb``."""
        if view not in self.views(sample):
            raise KeyError(view)

        def make() -> bytes:
            image = self._view(sample, view)
            return images.encode_png(images.shrink(image, THUMB_WIDTH) if thumb else image)

        return self.cache.get_or_make(["view", RENDER_VERSION, view, thumb, *_source(sample)], "png", make)

    def scene(self, sample: dict[str, Any], stage: str) -> Path:
        """The ``.viser`` scene with every stage's point cloud, ``stage``'s shown at first."""
        stages = self.stages(sample)
        if stage not in stages or "left" not in sample["files"]:
            raise KeyError(stage)

        def make() -> bytes:
            left = self._load(sample, "left")
            highlight = np.zeros(left.shape[:2], bool)
            for name, key in sample["files"].get("masks", {}).items():
                if name.startswith("illusion"):
                    highlight |= load_output(self.media, key, "mask")
            clouds = {f"{s}_rectification": disparity_cloud(left, self._disparity_px(sample, s), highlight=highlight,
                                                            max_points=MAX_POINTS) for s in stages}
            camera = VirtualCamera(left.shape[1], left.shape[0])
            return export_scene(clouds, f"{stage}_rectification", camera)

        return self.cache.get_or_make(["scene", SCENE_VERSION, stage, MAX_POINTS, *_source(sample)], "viser", make)

    def _view(self, sample: dict[str, Any], view: str) -> np.ndarray:
        if view.startswith("disparity_"):
            return images.colorize(self._disparity_px(sample, view.removeprefix("disparity_")),
                                   *self.disparity_range(sample))
        if view == "masks":
            masks = {name: load_output(self.media, key, "mask") for name, key in sample["files"].get("masks", {}).items()}
            return images.outline(self._load(sample, "left"), masks)
        right = self._load(sample, "right")
        if view == "anaglyph":
            return images.anaglyph(self._load(sample, "left"), right)
        if "holes" in sample["files"]:
            return images.blend(right, self._load(sample, "holes"), images.HOLE_RGB, images.HOLE_ALPHA)
        return right

    def _disparity_px(self, sample: dict[str, Any], stage: str) -> np.ndarray:
        disparity = self._load(sample, _STAGE_OUTPUT[stage])
        return disparity if stage == "after" else disparity * np.float32(disparity_scale(sample))

    def _load(self, sample: dict[str, Any], name: str) -> np.ndarray:
        return load_output(self.media, sample["files"][name], name)


def disparity_scale(sample: dict[str, Any]) -> float:
    """Pixels per unit of the monocular disparity (1 when the sample records none)."""
    return float(sample["params"].get("scale") or 1.0)


def _source(sample: dict[str, Any]) -> list[Any]:
    """What every preview of a sample is made from (media keys are content hashes)."""
    return [sample["files"], disparity_scale(sample)]
