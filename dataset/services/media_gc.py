"""Media garbage collection: mark every key the database references, sweep the other files.

Keys are found anywhere in the referencing columns, nested JSON included (a sample's masks, a
frame's assets, a job's upload path), so a new kind of side file needs no change here; a new
table that references media adds its columns to :data:`REFERENCE_COLUMNS`. A job's parameters
keep their files only while it may still run (:data:`LIVE_JOB_PARAMS`): a refused upload (a file
ingest could not read) would otherwise stay for as long as its failed job's row.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import InstrumentedAttribute, Session

from dataset.media import MediaStore
from dataset.tables import Frame, Job, JobState, Sample, TrainingRun, Video

# Every column that may hold media keys or media paths; a training run's pinned dataset version
# keeps its files while the run exists (regenerating a sample cannot pull them away).
REFERENCE_COLUMNS: tuple[InstrumentedAttribute[Any], ...] = (
    Frame.media_key, Frame.assets,
    Video.original_path, Video.meta,
    Sample.files,
    Job.result,
    TrainingRun.dataset,
)
# Queued, running, or interrupted (its worker died; a retry resumes it). A finished ingest's video
# references its upload itself (Video.original_path); a failed one's upload goes after the grace.
LIVE_JOB_PARAMS = select(Job.params).where(Job.state.in_((JobState.queued, JobState.running, JobState.interrupted)))
INCOMING = ".incoming"


@dataclass
class GcReport:
    kept: int = 0
    removed: list[str] = field(default_factory=list)
    removed_bytes: int = 0
    too_young: int = 0

    def json(self) -> dict[str, Any]:
        return {"kept": self.kept, "removed": len(self.removed), "removed_bytes": self.removed_bytes,
                "too_young": self.too_young}


def _strings(value: Any) -> Iterator[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)
    elif isinstance(value, list | tuple):
        for v in value:
            yield from _strings(v)


def referenced_keys(session: Session, media: MediaStore) -> set[str]:
    """Every media key the database references (keys, or absolute paths inside the store)."""
    root = str(media.root) + "/"
    keys = set()
    for query in (*(select(column) for column in REFERENCE_COLUMNS), LIVE_JOB_PARAMS):
        for value in session.scalars(query):
            for text in _strings(value):
                keys.add(text[len(root):] if text.startswith(root) else text)
    return keys


def protect_after(session: Session, grace: timedelta) -> datetime:
    """Files modified after this (UTC) stay: younger than the grace, or than a running or queued job."""
    cutoff = datetime.now(UTC).replace(tzinfo=None) - grace
    busy = session.scalar(select(func.min(func.coalesce(Job.started_at, Job.created_at)))
                          .where(Job.state.in_((JobState.running, JobState.queued))))
    return min(cutoff, busy) if busy is not None else cutoff


def collect(session: Session, media: MediaStore, *, grace: timedelta, dry_run: bool) -> GcReport:
    """Remove (or, with ``dry_run``, list) the store's files that nothing references."""
    keep = referenced_keys(session, media)
    young = protect_after(session, grace).replace(tzinfo=UTC).timestamp()
    report = GcReport()
    for path in sorted(media.root.rglob("*")):
        rel = path.relative_to(media.root).as_posix()
        if rel.startswith(INCOMING + "/") or not path.is_file() or not media.is_key(rel):
            continue
        if rel in keep:
            report.kept += 1
            continue
        stat = path.stat()
        if stat.st_mtime > young:
            report.too_young += 1
            continue
        report.removed.append(rel)
        report.removed_bytes += stat.st_size
        if not dry_run:
            path.unlink(missing_ok=True)
    return report


def clean_incoming(media: MediaStore, *, older_than_s: float) -> int:
    """Delete upload leftovers (``.incoming/*.part``) untouched for ``older_than_s``; returns how many.

    An upload in progress writes its part file continuously, so only a dead upload's part ages.
    """
    incoming: Path = media.root / INCOMING
    if not incoming.is_dir():
        return 0
    cutoff, removed = time.time() - older_than_s, 0
    for part in incoming.glob("*.part"):
        try:
            if part.stat().st_mtime < cutoff:
                part.unlink()
                removed += 1
        except FileNotFoundError:  # another process finished or cleaned it meanwhile
            continue
    return removed
