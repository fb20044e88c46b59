"""The interface every prefilter backend implements."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from annotation.vlm.verdict import Verdict


@runtime_checkable
class PrefilterBackend(Protocol):
    """Answers the 12 questions for frames. ``classify`` returns one Verdict per image, in order, and
    never raises for one bad image or answer (that Verdict carries the error / parsed=False)."""

    name: str  # "heuristic", "openai", "transformers"
    model_id: str  # what answered: the served model name, the checkpoint, the heuristic's version
    prompt_version: str  # the question set the answers refer to

    def classify(self, images: Sequence[np.ndarray]) -> list[Verdict]:
        """Verdicts for RGB uint8 HxWx3 images."""
        ...

    def close(self) -> None:
        """Release connections, threads and model memory."""
        ...


class AskError(RuntimeError):
    """A free prompt got no answer (server unreachable, HTTP error, generation failed)."""


@runtime_checkable
class FreePromptBackend(Protocol):
    """A backend that also answers a free prompt (the VLM ones; the heuristic backend cannot)."""

    def ask(self, image: np.ndarray, prompt: str, max_tokens: int = 512) -> str:
        """The model's reply to ``prompt`` about ``image`` (RGB uint8 HxWx3), at most ``max_tokens``
        tokens, greedy; AskError when no reply came."""
        ...
