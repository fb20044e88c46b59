"""The dashboard's funnel: frames the prefilter rejected never passed it, so "prefiltered" leaves
them out; frames a curator rejected after the prefilter passed them stay counted."""

from __future__ import annotations

from dataset.db import transaction
from dataset.services.frames import funnel_counts
from dataset.tables import FrameState, PrefilterResult
from tests.test_data_layer import _frame, _video


def test_prefiltered_counts_only_the_frames_that_passed_the_prefilter(sessions) -> None:  # type: ignore[no-untyped-def]
    verdicts = [(FrameState.rejected, False), (FrameState.rejected, False), (FrameState.rejected, True),
                (FrameState.rejected, None), (FrameState.prefiltered, None), (FrameState.approved, False),
                (FrameState.ingested, None)]
    with transaction(sessions) as s:
        video = _video(s)
        for i, (state, keep) in enumerate(verdicts):
            frame = _frame(s, video, i, state)
            if keep is not None:  # the trigger keeps the newest verdict on the frame
                s.add(PrefilterResult(frame_id=frame.id, backend="heuristic", model_id="m", prompt_version="v1",
                                      answers=[None] * 12, keep=keep))
    with sessions() as s:
        counts = funnel_counts(s)
    # the two the prefilter dropped are out; the one it kept, the undecided one (both then rejected by
    # a curator), the one waiting for review and the one a curator approved against it are in
    assert (counts["frames"], counts["prefiltered"], counts["approved"]) == (7, 4, 1)
