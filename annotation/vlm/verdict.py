"""The outcome of asking about one frame: answers, keep decision, reason, measured figures or error."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from annotation.vlm.parse import parse_answers
from annotation.vlm.rule import KeepRule


@dataclass(frozen=True)
class Verdict:
    """One frame's prefilter result.

    raw: the model's reply text (for the heuristic: its answers in the reply format, '?' = unknown);
    answers: 12 answers in question order (None = unknown), None when unparsed or failed;
    parsed: the reply was readable; keep: True/False, or None when a human must decide;
    reason: why ``keep`` is what it is (or why the reply was unreadable); metrics: measured
    figures (latency, sharpness, …); error: why no answer was obtained (server error, timeout, …).
    """

    raw: str
    answers: tuple[bool | None, ...] | None
    parsed: bool
    keep: bool | None
    reason: str
    metrics: dict[str, float] = field(default_factory=dict)
    error: str | None = None

    @classmethod
    def from_text(cls, raw: str, rule: KeepRule, metrics: Mapping[str, float] | None = None) -> Verdict:
        """Parse a VLM reply and apply the keep rule; an unreadable reply is unparsed with keep None."""
        parsed = parse_answers(raw)
        if parsed.answers is None:
            return cls(raw, None, False, None, parsed.reason, dict(metrics or {}))
        return cls.from_answers(parsed.answers, rule, raw=raw, metrics=metrics)

    @classmethod
    def from_answers(
        cls, answers: Sequence[bool | None], rule: KeepRule, *, raw: str, metrics: Mapping[str, float] | None = None
    ) -> Verdict:
        """Answers obtained otherwise than by parsing text (None = unknown)."""
        keep, reason = rule.explain(answers)
        return cls(raw, tuple(answers), True, keep, reason, dict(metrics or {}))

    @classmethod
    def failed(cls, error: str, *, raw: str = "", metrics: Mapping[str, float] | None = None) -> Verdict:
        """No answer could be obtained; a human decides."""
        return cls(raw, None, False, None, "no answer: " + error, dict(metrics or {}), error)


def image_problem(image: object) -> str | None:
    """Why ``image`` is not an RGB uint8 HxWx3 array, or None when it is one."""
    if not isinstance(image, np.ndarray):
        return f"invalid image: expected a numpy array, got {type(image).__name__}"
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3 or 0 in image.shape:
        return f"invalid image: expected RGB uint8 HxWx3, got {image.dtype} {image.shape}"
    return None
