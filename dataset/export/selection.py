"""Which samples an export contains, read from the database into plain records.

One sample per frame: among the samples in the chosen states, the one made from the newest
annotation version (then the newest row). Videos get folder names that are stable across
workspaces: a slug of the video's name, with a content-hash suffix only where two selected videos
would share one. Copies of one video (a scene group) are split as the group's first video.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Sequence
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from core.wording import quoted
from dataset.export.errors import LayoutError
from dataset.export.records import SampleRecord, VideoInfo
from dataset.tables import Annotation, Frame, Sample, SampleState, Video

DEFAULT_STATES = ("accepted",)


def parse_states(states: Sequence[str]) -> list[str]:
    """Validated sample states (``generated``, ``accepted``, ``rejected``), deduplicated, sorted."""
    bad = [s for s in states if s not in SampleState.__members__]
    if bad or not states:
        raise LayoutError(f"unknown sample state {quoted(bad[0])}" if bad else "choose at least one sample state")
    return sorted(set(states))


def select_samples(session: Session, states: Sequence[str] = DEFAULT_STATES,
                   video_ids: Sequence[int] | None = None) -> list[SampleRecord]:
    """The samples to export, sorted by video folder and frame index.

    Streamed: rows come ordered so that each frame's chosen sample is its first, in chunks, and
    each becomes a plain record at once; only the records are held, never every ORM row.
    """
    chosen = Sample.state.in_([SampleState(s) for s in parse_states(states)])
    scope = [Video.id.in_(list(video_ids))] if video_ids else []
    videos = session.execute(select(Video.content_sha256, Video.name, Video.id, Video.scene_group).where(
        Video.id.in_(select(Frame.video_id).join(Sample, Sample.frame_id == Frame.id).where(chosen)), *scope)).all()
    dirs = video_dirs({sha: name for sha, name, *_ in videos})
    scenes = _scenes(session, videos, dirs)
    query = (select(Sample, Frame, Video, Annotation.illusion_type)
             .join(Frame, Frame.id == Sample.frame_id).join(Video, Video.id == Frame.video_id)
             .outerjoin(Annotation, Annotation.frame_id == Frame.id).where(chosen, *scope)
             # the newest annotation version first (no version: oldest), then the newest row
             .order_by(Sample.frame_id, Sample.annotation_version.desc().nulls_last(), Sample.id.desc())
             .execution_options(yield_per=1000))
    items, last_frame = [], None
    for sample, frame, video, illusion_type in session.execute(query):
        if sample.frame_id != last_frame:
            items.append(_item(dirs[video.content_sha256], scenes.get(video.id, ""), sample, frame, video, illusion_type))
            last_frame = sample.frame_id
    return sorted(items, key=lambda item: (item.video_dir, item.index))


def _scenes(session: Session, videos: Sequence[Any], dirs: dict[str, str]) -> dict[int, str]:
    """{video id: the folder its split is drawn from} for the videos in a scene group with others:
    the folder of the group's first video (its name's slug when that one is not exported)."""
    grouped = {row.id: row.scene_group for row in videos if row.scene_group is not None}
    firsts = {row.id: dirs.get(row.content_sha256) or slug(row.name) for row in session.execute(
        select(Video.id, Video.name, Video.content_sha256).where(Video.id.in_(set(grouped.values()))))}
    # a first video deleted since: the group still splits together, under its smallest member's folder
    fallback = {group: min(dirs[row.content_sha256] for row in videos if row.scene_group == group)
                for group in set(grouped.values()) - set(firsts)}
    return {video: firsts.get(group) or fallback[group] for video, group in grouped.items()}


def _item(video_dir: str, scene: str, sample: Sample, frame: Frame, video: Video, illusion_type: Any) -> SampleRecord:
    return SampleRecord(
        video_dir=video_dir, scene=scene,
        video=VideoInfo(name=video.name, source_kind=video.source_kind.value, illusion_types=list(video.illusion_types),
                        content_sha256=video.content_sha256, fps=video.fps, width=video.width, height=video.height,
                        meta=dict(video.meta)),
        index=frame.index, time_s=frame.time_s, width=frame.width, height=frame.height,
        frame_state=frame.state.value, state=sample.state.value, flagged=sample.flagged,
        annotation_version=sample.annotation_version,
        illusion_type=illusion_type.value if illusion_type is not None else None,
        files=dict(sample.files), params=dict(sample.params), provenance=dict(sample.provenance), qa=dict(sample.qa),
        created_at=sample.created_at,
    )


def slug(name: str) -> str:
    """A folder name for ``name``: ``[A-Za-z0-9._-]`` kept, runs of anything else become ``_``;
    never hidden, never ``.``/``..``, at most 80 characters."""
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._")[:80].strip("._")
    return cleaned or "video"


def video_dirs(names: dict[str, str]) -> dict[str, str]:
    """Folder names for videos given as {content_sha256: name}; unique, and the same for the same
    set of videos in any workspace (the hash suffix only disambiguates equal slugs)."""
    by_slug: dict[str, list[str]] = defaultdict(list)
    for sha, name in names.items():
        by_slug[slug(name)].append(sha)
    dirs = {sha: base if len(shas) == 1 else f"{base}-{sha[:12]}" for base, shas in by_slug.items() for sha in shas}
    if len(set(dirs.values())) != len(dirs):
        raise LayoutError("two videos map to the same export folder name; rename one of them")
    return dirs
