"""Backend choice by name (settings ``vlm_backend`` or ``prefilter --backend``)."""

from __future__ import annotations

from pathlib import Path

from annotation.vlm.backends.base import PrefilterBackend
from annotation.vlm.backends.heuristic import ANSWERED, HeuristicBackend
from annotation.vlm.prompt import N_QUESTIONS
from annotation.vlm.rule import KeepRule

BACKEND_NAMES = ("heuristic", "openai", "transformers")


def answered_questions(name: str) -> tuple[int, ...]:
    """The 1-based numbers of the questions backend ``name`` answers (a VLM answers all 12)."""
    return ANSWERED if name == "heuristic" else tuple(range(1, N_QUESTIONS + 1))


def make_backend(
    name: str,
    *,
    base_url: str = "",
    model: str = "",
    api_key: str = "",
    model_path: Path | None = None,
    device: str = "cpu",
    concurrency: int = 8,
    timeout_s: float = 60.0,
    max_retries: int = 3,
    rule: KeepRule | None = None,
) -> PrefilterBackend:
    """Build a backend. ``concurrency`` is the number of requests in flight (openai) or the generation
    batch size (transformers); ValueError with a one-line message for an unknown name or missing setting."""
    rule = rule or KeepRule()
    if name == "heuristic":
        return HeuristicBackend(rule=rule)
    if name == "openai":
        # Imported here so that the other backends do not need the HTTP client, nor it torch.
        from annotation.vlm.backends.openai_compat import OpenAICompatBackend

        return OpenAICompatBackend(
            base_url,
            model,
            api_key=api_key,
            concurrency=concurrency,
            timeout_s=timeout_s,
            max_retries=max_retries,
            rule=rule,
        )
    if name == "transformers":
        if model_path is None:
            raise ValueError("the transformers backend needs a model path (setting vlm_model_path)")
        from annotation.vlm.backends.transformers_qwen import TransformersQwenBackend

        return TransformersQwenBackend(Path(model_path), device=device, batch_size=concurrency, rule=rule)
    raise ValueError(f"unknown VLM backend {name!r}; choose one of {', '.join(BACKEND_NAMES)}")
