"""What every network's inference does to a numpy pair before it becomes tensors: the pair checked
(RGB uint8 H×W×3, one size) and its padding to a size multiple, centred as the reference demos'
InputPadder pads (model/predictor.py), and the IGEV-family demos' whole inference step
(:func:`demo_disparity`: Selective-IGEV, MoCha-Stereo)."""

from __future__ import annotations

from typing import Any

import numpy as np


def check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """ValueError unless ``left`` and ``right`` are RGB uint8 H×W×3 images of one size."""
    for name, image in (("left", left), ("right", right)):
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"{name} image must be RGB uint8 H×W×3, got {image.dtype} {image.shape}")
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in size: {left.shape[:2]} vs {right.shape[:2]}")


def centred_padding(height: int, width: int, multiple: int) -> tuple[int, int, int, int]:
    """(left, right, top, bottom) pixels that bring H×W to multiples of ``multiple``, split as the
    reference's InputPadder does (the odd pixel on the right/bottom)."""
    pad_h, pad_w = -height % multiple, -width % multiple
    return pad_w // 2, pad_w - pad_w // 2, pad_h // 2, pad_h - pad_h // 2


def demo_disparity(network: Any, left: np.ndarray, right: np.ndarray, iters: int, multiple: int) -> np.ndarray:
    """What an IGEV-family demo computes for a pair: ``left``/``right`` RGB uint8 H×W×3 of one size → H×W
    float32 disparity in pixels (the network's last iterate as it is). Centred replicate padding to
    multiples of ``multiple``, the images scaled to [−1, 1] (the networks' own first step), ``iters``
    refinements in test mode, the padding cropped off; on the network's device, no autograd, and the
    network put in eval mode as the demos do (batch norms use their running statistics)."""
    import torch
    import torch.nn.functional as F

    check_pair(left, right)
    height, width = left.shape[:2]
    padding = centred_padding(height, width, multiple)
    device = next(network.parameters()).device
    network.eval()

    def tensor(image: np.ndarray) -> torch.Tensor:
        t = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float().to(device)
        return 2 * (F.pad(t, padding, mode="replicate") / 255.0) - 1.0

    with torch.inference_mode():
        out = network(tensor(left), tensor(right), iters=iters).iterates[-1]
    top, pad_left = padding[2], padding[0]
    return out[0, 0, top:top + height, pad_left:pad_left + width].float().cpu().numpy().astype(np.float32)
