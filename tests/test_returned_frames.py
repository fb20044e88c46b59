"""A sample a curator rejects goes back to its annotator: the frame's details carry who sent it back,
when and why, and the queue hands it to that annotator before any other frame (to others last)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select, update

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.services.annotate import frame_detail, save_annotation
from dataset.services.demo import true_regions
from dataset.services.frames import update_frame
from dataset.services.leases import next_frame
from dataset.services.sample_review import review_sample
from dataset.tables import Annotation, Frame, FrameState, Role, Sample, SampleState
from tests.test_generate import prepare
from webapp.runtime import Runtime

REASON = "mask misses the picture's left edge"


def submitted_and_generated(s: Any, media: Any, frame: Frame, user: Any) -> Sample:
    """The annotator submits the frame's true masks; a sample is made of them (as generate would)."""
    ann = save_annotation(s, frame.id, user, version=0, regions=true_regions(media, frame, frame.video),
                          illusion_type="picture", submit=True)
    update_frame(s, frame, state=FrameState.generated)
    sample = Sample(frame_id=frame.id, annotation_version=ann.version, state=SampleState.generated)
    s.add(sample)
    s.flush()
    return sample


@pytest.fixture
def workspace(runtime: Runtime, tmp_path: Path) -> Iterator[dict[str, Any]]:
    """Four approved frames of one video; `ana` submitted the third, and its sample awaits review."""
    prepare(runtime, tmp_path, n_frames=4, annotate=False)
    with transaction(runtime.sessions) as s:
        people = {name: user_service.create_user(s, name, role, "long-enough-pw")
                  for name, role in (("ana", Role.annotator), ("bo", Role.annotator), ("cy", Role.curator))}
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        sample = submitted_and_generated(s, runtime.media, frames[2], people["ana"])
    yield {"people": people, "frames": [f.id for f in frames], "sample": sample.id}


def test_a_rejected_sample_goes_back_to_its_annotator_first(runtime: Runtime, workspace: dict[str, Any]) -> None:
    people, frames = workspace["people"], workspace["frames"]
    with transaction(runtime.sessions) as s:
        assert frame_detail(s, frames[2], people["ana"])["returned"] is None  # generated: nothing to say yet
        review_sample(s, workspace["sample"], people["cy"], "reject", f"  {REASON} ")
    with transaction(runtime.sessions) as s:
        detail = frame_detail(s, frames[2], people["ana"])
        assert detail["state"] == "approved" and not detail["submitted"] and len(detail["regions"]) == 4  # the draft
        note = detail["returned"]
        assert (note["reason"], note["by"], note["annotator"], note["sample_id"]) == (REASON, "cy", "ana",
                                                                                      workspace["sample"])
        assert note["at"].endswith("Z")
        assert frame_detail(s, frames[0], people["ana"])["returned"] is None

        # bo's queue: fresh frames first, ana's returned frame only when nothing else waits
        got = [next_frame(s, people["bo"], 600)[0].id]
        assert got == [frames[0]]
        # ana's queue: her returned frame before the older fresh ones
        assert next_frame(s, people["ana"], 600)[0].id == frames[2]
    with transaction(runtime.sessions) as s:  # bo lets his frame go and works through the rest
        s.execute(update(Annotation).values(lease_user_id=None, lease_expires_at=None))
        s.execute(update(Frame).where(Frame.id.in_([frames[0], frames[1], frames[3]])).values(state=FrameState.deleted))
        assert next_frame(s, people["bo"], 600)[0].id == frames[2]  # nothing else waits: he may take it


def test_a_resubmitted_frame_is_no_longer_returned(runtime: Runtime, workspace: dict[str, Any]) -> None:
    people, frames = workspace["people"], workspace["frames"]
    with transaction(runtime.sessions) as s:
        review_sample(s, workspace["sample"], people["cy"], "reject", REASON)
    with transaction(runtime.sessions) as s:
        ann = s.scalar(select(Annotation).where(Annotation.frame_id == frames[2]))
        regions = frame_detail(s, frames[2], people["ana"])["regions"]
        draft = save_annotation(s, frames[2], people["ana"], version=ann.version, regions=regions,
                                illusion_type=None, submit=False)
        assert frame_detail(s, frames[2], people["ana"])["returned"]["reason"] == REASON  # drafts keep the note
        save_annotation(s, frames[2], people["ana"], version=draft.version, regions=regions, illusion_type=None,
                        submit=True)  # each pair kept its type: no frame-wide type needed
        assert frame_detail(s, frames[2], people["ana"])["returned"] is None
        assert next_frame(s, people["ana"], 600)[0].id == frames[3]  # on along the video, as usual
