"""Choose a segmenter backend by its configured name."""

from __future__ import annotations

from pathlib import Path

from annotation.segment.base import Segmenter

SEGMENTERS = ("classical", "sam2")


def make_segmenter(name: str, *, model_path: Path | None = None, device: str = "cpu") -> Segmenter:
    """The segmenter called ``name``: "classical" (no weights) or "sam2" (``model_path``: a
    local SAM2 checkpoint directory; ``device``: a torch device such as "cpu" or "cuda").
    Raises ValueError with a one-line reason for an unknown name or a missing checkpoint."""
    if name == "classical":
        from annotation.segment.classical import ClassicalSegmenter

        return ClassicalSegmenter()
    if name == "sam2":
        if model_path is None:
            raise ValueError("the sam2 segmenter needs sam2_model_path (a local checkpoint directory)")
        if not Path(model_path).is_dir():
            raise ValueError(f"sam2_model_path {model_path} is not a directory")
        # torch and transformers load only when SAM2 is configured
        from annotation.segment.sam2 import Sam2Segmenter

        return Sam2Segmenter(Path(model_path), device)
    raise ValueError(f"unknown segmenter {name!r}; choose one of {', '.join(SEGMENTERS)}")
