"""Exports made on the Export page: each one a folder ``<home>/exports/<id>`` that an ``export`` job
writes, listed with who asked for it and when, offered as one zip streamed from that folder, and
deleted by a curator or once it is older than ``export_retention_days``.

The page names an export by its id only; the folder is the app's own (``dataset/contained.py``: no
symbolic link below ``exports/``), never a path a request names.
"""

from __future__ import annotations

import io
import os
import shutil
import zipfile
from collections.abc import Iterator, Sequence
from datetime import timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from core.wording import plural
from dataset.contained import owned_folder
from dataset.export import FORMATS, LayoutError, export_params, parse_split_spec
from dataset.export.authors_layout import MASK_FORMATS
from dataset.export.selection import parse_states
from dataset.export.splits import DEFAULT_SPLIT
from dataset.redact import redacted
from dataset.services import audit
from dataset.services.errors import Conflict, FieldError, NotFound
from dataset.settings import Settings
from dataset.tables import Export, Frame, Job, JobState, Sample, SampleState, User, Video, utcnow

# Files that are compressed already: stored as they are, the rest deflated.
PACKED_SUFFIXES = frozenset({".png", ".jpg", ".jpeg"})
CHUNK_BYTES = 1 << 20
LIVE = (JobState.queued, JobState.running)


def export_folder(settings: Settings, export_id: int, *, whole: bool = False) -> Path:
    """``<home>/exports/<id>`` (LinkedFolder, a 404, when it or, with ``whole``, anything below it is a link)."""
    return owned_folder(settings.exports_dir, str(export_id), whole=whole)


def check_selection(session: Session, states: Sequence[str], video_ids: Sequence[int]) -> None:
    """Refuse, before any job is made, videos that do not exist and a selection without samples
    (FieldError naming ``video_ids``, or no field when the states and videos hold nothing)."""
    known = set(session.scalars(select(Video.id).where(Video.id.in_(list(video_ids))))) if video_ids else set()
    if missing := sorted(set(video_ids) - known):
        raise FieldError("video_ids", f"no video {', '.join(map(str, missing))}")
    count = select(func.count(Sample.id)).join(Frame, Frame.id == Sample.frame_id).where(
        Sample.state.in_([SampleState(s) for s in states]))
    if video_ids:
        count = count.where(Frame.video_id.in_(list(video_ids)))
    if not session.scalar(count):
        scope = f" in {plural(len(video_ids), 'video')} {', '.join(map(str, sorted(video_ids)))}" if video_ids else ""
        raise FieldError("", f"no samples to export: none is {' or '.join(states)}{scope}")


def create_export(session: Session, settings: Settings, user: User | None, *, format: str, split: str = DEFAULT_SPLIT,
                  seed: int = 0, states: Sequence[str] = ("accepted",), video_ids: Sequence[int] = (),
                  mask_format: str = "png") -> tuple[Export, dict[str, Any]]:
    """The export's row (flushed: it has its id) and its ``export`` job's parameters, every option
    checked first: a FieldError names the form's field. The caller queues the job and sets ``job_id``."""
    if format not in FORMATS:
        raise FieldError("format", f"choose {' or '.join(FORMATS)}")
    if mask_format not in MASK_FORMATS:
        raise FieldError("mask_format", f"choose {' or '.join(MASK_FORMATS)}")
    try:
        spec = parse_split_spec(split)
    except LayoutError as exc:
        raise FieldError("split", str(exc)) from None
    if format == "authors" and spec != parse_split_spec(DEFAULT_SPLIT):
        raise FieldError("split", "the authors' layout has no splits (captures go to testing/, the rest to "
                                  "training): leave it empty or choose the native format")
    try:
        states = parse_states(states)
    except LayoutError as exc:
        raise FieldError("states", str(exc)) from None
    check_selection(session, states, video_ids)
    export = Export(options={}, created_by_id=user.id if user else None)
    session.add(export)
    session.flush()
    folder = export_folder(settings, export.id)
    # A folder no row owns: left by a deleted export of the same id (SQLite reuses the largest id).
    shutil.rmtree(folder, ignore_errors=True)
    params = export_params(folder, format=format, split=split, seed=seed, states=states, video_ids=video_ids,
                           mask_format=mask_format)
    export.options = {k: params[k] for k in ("format", "split", "seed", "states", "video_ids", "mask_format")}
    if user is not None:
        audit.record(session, user.id, "export.create", "export", export.id, **export.options)
    return export, params


