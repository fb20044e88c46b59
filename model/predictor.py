"""numpy pair → disparity: padding as the network needs (bottom/right to the fusion network's size
multiple; centred to 32 for RAFT-Stereo, as its demo), device, AMP, cropping back."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from model.network import FusionNetwork
from model.presets import Config
from model.stereo.inputs import centred_padding, check_pair


@dataclass
class Prediction:
    disparity: np.ndarray  # float32 H×W pixels, the fused disparity
    stereo: np.ndarray  # float32 H×W pixels, the stereo branch's last iterate
    mono_align: np.ndarray  # float32 H×W pixels, the aligned mono disparity s_m·D_m + t_m
    confidence: np.ndarray  # float32 H×W in (0, 1), upsampled from the working resolution


class Predictor:
    """Runs ``network`` (eval mode) on single RGB pairs."""

    def __init__(self, network: FusionNetwork, config: Config, device: str = "cpu") -> None:
        self.network = network.to(device).eval()
        self.config, self.device = config, torch.device(device)

    def predict(self, left: np.ndarray, right: np.ndarray, mono: np.ndarray | None = None, *,
                iters: int | None = None, seed: int = 0) -> Prediction:
        """``left``/``right`` RGB uint8 H×W×3 of one size; ``mono`` float32 relative disparity of any
        size (resized, values kept). ``seed`` seeds the flow's noise. ValueError for bad inputs."""
        check_pair(left, right)
        full_height, full_width = left.shape[:2]
        left, right = self._shrunk(left), self._shrunk(right)
        height, width = left.shape[:2]
        multiple, centred = self.config.model.inference_padding
        padding = centred_padding(height, width, multiple) if centred else (0, -width % multiple, 0, -height % multiple)
        left_pad, top = padding[0], padding[2]

        def tensor(image: np.ndarray) -> torch.Tensor:
            t = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float().to(self.device)
            return F.pad(t, padding, mode="replicate")

        mono_t = None
        if mono is not None:
            mono = np.asarray(mono, dtype=np.float32)
            if mono.ndim != 2 or not np.isfinite(mono).all():
                raise ValueError(f"mono must be a finite float H×W map, got shape {mono.shape}")
            mono_t = torch.from_numpy(mono)[None, None].to(self.device)
            mono_t = F.interpolate(mono_t, (height, width), mode="bilinear", align_corners=False)
            mono_t = F.pad(mono_t, padding, mode="replicate")
        generator = torch.Generator(device=self.device).manual_seed(seed)
        amp = self.config.train.amp and self.device.type == "cuda"
        with torch.inference_mode(), torch.autocast(self.device.type, enabled=amp):
            out = self.network(tensor(left), tensor(right), mono_t,
                               iters=iters or self.config.train.test_iters, noise=generator)
        confidence = F.interpolate(out.confidence.float(), out.disparity.shape[2:], mode="bilinear",
                                   align_corners=False)

        def crop(t: torch.Tensor, *, disparity: bool = True) -> np.ndarray:
            t = t[:, :, top:top + height, left_pad:left_pad + width].float()
            if (height, width) != (full_height, full_width):  # back to the input's size, in its pixels
                t = F.interpolate(t, (full_height, full_width), mode="bilinear", align_corners=False)
                t = t * (full_width / width) if disparity else t
            return t[0, 0].cpu().numpy().astype(np.float32)

        return Prediction(crop(out.disparity), crop(out.stereo), crop(out.mono_aligned),
                          crop(confidence, disparity=False))

    def _shrunk(self, image: np.ndarray) -> np.ndarray:
        """``image`` resized (area) to at most ``max_inference_pixels``, or as it is."""
        limit = self.config.model.max_inference_pixels
        height, width = image.shape[:2]
        if not limit or height * width <= limit:
            return image
        factor = (limit / (height * width)) ** 0.5
        return cv2.resize(image, (max(1, round(width * factor)), max(1, round(height * factor))),
                          interpolation=cv2.INTER_AREA)
