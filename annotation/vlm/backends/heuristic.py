"""The embedded default: no weights, answers only what it can measure and leaves the rest unknown.

Answered (others stay None, so a frame normally goes to a curator with the figures shown):
- Q9 "too blurry": yes when even the sharpest tenth of the frame is soft — the 90th percentile
  of per-tile Laplacian variance below BLURRY_BELOW; no from SHARP_FROM up; unknown between.
  On the synthetic rooms sharp frames measure ≥ 550, a Gaussian blur of σ = 2 px (at 640 px
  wide) ≤ 125, σ = 1 px 40–740: so only clearly blurred frames are rejected. A sharp but almost
  featureless frame (a blank wall) also measures low: that is the main false "yes".
- Q7 "excessive watermarks or captions": yes when caption rows make up at least CAPTION_BAND_MIN
  of the height or text lines cover at least TEXT_AREA_MIN of the area; no when no text line
  is found at all; unknown otherwise.
- Q8 "small watermarks or captions in the corners": yes when a text line sits alone in a
  corner, else no.
Text finding misses low-contrast text and text over busy texture (see annotation.vlm.measure),
so its "no" answers mean "none found", and they can never keep a frame on their own.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from annotation.vlm.measure import FrameFigures, measure_frame
from annotation.vlm.parse import format_answers
from annotation.vlm.prompt import N_QUESTIONS, PROMPT_VERSION
from annotation.vlm.rule import KeepRule
from annotation.vlm.verdict import Verdict, image_problem

BLURRY_BELOW = 60.0
SHARP_FROM = 300.0
CAPTION_BAND_MIN = 0.05
TEXT_AREA_MIN = 0.05
ANSWERED = (7, 8, 9)  # the questions heuristic_answers can answer; the rest always stay unknown


def heuristic_answers(figures: FrameFigures) -> tuple[bool | None, ...]:
    """The 12 answers the figures support (None = not measurable)."""
    answers: list[bool | None] = [None] * N_QUESTIONS
    if figures.laplacian_var_p90 < BLURRY_BELOW:
        answers[9 - 1] = True
    elif figures.laplacian_var_p90 >= SHARP_FROM:
        answers[9 - 1] = False
    if figures.caption_band_fraction >= CAPTION_BAND_MIN or figures.text_area_fraction >= TEXT_AREA_MIN:
        answers[7 - 1] = True
    elif figures.text_area_fraction == 0.0:
        answers[7 - 1] = False
    answers[8 - 1] = figures.corner_text_count > 0
    return tuple(answers)


class HeuristicBackend:
    """Prefilter by image measurements; see the module doc for what it answers and its limits."""

    name = "heuristic"
    model_id = "heuristic-v1"
    prompt_version = PROMPT_VERSION

    def __init__(self, rule: KeepRule | None = None) -> None:
        self._rule = rule or KeepRule()

    def classify(self, images: Sequence[np.ndarray]) -> list[Verdict]:
        """One Verdict per RGB uint8 HxWx3 image; ``metrics`` holds the measured figures."""
        return [self._classify_one(image) for image in images]

    def close(self) -> None:
        """Nothing to release."""

    def _classify_one(self, image: np.ndarray) -> Verdict:
        problem = image_problem(image)
        if problem:
            return Verdict.failed(problem)
        figures = measure_frame(image)
        answers = heuristic_answers(figures)
        return Verdict.from_answers(answers, self._rule, raw=format_answers(answers), metrics=figures.as_metrics())
