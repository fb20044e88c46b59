"""The states and kinds the database stores, as plain string enums.

Pure (no SQLAlchemy): readers of dataset folders and the trainer check values against them without
loading the database layer; ``dataset.tables`` maps them to columns and is where the rest of the
code imports them from.
"""

from __future__ import annotations

import enum


class Role(enum.StrEnum):
    """Roles are ordered: each one may do everything the ones before it may."""

    annotator = "annotator"
    curator = "curator"
    admin = "admin"

    @property
    def rank(self) -> int:
        return list(Role).index(self)

    def allows(self, required: Role) -> bool:
        return self.rank >= required.rank


class SourceKind(enum.StrEnum):
    web = "web"
    generated = "generated"
    real_capture = "real_capture"


class IllusionType(enum.StrEnum):
    inpainting = "inpainting"
    picture = "picture"
    replay = "replay"
    holography = "holography"
    mirror = "mirror"


class FrameState(enum.StrEnum):
    """A frame's way through the pipeline (``rejected`` and ``deleted`` leave it)."""

    ingested = "ingested"
    prefiltered = "prefiltered"
    approved = "approved"
    rejected = "rejected"
    annotated = "annotated"
    generated = "generated"
    accepted = "accepted"
    deleted = "deleted"


class JobState(enum.StrEnum):
    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    interrupted = "interrupted"  # its worker died; retryable

    @property
    def finished(self) -> bool:
        return self in (JobState.succeeded, JobState.failed, JobState.interrupted)


class RegionKind(enum.StrEnum):
    illusion = "illusion"
    support = "support"


class ReviewDecision(enum.StrEnum):
    approve = "approve"
    reject = "reject"


class SampleState(enum.StrEnum):
    generated = "generated"
    accepted = "accepted"
    rejected = "rejected"


class RunState(enum.StrEnum):
    """A training run's state; ``diverged`` and ``cancelled`` are the run's own endings."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    diverged = "diverged"  # NaN/inf loss; the last good checkpoint stays
    cancelled = "cancelled"
    interrupted = "interrupted"  # its worker died; resume it

    @property
    def finished(self) -> bool:
        return self not in (RunState.queued, RunState.running)


class ProposalFate(enum.StrEnum):
    """What became of a proposal: still waiting, taken as it was, taken after the annotator's edits,
    or turned down (explicitly, or left untouched when the frame was submitted); ``hidden``: scored
    under its scan's threshold, so not shown unless asked, and left untouched."""

    pending = "pending"
    accepted = "accepted"
    edited = "edited"
    rejected = "rejected"
    hidden = "hidden"

