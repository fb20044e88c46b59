"""Choose a model-backed inpainting backend by its configured name (setting ``inpaint_backend``)."""

from __future__ import annotations

from pathlib import Path

from annotation.inpaint.base import Inpainter, InpainterError

INPAINT_BACKENDS = ("lama",)


def make_inpainter(name: str, *, model_path: Path | None = None, device: str = "cpu") -> Inpainter:
    """The backend called ``name``: "lama" (``model_path``: a TorchScript LaMa file; ``device``: a
    torch device such as "cpu" or "cuda"). Raises :class:`InpainterError` with a one-line reason
    for an unknown name or a missing or unusable model."""
    if name == "lama":
        if model_path is None:
            raise InpainterError("LaMa inpainting needs a TorchScript model path (--lama-model / lama_model_path)")
        # torch loads only when LaMa is configured
        from annotation.inpaint.lama import LamaInpainter

        return LamaInpainter(Path(model_path), device)
    raise InpainterError(f"unknown inpainting backend {name!r}; choose one of {', '.join(INPAINT_BACKENDS)}")
