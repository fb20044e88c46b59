"""A monocular input of another family than ``dataset.synthetic.mono``'s estimator, for held-out scoring.

The fusion benchmark trains on the realistic estimator's maps; a network may learn that family's
particular errors rather than to distrust a monocular map where stereo disagrees. :func:`warped_mono`
corrupts the scene's exact mono-fooled disparity (``SyntheticFrame.mono_ideal``: the depicted scene
inside a picture, the reflected scene inside a mirror, the truth elsewhere) otherwise:

1. a smooth multiplicative warp: ``exp`` of a coarse grid of independent Gaussian values (GRID
   control points over the image), bilinearly upsampled, drawn anew for every frame;
2. a Gaussian blur (sigma a fraction of the image width) and additive Gaussian noise (std a
   fraction of the map's median), independent per pixel;
3. an unknown scale and shift per frame, drawn from the estimator's ranges (``mono.SCALE``,
   ``mono.SHIFT``): mono-gt-align undoes it, so the family differs in its errors, not its affine.

How it differs from the realistic estimator: that one distorts the layout by a few global plane
waves in log-depth fixed per video and a power of the depth about its median, removes thin near
structures by a grey opening, and outside illusions only; mirrors fool it a fraction 0.6-0.9 of
the way and pictures stay exactly as painted; it adds no noise. Here the warp is local (a grid of
independent values, no waves, no power), new in every frame, over the whole image (illusions
included, so the illusions carry the scene's own fooling, warped like everything else), mirrors
fool it completely, nothing is opened, and per-pixel noise is added. The magnitude is calibrated
to the realistic one's (mono-gt-align's non-illusion EPE on the same pairs: see docs/benchmarks.md).
"""

from __future__ import annotations

import cv2
import numpy as np

from dataset.synthetic.mono import SCALE, SHIFT

_STREAM = 0x77617270  # "warp": apart from the scenes' and the realistic estimator's random numbers
GRID = (3, 5)  # control points of the warp, rows x columns, spread over the image
WARP_STRENGTH = (0.08, 0.16)  # per frame: std of the log-disparity at the control points
BLUR = (0.003, 0.01)  # per frame: Gaussian sigma, of the image width
NOISE = (0.005, 0.02)  # per frame: std of the additive noise, of the map's median


def warped_mono(ideal: np.ndarray, seed: int, index: int) -> np.ndarray:
    """Frame ``index`` of video ``seed``'s corrupted monocular disparity: float32 (H, W) > 0, relative
    (an unknown affine of a disparity in px). ``ideal``: the frame's mono-fooled disparity (H, W), px > 0.
    Deterministic in (``seed``, ``index``)."""
    ideal = np.asarray(ideal, np.float64)
    height, width = ideal.shape
    rng = np.random.default_rng([_STREAM, seed, index])
    strength, blur, noise = (float(rng.uniform(*bounds)) for bounds in (WARP_STRENGTH, BLUR, NOISE))
    coarse = rng.normal(0.0, strength, GRID)
    field = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_LINEAR)
    warped = cv2.GaussianBlur(ideal * np.exp(field), (0, 0), blur * width, borderType=cv2.BORDER_REPLICATE)
    noisy = warped + rng.normal(0.0, noise * float(np.median(warped)), warped.shape)
    # Held above half the blurred map's minimum: the noise never makes a far pixel non-positive.
    noisy = np.maximum(noisy, 0.5 * float(warped.min()))
    scale = float(np.exp(rng.uniform(*np.log(SCALE))))
    shift = float(rng.uniform(*SHIFT)) * scale * float(noisy.min())
    return (scale * noisy + shift).astype(np.float32)
