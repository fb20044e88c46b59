"""What runs after what on a frame's way: the jobs each step queues, with their parameters typed.

- a frame **leased** to an annotator: it and the next approved frames of its video get their image
  embeddings (``encode``) and their proposals (``propose``), so that clicks and proposals never wait;
- frames **approved** by a curator enter the annotation queue: their proposals are computed ahead;
- an annotation **submitted** (or a sample to make again): its sample is generated (``generate``).

Views, the CLI's demo and the benchmarks call these rather than queueing the kinds themselves, so the
order of the pipeline is written once. ``submit`` is the runtime's ``submit(session, kind, params, user)``:
each job's row commits with the caller's session.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from typing import Any

from sqlalchemy.orm import Session

from dataset.services import leases, proposals, segmentation
from dataset.services.errors import Unavailable
from dataset.settings import Settings
from dataset.tables import Frame, Job, User

Submit = Callable[[Session, str, dict[str, Any], User | None], Job]


@dataclass(frozen=True)
class GenerateParams:
    """A ``generate`` job: the sample of ``frame_id``'s annotation at ``annotation_version`` (None: the
    version the frame holds when the job runs)."""

    frame_id: int
    annotation_version: int | None = None

    def params(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v is not None}


@dataclass(frozen=True)
class FramesParams:
    """An ``encode`` or ``propose`` job: the frames it works on, in order."""

    frame_ids: list[int]

    def params(self) -> dict[str, Any]:
        return {"frame_ids": list(self.frame_ids)}


def submitted(session: Session, submit: Submit, job: GenerateParams, user: User | None) -> Job:
    """An annotation submitted, or a sample to make again: one generate job."""
    return submit(session, "generate", job.params(), user)


def approved(session: Session, submit: Submit, settings: Settings, frame_ids: Iterable[int],
             user: User | None) -> list[Job]:
    """Frames entering the annotation queue: propose jobs (in chunks) for those the configured proposers
    have not looked at. A queue that is down costs nothing here (approving, taking or keeping a frame
    goes on): the next lease renewal queues them again."""
    todo = proposals.frames_to_scan(session, settings, list(frame_ids))
    queued: list[Job] = []
    with contextlib.suppress(Unavailable):
        for chunk in proposals.propose_chunks(todo):
            queued.append(submit(session, "propose", FramesParams(chunk).params(), user))
    return queued


def leased(session: Session, submit: Submit, settings: Settings, frame: Frame, user: User | None) -> list[Job]:
    """A frame leased (or its lease kept): it and the next approved frames of its video get an encode job
    for those without embeddings, and their proposals (:func:`approved`)."""
    ids = leases.prefetch_ids(session, frame)
    missing = segmentation.frames_to_encode(session, settings, ids)
    queued = [submit(session, "encode", FramesParams(missing).params(), user)] if missing else []
    return queued + approved(session, submit, settings, ids, user)