def list_exports(session: Session) -> list[Export]:
    """Every export, newest first."""
    return list(session.scalars(select(Export).order_by(Export.id.desc())))


def get_export(session: Session, export_id: int) -> Export:
    export = session.get(Export, export_id)
    if export is None:
        raise NotFound(f"no export {export_id}")
    return export


def export_state(export: Export) -> str:
    """The export's job's state; ``failed`` when its job row is gone."""
    return export.job.state.value if export.job is not None else JobState.failed.value


def export_json(export: Export) -> dict[str, Any]:
    """What the page says of an export: by id, never by its folder."""
    job = export.job
    result = (job.result or {}) if job is not None else {}
    return {
        "id": export.id, "job": export.job_id, "state": export_state(export),
        "progress": job.progress if job is not None else 0.0,
        "error": redacted(job.error) if job is not None else "its job is gone",
        "samples": result.get("samples"), **export.options,
        "created_by": export.created_by.name if export.created_by else None,
        "created_at": export.created_at.isoformat() + "Z",
    }


def delete_export(session: Session, settings: Settings, export_id: int, user: User | None) -> None:
    """Remove the export's folder, then its row (a queued or running one is refused: its job still writes)."""
    export = get_export(session, export_id)
    if export.job is not None and export.job.state in LIVE:
        raise Conflict(f"export {export_id} is still {export.job.state.value}; delete it once its job has ended")
    shutil.rmtree(export_folder(settings, export_id), ignore_errors=True)
    session.delete(export)
    if user is not None:
        audit.record(session, user.id, "export.delete", "export", export_id)


def delete_expired(session: Session, settings: Settings) -> list[int]:
    """Delete the exports asked for more than ``export_retention_days`` ago whose job has ended; their ids."""
    if settings.export_retention_days <= 0:
        return []
    cutoff = utcnow() - timedelta(days=settings.export_retention_days)
    expired = session.scalars(select(Export).outerjoin(Job, Job.id == Export.job_id).where(
        Export.created_at < cutoff, (Job.id.is_(None)) | Job.state.not_in(LIVE))).all()
    for export in expired:
        delete_export(session, settings, export.id, None)
    return [export.id for export in expired]


def zip_name(export: Export) -> str:
    return f"export-{export.id}-{export.options.get('format', 'native')}"


def export_files(export: Export, settings: Settings) -> tuple[Path, list[tuple[Path, str]]]:
    """The finished export's folder and its files as (path, name inside it), sorted; NotFound when the
    export has not succeeded or its folder is gone, LinkedFolder when anything in it is a link."""
    if export_state(export) != JobState.succeeded.value:
        raise NotFound(f"export {export.id} is {export_state(export)}: there is nothing to download")
    folder = export_folder(settings, export.id, whole=True)
    if not folder.is_dir():
        raise NotFound(f"export {export.id}'s files are gone")
    files = []
    for parent, dirs, names in os.walk(folder):
        dirs.sort()
        for name in sorted(names):
            path = Path(parent, name)
            files.append((path, path.relative_to(folder).as_posix()))
    return folder, files


class _Pieces(io.RawIOBase):
    """A write-only file whose bytes are taken out as they come: zipfile writes the archive into it
    (with data descriptors, since it cannot seek) and the response sends each piece on."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        self._parts.append(bytes(data))
        return len(data)

    def take(self) -> bytes:
        out = b"".join(self._parts)
        self._parts.clear()
        return out


def zip_stream(files: Sequence[tuple[Path, str]], top: str) -> Iterator[bytes]:
    """A zip of ``files`` (path, name) under the folder ``top``, made while it is sent: at most one
    chunk of a file is held, nothing is written to disk."""
    sink = _Pieces()
    with zipfile.ZipFile(sink, "w") as archive:
        for path, name in files:
            info = zipfile.ZipInfo.from_file(path, f"{top}/{name}")  # its size: zip64 when it needs it
            info.compress_type = zipfile.ZIP_STORED if path.suffix.lower() in PACKED_SUFFIXES else zipfile.ZIP_DEFLATED
            with path.open("rb") as source, archive.open(info, "w") as target:
                while block := source.read(CHUNK_BYTES):
                    target.write(block)
                    yield sink.take()
            yield sink.take()
    yield sink.take()
