"""Choose a monocular depth backend by its configured name (setting ``depth_backend``)."""

from __future__ import annotations

from pathlib import Path

from annotation.depth.base import DepthBackend

DEPTH_BACKENDS = ("precomputed", "depth-anything-v2")


def make_depth_backend(name: str, *, model_path: Path | None = None, device: str = "cpu") -> DepthBackend:
    """The backend called ``name``: "precomputed" (no model; disparities come with the frames) or
    "depth-anything-v2" (``model_path``: a local checkpoint directory; ``device``: a torch device
    such as "cpu" or "cuda"). Raises ValueError with a one-line reason for an unknown name or a
    missing or unusable checkpoint."""
    if name == "precomputed":
        from annotation.depth.precomputed import PrecomputedBackend

        return PrecomputedBackend()
    if name == "depth-anything-v2":
        if model_path is None:
            raise ValueError("the depth-anything-v2 backend needs depth_model_path (a local checkpoint directory)")
        if not Path(model_path).is_dir():
            raise ValueError(f"depth_model_path {model_path} is not a directory")
        # torch and transformers load only when Depth Anything is configured
        from annotation.depth.depth_anything import DepthAnythingBackend

        return DepthAnythingBackend(Path(model_path), device)
    raise ValueError(f"unknown depth backend {name!r}; choose one of {', '.join(DEPTH_BACKENDS)}")
