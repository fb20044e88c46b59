"""Tolerant reading of a VLM's reply to the 12-question prompt.

Accepted: "yes,no,...", "Yes, No, no.", space-separated words, an "Answer:" preamble,
numbered lists ("1. Yes", "Q2: No - because ...") with or without explanations, and a
leading <think>…</think> block. Anything that does not give exactly 12 answers is
*unparsed* (it goes to a human), never guessed: a reply with explanations that repeat
"no" inside a comma list is unparsed rather than mis-counted into a wrong verdict.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from annotation.vlm.prompt import N_QUESTIONS

_ANSWER = re.compile(r"\b(yes|no)\b", re.IGNORECASE)
_SEGMENT_SEPARATORS = re.compile(r"[,;|\n]+")
_NUMBERED_LINE = re.compile(r"^\s*(?:q(?:uestion)?\s*)?(\d{1,2})\s*[.):\-]", re.IGNORECASE)
_THINKING = re.compile(r"<think>.*?</think>", re.IGNORECASE | re.DOTALL)
_LETTER = re.compile(r"[^\W\d_]")


@dataclass(frozen=True)
class ParsedAnswers:
    """The 12 answers in question order (True = yes), or None with the reason it is unreadable."""

    answers: tuple[bool, ...] | None
    reason: str = ""

    @property
    def parsed(self) -> bool:
        return self.answers is not None


def parse_answers(text: str) -> ParsedAnswers:
    """Read a reply to the prompt; ``.parsed`` is False (with ``.reason``) unless exactly 12 answers are found."""
    text = _THINKING.sub(" ", text or "").strip()
    if not text:
        return ParsedAnswers(None, "empty answer")
    words = _numbered_answers(text)
    if words is None:
        words = _segment_answers(text)
    if not words:
        return ParsedAnswers(None, "no yes/no answer found")
    if len(words) != N_QUESTIONS:
        return ParsedAnswers(None, f"expected {N_QUESTIONS} answers, found {len(words)}")
    return ParsedAnswers(tuple(word.lower() == "yes" for word in words))


def format_answers(answers: Sequence[bool | None]) -> str:
    """The prompt's own reply format, with '?' for an unknown answer: 'no,no,?,yes,…'."""
    return ",".join("?" if a is None else ("yes" if a else "no") for a in answers)


def _numbered_answers(text: str) -> list[str] | None:
    """First yes/no of each line numbered 1..12 (in that order), or None when the reply is not such a list."""
    numbered = [(m, line) for line in text.splitlines() if (m := _NUMBERED_LINE.match(line))]
    if [int(m.group(1)) for m, _ in numbered] != list(range(1, N_QUESTIONS + 1)):
        return None
    found = [_ANSWER.search(line, m.end()) for m, line in numbered]
    return [f.group(1) for f in found] if all(found) else None


def _segment_answers(text: str) -> list[str]:
    """Split on , ; | and newlines; a segment of bare answers gives them all, one with other words its first."""
    words: list[str] = []
    for segment in _SEGMENT_SEPARATORS.split(text):
        found = _ANSWER.findall(segment)
        if not found:
            continue
        if _LETTER.search(_ANSWER.sub(" ", segment)):
            words.append(found[0])
        else:
            words.extend(found)
    return words
