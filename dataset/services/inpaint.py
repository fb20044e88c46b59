"""The configured hole filling as :func:`core.geometry.synthesize_right_view` takes it."""

from __future__ import annotations

from pathlib import Path

from annotation.inpaint import INPAINT_BACKENDS, make_inpainter
from core.geometry import INPAINT_METHODS, HoleFiller, InpaintMethod
from core.geometry.inpaint import check_method

# Every configurable ``inpaint_backend``: the geometry's own methods, then the model-backed ones.
HOLE_FILLERS: tuple[str, ...] = INPAINT_METHODS + INPAINT_BACKENDS


def hole_filler(method: str, lama_model: Path | None = None) -> InpaintMethod | HoleFiller:
    """An OpenCV method name (``telea``, ``ns``, ``none``) as it is, or a model backend's
    ``inpaint`` (``lama`` with the TorchScript file ``lama_model``; the model loads once per file).

    Raises ``InpaintError`` for an unknown name, ``InpainterError`` for a missing or unusable model.
    """
    if method in INPAINT_BACKENDS:
        return make_inpainter(method, model_path=lama_model).inpaint
    return check_method(method)
