"""Scene groups: a video that copies earlier ones (by its frames' dHashes) joins their group, so
every split — a training run's, an export's — keeps the copies on one side.

``Video.scene_group`` holds the id of the group's first video; None is a group of its own.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from sqlalchemy import or_, select, update
from sqlalchemy.orm import Session

from dataset.ingest.copies import find_copies
from dataset.tables import Frame, Video

_BATCH = 5000  # frame rows streamed at a time


def group_of(video: Any) -> int:
    """The scene group of a video (a row with ``id`` and ``scene_group``)."""
    return video.scene_group if video.scene_group is not None else video.id


def join_scene_group(session: Session, video_id: int, hashes: Sequence[int]) -> dict[str, Any] | None:
    """Put video ``video_id`` (its kept frames' 64-bit dHashes ``hashes``) in the scene group of the
    finished videos it copies, merging their groups when it copies several (the oldest group
    stays). Returns the best match — ``video_id``, ``video_name``, ``matched`` frames of
    ``frames``, ``scene_group`` — or None when it copies nothing. Runs in the caller's transaction."""
    videos = {row.id: row for row in session.execute(select(Video.id, Video.name, Video.scene_group, Video.meta))
              if row.id != video_id and _finished(row.meta)}
    matches = find_copies(hashes, _frame_hashes(session, videos))
    if not matches:
        return None
    groups = sorted({group_of(videos[m.video_id]) for m in matches})
    group = groups[0]
    session.execute(update(Video).where(or_(Video.id.in_(groups), Video.scene_group.in_(groups), Video.id == video_id))
                    .values(scene_group=group).execution_options(synchronize_session=False))
    best = matches[0]
    return {"video_id": best.video_id, "video_name": videos[best.video_id].name, "matched": best.matched,
            "frames": best.frames, "scene_group": group}


def _finished(meta: dict[str, Any]) -> bool:
    """Not mid-ingest or mid-import: a video that may yet fail and vanish is nobody's group."""
    return "running" not in (meta.get("ingest"), meta.get("capture"))


def _frame_hashes(session: Session, videos: dict[int, Any]) -> Iterator[tuple[int, int]]:
    """(video id, dHash) of every frame of ``videos`` that has one, read off the frames' assets."""
    query = select(Frame.video_id, Frame.assets["dhash"].as_string()).execution_options(yield_per=_BATCH)
    for video, text in session.execute(query):
        if text and video in videos:
            yield video, int(text, 16)
