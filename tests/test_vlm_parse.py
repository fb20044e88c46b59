"""The prompt and the tolerant answer parser."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from annotation.vlm import PROMPT, PROMPT_VERSION, QUESTIONS, format_answers, parse_answers

NO = [False] * 12
ONE_YES = tuple([True] + [False] * 11)


def test_prompt_is_the_papers_twelve_questions_in_order() -> None:
    assert len(QUESTIONS) == 12 and all(q.endswith("?") for q in QUESTIONS)
    assert PROMPT.startswith("Reply to me in the format of a string concatenating 'yes' or 'no' with ','.")
    positions = [PROMPT.index(q) for q in QUESTIONS]
    assert positions == sorted(positions)
    assert QUESTIONS[8] == "Is this image too blurry?"
    assert PROMPT_VERSION == "paper-v1"


@pytest.mark.parametrize(
    "text",
    [
        "yes,no,no,no,no,no,no,no,no,no,no,no",
        "Yes, No, no, NO, no, no, no, no, no, no, no, no.",
        "yes no no no no no no no no no no no",
        "Answer: yes, no, no, no, no, no, no, no, no, no, no, no",
        "'yes','no','no','no','no','no','no','no','no','no','no','no'",
        "yes;no;no;no;no;no;no;no;no;no;no;no\n",
        "\n".join(["1. Yes"] + [f"{i}. No" for i in range(2, 13)]),
        "Here you are:\n"
        + "\n".join(["Q1: Yes, it is a flat painting.", *(f"Q{i}) No, there is no such thing." for i in range(2, 13))]),
        "<think>the wall has no painting... or yes?</think>yes,no,no,no,no,no,no,no,no,no,no,no",
    ],
)
def test_variants_parse(text: str) -> None:
    parsed = parse_answers(text)
    assert parsed.parsed and parsed.reason == ""
    assert parsed.answers == ONE_YES


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "empty answer"),
        ("   \n", "empty answer"),
        ("I cannot tell from this picture.", "no yes/no answer found"),
        ("yes,no,no,no,no,no,no,no,no,no,no", "expected 12 answers, found 11"),
        ("yes,no,no,no,no,no,no,no,no,no,no,no,no", "expected 12 answers, found 13"),
        ("yes,no,no,no,no,no,no,no,no,no,no,no, and there is no caption", "expected 12 answers, found 13"),
        ("yes/no, " * 12, "expected 12 answers, found 24"),
        (", , , maybe wall the , .", "no yes/no answer found"),
    ],
)
def test_unreadable_replies_are_unparsed_with_a_reason(text: str, reason: str) -> None:
    parsed = parse_answers(text)
    assert not parsed.parsed and parsed.answers is None
    assert parsed.reason == reason


def test_format_answers_writes_the_reply_format_with_unknowns() -> None:
    assert format_answers([True, None, *NO[2:]]) == "yes,?,no,no,no,no,no,no,no,no,no,no"


@given(
    answers=st.lists(st.booleans(), min_size=12, max_size=12),
    separator=st.sampled_from([",", ", ", " , ", ";", "\n", " "]),
    upper=st.booleans(),
    period=st.booleans(),
)
def test_formatted_answers_parse_back(answers: list[bool], separator: str, upper: bool, period: bool) -> None:
    text = separator.join("yes" if a else "no" for a in answers) + ("." if period else "")
    assert parse_answers(text.upper() if upper else text).answers == tuple(answers)


@given(st.text(max_size=300))
def test_any_text_is_parsed_or_given_a_reason_never_raises(text: str) -> None:
    parsed = parse_answers(text)
    assert (parsed.answers is not None and len(parsed.answers) == 12 and parsed.reason == "") or (
        parsed.answers is None and parsed.reason
    )
