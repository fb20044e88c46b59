"""What a real monocular depth network would report for a synthetic frame, made from its exact maps.

The paper's tables say how monocular depth fails (DESIGN.md): on Booster's non-transparent pixels
Depth Anything V2 scores EPE 2.91 px / bad-2 47.25 % where RAFT-Stereo scores 3.13 / 13.10 —
coarse everywhere, soft edges, an unknown affine; on transparent surfaces it fails *less* than
stereo (7.19 against 9.55 px); on pictures it is fooled completely (5.81 against 1.62). So the
realistic map, per frame, is

1. the perceived disparity: the truth outside illusions, the depicted scene inside pictures, and
   inside mirrors a fraction ``f`` of the way from the glass to the reflected scene (in disparity;
   ``f`` drawn per video from U(0.6, 0.9), around 7.19 / 9.55 ≈ 0.75);
2. outside illusions, the depth layout distorted in log-depth: a power ``1 + gamma`` of the
   depth about its median and a smooth random field of a few low-frequency waves over the image;
3. thin near structures lost (a grey opening) and depth edges blurred (a Gaussian), both sized as
   fractions of the image width; a picture keeps its depicted disparity exactly;
4. a per-frame scale and shift (relative depth), the shift a fraction above -1 of the map's
   minimum so that the map stays positive.

Every parameter comes from ``seed`` alone (a random stream of its own, apart from the layout's),
so renders of a seed at any size agree, and every one is recorded (:meth:`MonoModel.as_dict`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np

_STREAM = 0x6D6F6E6F  # "mono": this model's random numbers never shift the layout's
_WAVES = 6
MIRROR_FRACTION = (0.6, 0.9)
# Scene families: half the estimators read a mirror as the surface it is (the glass: stereo is the one
# fooled there), half are fooled by it as MIRROR_FRACTION's are.
MIRROR_FRACTION_FAMILIES = ((0.0, 0.3), (0.6, 0.9))
_FAMILY_STREAM = 0x66616D  # "fam"
# Calibrated once on the fusion benchmark's test pairs (`illusion-studio bench fusion --mono-only`):
# mono-gt-align's non-illusion bad-2 lands near Depth Anything V2's 47 % on Booster.
LAYOUT_STRENGTH = (0.07, 0.12)  # std of the log-depth field
DEPTH_GAMMA = (-0.25, 0.1)  # the log-depth power's offset: > 0 stretches, < 0 flattens the layout
WAVE_CYCLES = (0.3, 1.2)  # per image width
EDGE_BLUR = (0.004, 0.008)  # Gaussian sigma, of the image width
THIN_SIZE = (0.006, 0.014)  # opening kernel side, of the image width
SCALE = (0.25, 4.0)  # per frame, log-uniform
SHIFT = (-0.5, 1.0)  # per frame, of the scaled map's minimum


@dataclass(frozen=True)
class MonoModel:
    """One video's monocular estimator. Widths are fractions of the image width; ``waves`` are
    (cycles per width along x, along y, phase rad, amplitude) of the log-depth field."""

    mirror_fraction: float
    layout_strength: float
    depth_gamma: float
    edge_blur: float
    thin_size: float
    waves: tuple[tuple[float, float, float, float], ...]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (scene.json's ``mono``)."""
        return {**asdict(self), "waves": [list(w) for w in self.waves]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MonoModel:
        """The inverse of :meth:`as_dict`."""
        return cls(**{**data, "waves": tuple(tuple(float(x) for x in w) for w in data["waves"])})


@dataclass(frozen=True)
class FrameAffine:
    """The frame's relative-depth affine: mono = ``scale`` · map + ``shift`` (pixels of the map)."""

    scale: float
    shift: float


def sample_mono_model(seed: int, families: bool = False) -> MonoModel:
    """The estimator of video ``seed``; deterministic. ``families``: its mirror fraction drawn from
    MIRROR_FRACTION_FAMILIES (a mirror the estimator reads as a surface, or one that fools it)."""
    rng = np.random.default_rng([_STREAM, seed])
    strength = float(rng.uniform(*LAYOUT_STRENGTH))
    amplitude = strength * np.sqrt(2 / _WAVES)  # K cosines of amplitude a have variance K a² / 2
    waves = []
    for _ in range(_WAVES):
        cycles, angle = rng.uniform(*WAVE_CYCLES), rng.uniform(0, 2 * np.pi)
        waves.append((float(cycles * np.cos(angle)), float(cycles * np.sin(angle)),
                      float(rng.uniform(0, 2 * np.pi)), float(amplitude)))
    fraction = float(rng.uniform(*MIRROR_FRACTION))
    if families:  # from a stream of its own: the rest of the estimator is the seed's
        family = np.random.default_rng([_STREAM, _FAMILY_STREAM, seed])
        fraction = float(family.uniform(*MIRROR_FRACTION_FAMILIES[int(family.integers(2))]))
    return MonoModel(mirror_fraction=fraction, layout_strength=strength,
                     depth_gamma=float(rng.uniform(*DEPTH_GAMMA)), edge_blur=float(rng.uniform(*EDGE_BLUR)),
                     thin_size=float(rng.uniform(*THIN_SIZE)), waves=tuple(waves))


def log_depth_field(model: MonoModel, width: int, height: int) -> np.ndarray:
    """float64 (H, W): the smooth log-depth offset, in coordinates normalised by the width about
    the image centre (so every render size sees the same field)."""
    x = (np.arange(width) - (width - 1) / 2) / width
    y = (np.arange(height) - (height - 1) / 2) / width
    field = np.zeros((height, width))
    for kx, ky, phase, amplitude in model.waves:
        field += amplitude * np.cos(2 * np.pi * (kx * x[None, :] + ky * y[:, None]) + phase)
    return field


def realistic_mono(model: MonoModel, seed: int, index: int, truth: np.ndarray, ideal: np.ndarray,
                   picture: np.ndarray, mirror: np.ndarray) -> tuple[np.ndarray, FrameAffine]:
    """Frame ``index``'s realistic monocular disparity, float32 (H, W) > 0, and its affine.

    ``truth``: the true disparity (a mirror as its glass); ``ideal``: the mono-fooled one (the
    depicted scene in pictures, the reflected one in mirrors, the truth elsewhere), both px > 0;
    ``picture``/``mirror``: bool (H, W) illusion masks.
    """
    height, width = truth.shape
    truth, ideal = truth.astype(np.float64), ideal.astype(np.float64)
    outside = ~(picture | mirror)
    reference = float(np.median(truth[outside])) if outside.any() else float(np.median(truth))
    # Disparity is inverse depth, so a log-depth offset g multiplies it by exp(-g).
    distorted = reference * (truth / reference) ** (1 + model.depth_gamma) * np.exp(
        -log_depth_field(model, width, height))
    perceived = np.where(outside, distorted, ideal)
    perceived[mirror] = truth[mirror] + model.mirror_fraction * (ideal[mirror] - truth[mirror])
    soft = perceived.astype(np.float32)
    side = round(model.thin_size * width)
    if side >= 2:
        soft = cv2.morphologyEx(soft, cv2.MORPH_OPEN, np.ones((side, side), np.uint8),
                                borderType=cv2.BORDER_REPLICATE)
    soft = cv2.GaussianBlur(soft, (0, 0), model.edge_blur * width, borderType=cv2.BORDER_REPLICATE)
    soft = soft.astype(np.float64)
    soft[picture] = ideal[picture]  # fooled completely: the depicted scene, as painted
    rng = np.random.default_rng([_STREAM, seed, index])
    scale = float(np.exp(rng.uniform(*np.log(SCALE))))
    shift = float(rng.uniform(*SHIFT)) * scale * float(soft.min())
    return (scale * soft + shift).astype(np.float32), FrameAffine(scale, shift)
