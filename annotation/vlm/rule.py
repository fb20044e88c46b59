"""The authors' keep rule over the 12 answers, in three-valued logic (unknown answers allowed)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from annotation.vlm.prompt import N_QUESTIONS, question_label


@dataclass(frozen=True)
class KeepRule:
    """Keep a frame if any ``any_of`` answer is yes, and not (``veto_pair[0]`` yes and ``veto_pair[1]`` no),
    and no ``none_of`` answer is yes. Question numbers are 1-based; an empty ``any_of`` requires nothing,
    ``veto_pair=None`` disables the veto. The defaults are the authors' rule."""

    any_of: tuple[int, ...] = (1, 2, 3, 4, 5, 6)
    veto_pair: tuple[int, int] | None = (7, 8)
    none_of: tuple[int, ...] = (9, 10, 11, 12)

    def __post_init__(self) -> None:
        numbers = [*self.any_of, *(self.veto_pair or ()), *self.none_of]
        bad = [q for q in numbers if not isinstance(q, int) or not 1 <= q <= N_QUESTIONS]
        if bad:
            raise ValueError(f"question numbers must be integers in 1..{N_QUESTIONS}, got {bad}")
        if self.veto_pair is not None and len(self.veto_pair) != 2:
            raise ValueError(f"veto_pair must name two questions, got {self.veto_pair}")

    def decide(self, answers: Sequence[bool | None]) -> bool | None:
        """True = keep, False = reject, None = undecidable because of unknown answers (a human decides)."""
        return self.explain(answers)[0]

    def explain(self, answers: Sequence[bool | None]) -> tuple[bool | None, str]:
        """The decision and a one-line reason naming the questions that made it."""
        if len(answers) != N_QUESTIONS:
            raise ValueError(f"expected {N_QUESTIONS} answers, got {len(answers)}")

        def answer(q: int) -> bool | None:
            return answers[q - 1]

        # A definite rejection wins over any unknown, so it is looked for first.
        forbidden = [q for q in self.none_of if answer(q) is True]
        if forbidden:
            return False, "rejected: " + ", ".join(f"{question_label(q)} yes" for q in forbidden)
        if self.veto_pair is not None:
            first, second = self.veto_pair
            if answer(first) is True and answer(second) is False:
                return False, f"rejected: {question_label(first)} yes and {question_label(second)} no"
        if self.any_of and all(answer(q) is False for q in self.any_of):
            return False, "rejected: " + _span(self.any_of) + " all no"

        unknown = [q for q in self.none_of if answer(q) is None]
        if self.veto_pair is not None:
            first, second = self.veto_pair
            if answer(first) is not False and answer(second) is not True:
                unknown += [q for q in self.veto_pair if answer(q) is None]
        wanted = [q for q in self.any_of if answer(q) is True]
        if self.any_of and not wanted:
            unknown += [q for q in self.any_of if answer(q) is None]
        if unknown:
            return None, "undecided: unknown " + _span(tuple(sorted(set(unknown))))
        if not wanted:
            return True, "kept"
        return True, "kept: " + ", ".join(f"{question_label(q)} yes" for q in wanted)


def _span(numbers: tuple[int, ...]) -> str:
    """Question numbers with runs of three or more collapsed: (1, 2, 3, 4, 9) → 'Q1–Q4, Q9'."""
    runs: list[list[int]] = []
    for q in numbers:
        if runs and q == runs[-1][-1] + 1:
            runs[-1].append(q)
        else:
            runs.append([q])
    return ", ".join(f"Q{run[0]}–Q{run[-1]}" if len(run) > 2 else ", ".join(f"Q{q}" for q in run) for run in runs)
