"""The authors' keep rule (three-valued) and their sparse sampling."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from annotation.vlm import KeepRule, sparse_expand, sparse_samples, sparse_step

Y, N, U = True, False, None


def answers(**given: bool | None) -> list[bool | None]:
    """All 'no' except the questions named q1..q12."""
    values: list[bool | None] = [False] * 12
    for name, value in given.items():
        values[int(name[1:]) - 1] = value
    return values


def paper_rule(a: list[bool]) -> bool:
    """The rule as the paper states it."""
    return any(a[0:6]) and not (a[6] and not a[7]) and not any(a[8:12])


@pytest.mark.parametrize(
    ("given", "keep", "reason"),
    [
        (answers(q2=Y), True, "kept: Q2 (perspective illusion) yes"),
        (answers(), False, "rejected: Q1–Q6 all no"),
        (answers(q2=Y, q9=Y), False, "rejected: Q9 (too blurry) yes"),
        (
            answers(q2=Y, q7=Y),
            False,
            "rejected: Q7 (excessive watermark/caption) yes and Q8 (corner watermark/caption) no",
        ),
        (answers(q2=Y, q7=Y, q8=Y), True, "kept: Q2 (perspective illusion) yes"),
        ([U] * 12, None, "undecided: unknown Q1–Q12"),
        ([U] * 8 + [Y] + [U] * 3, False, "rejected: Q9 (too blurry) yes"),
        (answers(q1=U, q2=U, q3=U, q4=U, q5=U, q6=U), None, "undecided: unknown Q1–Q6"),
        (answers(q2=Y, q7=U, q8=U), None, "undecided: unknown Q7, Q8"),
        (answers(q2=Y, q7=N, q8=U), True, "kept: Q2 (perspective illusion) yes"),
    ],
)
def test_default_rule(given: list[bool | None], keep: bool | None, reason: str) -> None:
    rule = KeepRule()
    assert rule.explain(given) == (keep, reason)
    assert rule.decide(given) is keep


def test_rule_is_configurable() -> None:
    mirrors_only = KeepRule(any_of=(4,), veto_pair=None, none_of=(9,))
    assert mirrors_only.decide(answers(q4=Y, q7=Y, q11=Y)) is True
    assert mirrors_only.decide(answers(q2=Y)) is False
    assert KeepRule(any_of=(), veto_pair=None, none_of=(9,)).decide(answers()) is True


@pytest.mark.parametrize("bad", [{"any_of": (0,)}, {"none_of": (13,)}, {"veto_pair": (7,)}])
def test_rule_rejects_bad_question_numbers(bad: dict) -> None:
    with pytest.raises(ValueError):
        KeepRule(**bad)


def test_rule_needs_twelve_answers() -> None:
    with pytest.raises(ValueError, match="expected 12 answers"):
        KeepRule().decide([True] * 11)


@settings(max_examples=150)
@given(st.lists(st.sampled_from([Y, N, U]), min_size=12, max_size=12).filter(lambda a: a.count(None) <= 6))
def test_rule_decides_exactly_when_every_completion_agrees(given: list[bool | None]) -> None:
    unknown = [i for i, a in enumerate(given) if a is None]
    outcomes = set()
    for filling in itertools.product([True, False], repeat=len(unknown)):
        complete = list(given)
        for i, value in zip(unknown, filling, strict=True):
            complete[i] = value
        outcomes.add(paper_rule(complete))
    decided = KeepRule().decide(given)
    assert decided == (outcomes.pop() if len(outcomes) == 1 else None)


@pytest.mark.parametrize(("n", "step"), [(0, 1), (5, 1), (19, 1), (50, 5), (999, 99), (1000, 100), (52_000, 100)])
def test_sparse_step(n: int, step: int) -> None:
    assert sparse_step(n) == step


def test_sparse_samples_sit_in_the_middle_of_each_block() -> None:
    assert sparse_samples(1000) == list(range(50, 1000, 100))
    assert sparse_samples(105) == [5, 15, 25, 35, 45, 55, 65, 75, 85, 95, 104]
    assert sparse_samples(7) == list(range(7))
    assert sparse_samples(0) == []


def test_sparse_expand_removes_the_window_of_a_rejected_sample() -> None:
    n = 1000
    samples = sparse_samples(n)
    verdicts: dict[int, bool | None] = {s: True for s in samples}
    verdicts[450] = False
    verdicts[850] = None
    frames = sparse_expand(n, verdicts)
    assert frames[400:501] == [False] * 101  # 450 ± 50
    assert frames[399] is True and frames[501] is True
    assert frames[801:901] == [None] * 100  # nearest sample undecided → a human looks
    assert frames[800] is True  # equidistant from 750 and 850: the earlier sample wins
    assert frames[0] is True and frames[-1] is True


def test_sparse_expand_edge_cases() -> None:
    assert sparse_expand(5, {}) == [None] * 5
    assert sparse_expand(3, {0: True, 2: False}) == [True, True, False]  # step 1: window ±0, tie → earlier
    with pytest.raises(ValueError):
        sparse_expand(10, {10: True})


@settings(max_examples=100)
@given(st.integers(1, 3000), st.data())
def test_sparse_expand_properties(n: int, data: st.DataObject) -> None:
    samples = sparse_samples(n)
    verdicts = {s: data.draw(st.sampled_from([Y, N, U])) for s in samples}
    frames = sparse_expand(n, verdicts)
    half = sparse_step(n) // 2
    assert len(frames) == n
    for f, verdict in enumerate(frames):
        nearest = min(samples, key=lambda s: (abs(s - f), s))
        near_rejection = any(verdicts[s] is False and abs(s - f) <= half for s in samples)
        assert verdict == (False if near_rejection else verdicts[nearest])
    assert all(frames[s] == verdicts[s] or frames[s] is False for s in samples)
