"""Training augmentation of stereo pairs, as RAFT-Stereo's augmentor (numpy, torch-free).

Spatial: the pair is scaled by s = 2**U(cfg.scale) (disparity × s; NaN stays invalid: see
``dataset.readers.base.resample_disparity``) and cropped at a random place to ``crop``; where the
scaled pair is smaller than the crop it is padded (images black, disparity NaN = invalid, regions
false, mono 0). Photometric (``cfg.color_jitter``): brightness and contrast factors in [0.6, 1.4],
saturation in ``cfg.saturation``, hue ± 0.5/π of a turn, in random order, identical for both
views (the matcher must see the same colours in both; the pair is jittered as one image). Every draw comes from ``rng`` in a fixed
order, so a generator seeded alike gives the same sample bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from dataset.readers.base import StereoSample, make_regions, resample_disparity

if TYPE_CHECKING:
    from model.presets import TrainConfig

BRIGHTNESS = CONTRAST = 0.4
HUE = 0.5 / np.pi  # fraction of a full turn, as RAFT-Stereo's ColorJitter(hue=0.5/3.14)


def augment_pair(sample: StereoSample, crop: tuple[int, int], cfg: TrainConfig, rng: np.random.Generator) -> StereoSample:
    """``sample`` scaled, cropped to ``crop`` = (H, W) pixels and colour-jittered (see the module docstring).

    The crop is sampled straight from the source (one affine warp per array), so the cost does
    not grow with the source resolution: the same pixels as resizing the whole pair first.
    """
    height, width = crop
    if height <= 0 or width <= 0:
        raise ValueError(f"crop must be positive (H, W), got {crop}")
    lo, hi = cfg.scale
    scale = float(2.0 ** rng.uniform(lo, hi))
    h, w = (int(n * scale) for n in sample.disparity.shape)
    y0 = int(rng.integers(0, max(h - height, 0) + 1))
    x0 = int(rng.integers(0, max(w - width, 0) + 1))
    # output pixel (x, y) of the crop ← source point ((x0 + x + 0.5)/s − 0.5, (y0 + y + 0.5)/s − 0.5);
    # only the source window those points fall in (plus interpolation margin) is touched
    rows, cols = _window(y0, height, scale, sample.disparity.shape[0]), _window(x0, width, scale, sample.disparity.shape[1])
    warp = np.array([[1 / scale, 0, (x0 + 0.5) / scale - 0.5 - cols.start],
                     [0, 1 / scale, (y0 + 0.5) / scale - 0.5 - rows.start]])

    def warp_window(window: np.ndarray, interpolation: int) -> np.ndarray:
        return cv2.warpAffine(window, warp, (width, height), flags=interpolation | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def sample_at(array: np.ndarray, interpolation: int) -> np.ndarray:
        return warp_window(np.ascontiguousarray(array[rows, cols]), interpolation)

    left, right = sample_at(sample.left, cv2.INTER_LINEAR), sample_at(sample.right, cv2.INTER_LINEAR)
    jitter = None
    if cfg.color_jitter:
        jitter = _draw_jitter(rng, tuple(cfg.saturation))
        # both views as one image, as RAFT-Stereo's symmetric jitter: one contrast mean for the pair
        left, right = np.split(_jitter(np.concatenate([left, right]), jitter), 2)
    disparity = resample_disparity(np.ascontiguousarray(sample.disparity[rows, cols]), warp_window, scale)
    masks = {name: sample_at(mask.astype(np.uint8), cv2.INTER_NEAREST).astype(bool)
             for name, mask in sample.regions.items() if name != "all"}
    return replace(sample, left=left, right=right, disparity=disparity, regions=make_regions(disparity, masks),
                   mono=None if sample.mono is None else sample_at(sample.mono.astype(np.float32), cv2.INTER_LINEAR),
                   camera=None if sample.camera is None else sample.camera.scaled(scale),
                   meta={**sample.meta, "augment": {"scale": scale, "crop_origin": [y0, x0], "jitter": jitter}})


def _window(origin: int, size: int, scale: float, limit: int) -> slice:
    """The source rows (or columns) that output pixels origin … origin + size − 1 sample, with a
    margin of two pixels for the interpolation, within 0 … limit."""
    first = math.floor((origin + 0.5) / scale - 0.5) - 2
    last = math.ceil((origin + size - 0.5) / scale - 0.5) + 2
    return slice(min(max(first, 0), limit), min(max(last + 1, 0), limit))


def _draw_jitter(rng: np.random.Generator, saturation: tuple[float, float]) -> dict[str, Any]:
    return {"brightness": float(rng.uniform(1 - BRIGHTNESS, 1 + BRIGHTNESS)),
            "contrast": float(rng.uniform(1 - CONTRAST, 1 + CONTRAST)),
            "saturation": float(rng.uniform(*saturation)), "hue": float(rng.uniform(-HUE, HUE)),
            "order": [int(i) for i in rng.permutation(4)]}


def _jitter(image: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """Apply the drawn brightness, contrast, saturation and hue changes (uint8 RGB H×W×3 in and out)."""
    img = image.astype(np.float32) * np.float32(1 / 255)
    for op in params["order"]:
        if op == 0:
            img *= np.float32(params["brightness"])
        elif op == 1:
            c = params["contrast"]
            img = cv2.addWeighted(img, c, img, 0.0, (1 - c) * float(_gray(img).mean()))
        elif op == 2:
            s = params["saturation"]
            img = cv2.addWeighted(img, s, cv2.cvtColor(_gray(img), cv2.COLOR_GRAY2RGB), 1 - s, 0.0)
        else:
            hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)  # float input: hue in degrees [0, 360)
            hsv[..., 0] = (hsv[..., 0] + 360.0 * params["hue"]) % 360.0
            img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
        np.clip(img, 0.0, 1.0, out=img)
    return np.rint(img * 255.0).astype(np.uint8)


def _gray(img: np.ndarray) -> np.ndarray:
    """ITU-R 601 luma of float RGB (as torchvision's rgb_to_grayscale)."""
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
