"""SAM2 through Hugging Face ``transformers``: ``Sam2Model`` for clicks, ``Sam2VideoModel`` for
propagation, loaded with ``from_pretrained`` from one local directory.

The directory's ``config.json`` decides what it serves. A ``sam2_video`` checkpoint (what the
official ``facebook/sam2.1-hiera-*`` repositories hold) serves both: ``Sam2Model`` loads the
image part of it (transformers supports loading the subset), ``Sam2VideoModel`` the whole. A
``sam2`` (image-only) checkpoint serves clicks, and propagation falls back to optical flow.

Pre- and post-processing are done here with OpenCV rather than with ``Sam2Processor``: its
image processor exists only as a torchvision backend, and the CPU build of torch has no
matching torchvision wheel. What it does is small and fixed: resize to the model's square
input (no aspect preservation), ImageNet normalisation (or the directory's
``preprocessor_config.json`` values), point and box coordinates scaled by the same factors,
low-resolution mask logits resized back to the image and thresholded at 0.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import torch
from transformers import Sam2Model, Sam2VideoInferenceSession, Sam2VideoModel

from annotation.checkpoints import PROCESSOR_FILE, open_checkpoint
from annotation.segment.base import (
    Box,
    Embedding,
    MaskCandidate,
    Progress,
    SegmentError,
    check_image,
    check_mask,
    check_prompt,
)
from annotation.segment.propagate import flow_propagate
from core.formats.masks import cv_mask

_IMAGENET_MEAN = (0.485, 0.456, 0.406)
_IMAGENET_STD = (0.229, 0.224, 0.225)
# A bool mask as mask-decoder input logits: the value SAM2 itself gives a mask used as output.
_MASK_LOGIT_SCALE, _MASK_LOGIT_BIAS = 20.0, -10.0
_OBJECT_ID = 1


class Sam2Segmenter:
    """SAM2 click segmentation and video propagation from a local checkpoint directory."""

    name = "sam2"

    def __init__(self, model_path: Path, device: str = "cpu") -> None:
        checkpoint = open_checkpoint(model_path, "SAM2", {"sam2", "sam2_video"})
        self.model_path = checkpoint.path
        self.has_video = checkpoint.model_type == "sam2_video"
        self.device = torch.device(device)
        self.model_id = checkpoint.model_id(self.name)
        self.model = Sam2Model.from_pretrained(self.model_path).to(self.device).eval()
        self._video_model: Sam2VideoModel | None = None
        self.input_size = int(self.model.config.prompt_encoder_config.image_size)
        self._mean, self._std = _pixel_statistics(self.model_path)

    def encode(self, image: np.ndarray) -> Embedding:
        """The image encoder's multi-level features (float16, ``feat0``..``featN``, highest
        resolution first) — all the mask decoder needs."""
        image = check_image(image)
        with torch.inference_mode():
            features = self.model.get_image_embeddings(self._pixels([image]))
        arrays = {f"feat{i}": f[0].to(torch.float16).cpu().numpy() for i, f in enumerate(features)}
        return Embedding(self.model_id, image.shape[0], image.shape[1], arrays)

    def predict(self, embedding: Embedding, points: np.ndarray, labels: np.ndarray,
                box: Box | None = None, prev_mask: np.ndarray | None = None) -> list[MaskCandidate]:
        """SAM2's three masks (multimask output), best predicted IoU first."""
        prompt = check_prompt(embedding, self.model_id, points, labels, box, prev_mask)
        h, w = embedding.height, embedding.width
        features = self._features(embedding)
        to_input = np.array([self.input_size / w, self.input_size / h])
        kwargs: dict[str, torch.Tensor] = {}
        if len(prompt.points):
            kwargs["input_points"] = self._tensor(prompt.points * to_input).reshape(1, 1, -1, 2)
            kwargs["input_labels"] = torch.as_tensor(prompt.labels, device=self.device).reshape(1, 1, -1)
        if prompt.box is not None:
            kwargs["input_boxes"] = self._tensor(np.reshape(prompt.box, (2, 2)) * to_input).reshape(1, 1, 4)
        if prompt.prev_mask is not None:
            mask_size = tuple(self.model.prompt_encoder.mask_input_size)
            small = cv2.resize(cv_mask(prompt.prev_mask, np.float32), mask_size[::-1], interpolation=cv2.INTER_AREA)
            kwargs["input_masks"] = self._tensor(small * _MASK_LOGIT_SCALE + _MASK_LOGIT_BIAS)[None, None]
        with torch.inference_mode():
            out = self.model(image_embeddings=features, multimask_output=True, **kwargs)
        logits = out.pred_masks[0, 0].float().cpu().numpy()
        scores = out.iou_scores[0, 0].float().cpu().numpy()
        order = np.argsort(-scores, kind="stable")
        return [MaskCandidate(_upsample_logits(logits[i], h, w), float(np.clip(scores[i], 0, 1)))
                for i in order]

    def propagate(self, frames: Sequence[np.ndarray], mask: np.ndarray, *,
                  progress: Progress | None = None) -> list[np.ndarray]:
        """``Sam2VideoModel`` tracking from the mask on frame 0 (optical flow for an image-only
        checkpoint)."""
        if not frames:
            return []
        images = [check_image(f) for f in frames]
        h, w = images[0].shape[:2]
        mask = check_mask(mask, h, w)
        if any(im.shape[:2] != (h, w) for im in images):
            raise SegmentError("all frames of a propagation must have the same size")
        if not self.has_video:
            return flow_propagate(images, mask, progress=progress)
        model = self._video()
        session = Sam2VideoInferenceSession(
            video=self._pixels(images), video_height=h, video_width=w,
            inference_device=self.device, video_storage_device=self.device,
            inference_state_device=self.device, dtype=torch.float32)
        # what Sam2VideoProcessor.add_inputs_to_inference_session does for a mask prompt
        square = cv2.resize(cv_mask(mask, np.float32), (self.input_size, self.input_size),
                            interpolation=cv2.INTER_AREA) >= 0.5
        session.add_mask_inputs(session.obj_id_to_idx(_OBJECT_ID), 0, self._tensor(square)[None, None])
        session.obj_with_new_inputs = [_OBJECT_ID]
        out = []
        with torch.inference_mode():
            for result in model.propagate_in_video_iterator(session, start_frame_idx=0):
                if result.frame_idx == 0:
                    continue
                logits = result.pred_masks[0, 0].float().cpu().numpy()
                out.append(_upsample_logits(logits, h, w))
                if progress is not None:
                    progress(len(out) / (len(images) - 1))
        return out

    def _video(self) -> Sam2VideoModel:
        """The video model, loaded on first use (clicks never need it)."""
        if self._video_model is None:
            self._video_model = Sam2VideoModel.from_pretrained(self.model_path).to(self.device).eval()
        return self._video_model

    def _pixels(self, images: Sequence[np.ndarray]) -> torch.Tensor:
        """float32 (N, 3, S, S) normalised model input of RGB uint8 images."""
        size = (self.input_size, self.input_size)
        batch = np.stack([
            cv2.resize(im, size, interpolation=cv2.INTER_AREA if max(im.shape[:2]) > self.input_size
                       else cv2.INTER_LINEAR) for im in images]).astype(np.float32) / 255.0
        batch = (batch - self._mean) / self._std
        return torch.from_numpy(batch.transpose(0, 3, 1, 2).copy()).to(self.device)

    def _features(self, embedding: Embedding) -> list[torch.Tensor]:
        """The embedding's feature levels as float32 (1, C, h, w) tensors on the device."""
        names = sorted((k for k in embedding.arrays if k.startswith("feat")), key=lambda k: int(k[4:]))
        expected = len(self.model.config.vision_config.backbone_feature_sizes)
        if len(names) != expected:
            raise SegmentError(f"SAM2 embedding has {len(names)} feature levels, the model needs {expected}")
        return [torch.from_numpy(embedding.arrays[k]).to(self.device, torch.float32)[None] for k in names]

    def _tensor(self, array: np.ndarray) -> torch.Tensor:
        """float32 tensor on the model's device."""
        return torch.as_tensor(np.asarray(array, dtype=np.float32), device=self.device)


def _pixel_statistics(model_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) float32 (3,) for normalising [0, 1] RGB: the directory's processor config
    when present, else ImageNet's (what every SAM2 checkpoint uses)."""
    mean, std = _IMAGENET_MEAN, _IMAGENET_STD
    config = model_path / PROCESSOR_FILE
    if config.is_file():
        values = json.loads(config.read_text())
        mean, std = values.get("image_mean", mean), values.get("image_std", std)
    return np.asarray(mean, np.float32), np.asarray(std, np.float32)


def _upsample_logits(logits: np.ndarray, height: int, width: int) -> np.ndarray:
    """bool (height, width): low-resolution mask logits resized bilinearly, thresholded at 0."""
    return cv2.resize(logits, (width, height), interpolation=cv2.INTER_LINEAR) > 0
