"""Qwen2-VL / Qwen2.5-VL run in-process with Hugging Face transformers, from a local checkpoint.

The checkpoint directory is what ``save_pretrained`` writes (config, weights, tokenizer with its
chat template, preprocessor_config.json); ``AutoModelForImageTextToText`` picks the Qwen2-VL or
Qwen2.5-VL class from the config. Frames are answered in batches, greedily, with a short
answer budget.

The processor is assembled from the tokenizer and the image processor rather than loaded with
``AutoProcessor``: Qwen2VLProcessor insists on a video processor, which needs torchvision even
for images only (transformers issue #48558), and torchvision is not installable beside every
torch build. Without torchvision the image processor is the PIL one.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from transformers import AutoImageProcessor, AutoModelForImageTextToText, AutoTokenizer

from annotation.checkpoints import open_checkpoint
from annotation.vlm.backends.base import AskError
from annotation.vlm.prompt import ANSWER_TOKEN_BUDGET, PROMPT, PROMPT_VERSION
from annotation.vlm.rule import KeepRule
from annotation.vlm.verdict import Verdict, image_problem

logger = logging.getLogger(__name__)


class TransformersQwenBackend:
    """Prefilter with a local Qwen2-VL-family checkpoint on ``device`` ("cpu", "cuda", "cuda:1", …)."""

    name = "transformers"
    prompt_version = PROMPT_VERSION

    def __init__(
        self,
        model_path: Path,
        *,
        device: str = "cpu",
        batch_size: int = 4,
        max_new_tokens: int = ANSWER_TOKEN_BUDGET,
        rule: KeepRule | None = None,
    ) -> None:
        """Load the checkpoint; ValueError (one line) when ``model_path`` holds no usable Qwen2-VL model."""
        checkpoint = open_checkpoint(model_path, "Qwen2-VL")
        path = checkpoint.path
        if batch_size < 1:
            raise ValueError("transformers backend needs batch_size ≥ 1")
        try:
            self._tokenizer = AutoTokenizer.from_pretrained(path)
            self._image_processor = AutoImageProcessor.from_pretrained(path)
            model = AutoModelForImageTextToText.from_pretrained(path, dtype="auto")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            first_line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise ValueError(f"cannot load a Qwen2-VL model from {path}: {first_line}") from exc
        image_token_id = getattr(model.config, "image_token_id", None)
        if image_token_id is None or self._tokenizer.chat_template is None:
            raise ValueError(f"{path} is not a Qwen2-VL-style checkpoint (no image token or no chat template)")
        self._model = model.to(device).eval()
        self._device = device
        self._batch_size = batch_size
        self._max_new_tokens = max_new_tokens
        self._rule = rule or KeepRule()
        self._image_token_id = int(image_token_id)
        self._image_token = self._tokenizer.convert_ids_to_tokens(self._image_token_id)
        # Left padding: every row of a batch must end where generation starts.
        self._tokenizer.padding_side = "left"
        self._prompt = self._chat(PROMPT)
        if self._prompt.count(self._image_token) != 1:
            raise ValueError(f"the chat template of {path} does not place one {self._image_token} per image")
        self.model_id = checkpoint.model_id(checkpoint.model_type)

    def classify(self, images: Sequence[np.ndarray]) -> list[Verdict]:
        """One Verdict per RGB uint8 HxWx3 image; a failed batch fails only its own frames."""
        verdicts: list[Verdict | None] = [None] * len(images)
        valid: list[int] = []
        for index, image in enumerate(images):
            problem = image_problem(image)
            if problem:
                verdicts[index] = Verdict.failed(problem)
            else:
                valid.append(index)
        for start in range(0, len(valid), self._batch_size):
            batch = valid[start : start + self._batch_size]
            started = time.perf_counter()
            try:
                replies = self._generate([images[i] for i in batch])
            except Exception as exc:  # out of memory, a bad checkpoint, …: record it, keep the other batches
                logger.exception("prefilter generation failed")
                for i in batch:
                    verdicts[i] = Verdict.failed(f"generation failed ({type(exc).__name__}: {exc})")
                continue
            metrics = {"batch_seconds": time.perf_counter() - started, "batch_size": float(len(batch))}
            for i, reply in zip(batch, replies, strict=True):
                verdicts[i] = Verdict.from_text(reply, self._rule, metrics=metrics)
        return [v for v in verdicts if v is not None]

    def ask(self, image: np.ndarray, prompt: str, max_tokens: int = 512) -> str:
        """The greedy reply to a free ``prompt`` about ``image``; AskError when generation fails."""
        problem = image_problem(image)
        if problem:
            raise AskError(problem)
        try:
            return self._generate([image], self._chat(prompt), max_tokens)[0]
        except Exception as exc:  # out of memory, a bad checkpoint, …: the caller decides
            raise AskError(f"generation failed ({type(exc).__name__}: {exc})") from exc

    def close(self) -> None:
        """Drop the model so its memory can be freed."""
        del self._model
        if torch.cuda.is_available():
            torch.cuda.empty_cache()

    def _chat(self, text: str) -> str:
        """The chat-templated prompt: one image, then ``text``, then the assistant's turn."""
        messages = [{"role": "user", "content": [{"type": "image"}, {"type": "text", "text": text}]}]
        return self._tokenizer.apply_chat_template(messages, add_generation_prompt=True, tokenize=False)

    @torch.inference_mode()
    def _generate(self, images: Sequence[np.ndarray], prompt: str | None = None,
                  max_new_tokens: int | None = None) -> list[str]:
        vision = self._image_processor(images=list(images), return_tensors="pt")
        tokens_per_patch = self._image_processor.merge_size**2
        # What Qwen2VLProcessor does: one image token per merged patch of that image.
        texts = [
            (prompt or self._prompt).replace(self._image_token, self._image_token * (int(grid.prod()) // tokens_per_patch), 1)
            for grid in vision["image_grid_thw"]
        ]
        text = self._tokenizer(texts, padding=True, return_tensors="pt")
        # Marks image positions for multimodal RoPE (the processor's mm_token_type_ids).
        text["mm_token_type_ids"] = (text["input_ids"] == self._image_token_id).long()
        inputs = {name: tensor.to(self._device) for name, tensor in {**text, **vision}.items()}
        inputs["pixel_values"] = inputs["pixel_values"].to(self._model.dtype)
        output = self._model.generate(**inputs, max_new_tokens=max_new_tokens or self._max_new_tokens,
                                     do_sample=False)
        return self._tokenizer.batch_decode(output[:, text["input_ids"].shape[1] :], skip_special_tokens=True)
