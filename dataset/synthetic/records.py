"""The in-memory form of a synthetic video: frames, their maps and illusion/support masks.

The dataclasses hold numpy arrays, so they compare by identity (``eq=False``); compare
fields with ``np.array_equal`` instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from dataset.synthetic.mono import FrameAffine, MonoModel

IllusionKind = Literal["picture", "mirror"]


@dataclass(frozen=True, eq=False)
class RegionPair:
    """One illusion and its support surface in one frame.

    ``illusion``: bool (H, W), the flat thing that fools a depth estimator (the picture's
    canvas, the mirror's glass); ``support``: bool (H, W), a frame-shaped band of the same
    wall plane around it (never overlapping ``illusion``). ``pair`` numbers the pairs of a
    video from 0; ``kind`` and ``illusion_type`` are both the illusion's type.
    """

    pair: int
    kind: IllusionKind
    illusion_type: IllusionKind
    illusion: np.ndarray
    support: np.ndarray


@dataclass(frozen=True, eq=False)
class SyntheticFrame:
    """One rectified stereo frame with exact maps (all (H, W), left view, pixels).

    ``left``/``right``: uint8 (H, W, 3) RGB, the right camera translated by the baseline
    along the left camera's +x; ``disparity``: float32 true disparity f·B/Z (Z = camera depth
    of the first surface met, the mirror counting as its glass), finite and > 0;
    ``mono_disparity``: float32 > 0, what a real monocular network reports (relative, coarse,
    fooled by pictures and partly by mirrors; see dataset.synthetic.mono), ``mono_affine`` its
    frame's scale and shift; ``mono_ideal``: float32, an exact mono-fooled disparity (the
    depicted scene inside a picture, the reflected scene inside a mirror, else the truth);
    ``stereo_disparity``: float32, what a stereo matcher reports (the reflected scene's
    virtual depth inside a mirror, else the truth); ``time_s`` = index / fps.
    """

    index: int
    time_s: float
    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    mono_disparity: np.ndarray
    stereo_disparity: np.ndarray
    regions: list[RegionPair]
    mono_ideal: np.ndarray
    mono_affine: FrameAffine


@dataclass(frozen=True, eq=False)
class SyntheticVideo:
    """A rendered synthetic video: pinhole intrinsics ``fx``, ``fy``, ``cx``, ``cy`` (pixels,
    pixel centres at integer coordinates), stereo ``baseline_m`` (m), frame rate ``fps``, and the
    monocular estimator ``mono`` its frames' ``mono_disparity`` came from; ``families``: rendered
    with the scene families (``dataset.synthetic.layout``)."""

    name: str
    seed: int
    fps: float
    fx: float
    fy: float
    cx: float
    cy: float
    baseline_m: float
    frames: list[SyntheticFrame]
    mono: MonoModel
    families: bool = False

    @property
    def width(self) -> int:
        """Frame width in pixels."""
        return int(self.frames[0].left.shape[1])

    @property
    def height(self) -> int:
        """Frame height in pixels."""
        return int(self.frames[0].left.shape[0])
