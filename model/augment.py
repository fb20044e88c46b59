"""Training augmentation of stereo pairs, as RAFT-Stereo's augmentor (numpy, torch-free).

Spatial: the pair is resized by s = 2**U(cfg.scale) (disparity × s, validity kept exactly: see
``dataset.readers.base.resize_disparity``), then cropped at a random place to ``crop``; where the
resized pair is smaller than the crop it is padded (images black, disparity NaN = invalid, regions
false). Photometric (``cfg.color_jitter``): brightness and contrast factors in [0.6, 1.4],
saturation in ``cfg.saturation``, hue ± 0.5/π of a turn, in random order, identical for both
views (the matcher must see the same colours in both). Every draw comes from ``rng`` in a fixed
order, so a generator seeded alike gives the same sample bit for bit.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from dataset.readers.base import StereoSample, resize_sample

if TYPE_CHECKING:
    from model.presets import TrainConfig

BRIGHTNESS = CONTRAST = 0.4
HUE = 0.5 / np.pi  # fraction of a full turn, as RAFT-Stereo's ColorJitter(hue=0.5/3.14)


def augment_pair(sample: StereoSample, crop: tuple[int, int], cfg: TrainConfig, rng: np.random.Generator) -> StereoSample:
    """``sample`` scaled, cropped to ``crop`` = (H, W) pixels and colour-jittered (see the module docstring)."""
    height, width = crop
    if height <= 0 or width <= 0:
        raise ValueError(f"crop must be positive (H, W), got {crop}")
    lo, hi = cfg.scale
    scale = float(2.0 ** rng.uniform(lo, hi))
    scaled = resize_sample(sample, scale)
    h, w = scaled.disparity.shape
    y0 = int(rng.integers(0, max(h - height, 0) + 1))
    x0 = int(rng.integers(0, max(w - width, 0) + 1))
    window = (slice(y0, y0 + height), slice(x0, x0 + width))

    def cut(array: np.ndarray, fill: Any) -> np.ndarray:
        part = array[window]
        pad = [(0, height - part.shape[0]), (0, width - part.shape[1])] + [(0, 0)] * (part.ndim - 2)
        return np.pad(part, pad, constant_values=fill) if any(p[1] for p in pad) else part.copy()

    left, right = cut(scaled.left, 0), cut(scaled.right, 0)
    jitter = None
    if cfg.color_jitter:
        jitter = _draw_jitter(rng, tuple(cfg.saturation))
        left, right = _jitter(left, jitter), _jitter(right, jitter)
    disparity = cut(scaled.disparity, np.float32(np.nan))
    regions = {name: cut(mask, False) for name, mask in scaled.regions.items()}
    regions["all"] = np.isfinite(disparity)
    return replace(scaled, left=left, right=right, disparity=disparity, regions=regions,
                   mono=None if scaled.mono is None else cut(scaled.mono, np.float32(0)),
                   meta={**sample.meta, "augment": {"scale": scale, "crop_origin": [y0, x0], "jitter": jitter}})


def _draw_jitter(rng: np.random.Generator, saturation: tuple[float, float]) -> dict[str, Any]:
    return {"brightness": float(rng.uniform(1 - BRIGHTNESS, 1 + BRIGHTNESS)),
            "contrast": float(rng.uniform(1 - CONTRAST, 1 + CONTRAST)),
            "saturation": float(rng.uniform(*saturation)), "hue": float(rng.uniform(-HUE, HUE)),
            "order": [int(i) for i in rng.permutation(4)]}


def _jitter(image: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """Apply the drawn brightness, contrast, saturation and hue changes (uint8 RGB H×W×3 in and out)."""
    img = image.astype(np.float32) / 255.0
    for op in params["order"]:
        if op == 0:
            img = img * params["brightness"]
        elif op == 1:
            mean = _gray(img).mean()
            img = (img - mean) * params["contrast"] + mean
        elif op == 2:
            gray = _gray(img)[..., None]
            img = (img - gray) * params["saturation"] + gray
        else:
            hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)  # float input: hue in degrees [0, 360)
            hsv[..., 0] = (hsv[..., 0] + 360.0 * params["hue"]) % 360.0
            img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
        img = np.clip(img, 0.0, 1.0)
    return np.rint(img * 255.0).astype(np.uint8)


def _gray(img: np.ndarray) -> np.ndarray:
    """ITU-R 601 luma of RGB in [0, 1] (as torchvision's rgb_to_grayscale)."""
    return img[..., 0] * 0.299 + img[..., 1] * 0.587 + img[..., 2] * 0.114
