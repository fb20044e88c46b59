"""Import's database side: a :class:`SampleRecord` whose files are in the media store becomes rows.

Idempotent by content: a video is found by its ``content_sha256``, a frame by (video, index), and a
sample by its files (media keys are content hashes), so importing a dataset again adds nothing,
and an import that stopped half way picks up where it stopped. Existing rows are never changed.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Literal

from sqlalchemy import select
from sqlalchemy.orm import Session

from core.formats import mask_to_rle
from dataset.export.coco import pair_type, parse_mask_name
from dataset.export.records import SampleRecord
from dataset.media import MediaStore
from dataset.samples import load_output
from dataset.tables import (
    Annotation,
    Frame,
    FrameState,
    IllusionType,
    Region,
    RegionKind,
    Sample,
    SampleState,
    SourceKind,
    Video,
)

Outcome = Literal["added", "present", "conflict"]


def add_sample(session: Session, media: MediaStore, record: SampleRecord) -> Outcome:
    """Add ``record``'s video, frame, annotation and sample where missing.

    ``present``: the frame already has a sample with these files; ``conflict``: it has a different
    sample for the same annotation version (kept; the record is skipped).
    """
    video = _video(session, record)
    frame = _frame(session, video.id, record)
    samples = session.scalars(select(Sample).where(Sample.frame_id == frame.id)).all()
    if any(s.files == record.files for s in samples):
        return "present"
    if record.annotation_version is not None and any(s.annotation_version == record.annotation_version
                                                     for s in samples):
        return "conflict"
    # Only a sample made from an annotation brings one: curators review a sample against its version.
    if (record.annotation_version is not None and record.files.get("masks")
            and session.scalar(select(Annotation.id).where(Annotation.frame_id == frame.id)) is None):
        session.add(_annotation(media, frame.id, record))
    sample = Sample(frame_id=frame.id, annotation_version=record.annotation_version, state=SampleState(record.state),
                    flagged=record.flagged, files=record.files, params=record.params, provenance=record.provenance,
                    qa=record.qa)
    if record.created_at is not None:
        sample.created_at = record.created_at
    session.add(sample)
    session.flush()
    return "added"


def _video(session: Session, record: SampleRecord) -> Video:
    info = record.video
    video = session.scalar(select(Video).where(Video.content_sha256 == info.content_sha256))
    if video is None:
        video = Video(name=info.name, source_kind=SourceKind(info.source_kind), illusion_types=info.illusion_types,
                      content_sha256=info.content_sha256, fps=info.fps, width=info.width, height=info.height,
                      meta=info.meta)
        session.add(video)
        session.flush()
    return video


def _frame(session: Session, video_id: int, record: SampleRecord) -> Frame:
    frame = session.scalar(select(Frame).where(Frame.video_id == video_id, Frame.index == record.index))
    if frame is None:
        left = record.files["left"]
        frame = Frame(video_id=video_id, index=record.index, time_s=record.time_s, width=record.width,
                      height=record.height, content_sha256=PurePosixPath(left).stem, media_key=left,
                      state=FrameState(record.frame_state))
        session.add(frame)
        session.flush()
    return frame


def _annotation(media: MediaStore, frame_id: int, record: SampleRecord) -> Annotation:
    """A submitted annotation whose regions are the sample's masks (clicks are not part of a dataset)."""
    regions = []
    for name, key in sorted(record.files["masks"].items()):
        kind, pair = parse_mask_name(name)
        typed = pair_type(record, pair)
        regions.append(Region(pair=pair, kind=RegionKind(kind), mask_rle=mask_to_rle(load_output(media, key, "mask")),
                              illusion_type=IllusionType(typed) if typed else None))
    return Annotation(frame_id=frame_id, version=record.annotation_version, submitted=True, regions=regions,
                      illusion_type=IllusionType(record.illusion_type) if record.illusion_type else None)
