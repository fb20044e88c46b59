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
