"""Plain records of samples as exports describe them: what export writes and import reads back.

No workspace ids or local paths appear here, so a record means the same in every workspace.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from dataset.media import MediaStore


@dataclass(frozen=True)
class VideoInfo:
    """A video: its name, kind and ``content_sha256`` (the key that makes import idempotent)."""

    name: str
    source_kind: str
    illusion_types: list[str]
    content_sha256: str
    fps: float | None
    width: int | None
    height: int | None
    meta: dict[str, Any]


@dataclass(frozen=True)
class SampleRecord:
    """One sample with its frame and video; ``files`` holds media keys as in ``Sample.files``.

    ``video_dir`` is the video's folder in a native export ("" where a format has none);
    ``scene`` what its split is drawn from: the folder of its scene group's first video (copies of
    one scene share it), "" for ``video_dir``; ``created_at`` None means "now" on import.
    """

    video: VideoInfo
    index: int
    time_s: float
    width: int
    height: int
    frame_state: str
    state: str
    flagged: bool
    annotation_version: int | None
    illusion_type: str | None
    files: dict[str, Any]
    params: dict[str, Any]
    provenance: dict[str, Any]
    qa: dict[str, Any]
    created_at: datetime | None = None
    video_dir: str = ""
    scene: str = ""

    @property
    def name(self) -> str:
        """``<video_dir>/<index:06d>``: the sample's id in a native export."""
        return f"{self.video_dir}/{self.index:06d}"


@dataclass(frozen=True)
class PendingSample:
    """A validated sample of a dataset folder; ``store`` puts its files into the media store."""

    name: str
    store: Callable[[MediaStore], SampleRecord]


Progress = Callable[[int, int, str], None]
"""``progress(done, total, what)``: called after each sample of an export or import."""
