"""Choose proposers by their configured names (settings ``proposers``)."""

from __future__ import annotations

from collections.abc import Sequence

from annotation.proposals.base import Proposer
from annotation.segment.base import Segmenter
from annotation.vlm.backends.base import PrefilterBackend

PROPOSERS = ("plane-break", "vlm")


def make_proposers(names: Sequence[str], *, vlm: PrefilterBackend | None = None,
                   segmenter: Segmenter | None = None, min_score: float | None = None) -> list[Proposer]:
    """The proposers called ``names``, in order. ``vlm`` (the configured VLM backend) and ``segmenter``
    serve the "vlm" proposer; ``min_score`` is the least score plane-break keeps (None: its
    DEFAULT_THRESHOLD; its SCORE_FLOOR keeps all, for a threshold applied later). ValueError with a
    one-line reason for an unknown name or a missing part."""
    proposers: list[Proposer] = []
    for name in names:
        if name == "plane-break":
            from annotation.proposals.plane_break import DEFAULT_THRESHOLD, PlaneBreakProposer

            proposers.append(PlaneBreakProposer(min_score=DEFAULT_THRESHOLD if min_score is None else min_score))
        elif name == "vlm":
            if vlm is None or segmenter is None:
                raise ValueError("the vlm proposer needs the configured VLM backend and segmenter")
            from annotation.proposals.vlm import VlmProposer

            proposers.append(VlmProposer(vlm, segmenter))
        else:
            raise ValueError(f"unknown proposer {name!r}; choose among {', '.join(PROPOSERS)}")
    return proposers
