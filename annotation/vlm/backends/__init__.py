"""Prefilter backends: the interface and the registry (backend modules are imported on demand)."""

from annotation.vlm.backends.base import AskError, FreePromptBackend, PrefilterBackend
from annotation.vlm.backends.registry import BACKEND_NAMES, answered_questions, make_backend

__all__ = ["BACKEND_NAMES", "AskError", "FreePromptBackend", "PrefilterBackend", "answered_questions", "make_backend"]
