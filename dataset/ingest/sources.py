"""Where frames come from: a video file decoded with OpenCV, or a synthetic scene directory.

A source yields the frames chosen by the sampling rate, in order, each with its index in the
original stream and its time in seconds. Anything that cannot be decoded raises
:class:`IngestError` with a message a user can act on.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from dataset.media import sha256_file

VIDEO_EXTENSIONS = frozenset({".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv", ".flv"})
SCENE_FILE = "scene.json"
# A decode that stops short of this share of the frames the container announces is a broken file.
MIN_DECODED_SHARE = 0.9


class IngestError(ValueError):
    """A source that cannot be ingested; the message says why and what to do."""


@dataclass(frozen=True)
class SourceInfo:
    kind: str  # "video" or "synthetic"
    fps: float
    frame_count: int
    width: int
    height: int
    fingerprint: str  # SHA-256 of the source's bytes: the same file is the same video
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DecodedFrame:
    index: int  # position in the original stream
    time_s: float
    rgb: np.ndarray  # uint8 HxWx3
    png: bytes | None = None  # lossless bytes when the source already has them
    side_files: dict[str, Path] = field(default_factory=dict)  # ground truth that comes with the frame


class FrameSource(Protocol):
    info: SourceInfo

    def frames(self, fps: float | None) -> Iterator[DecodedFrame]: ...


_IMAGE_MAGIC = ((b"\x89PNG\r\n\x1a\n", "PNG"), (b"\xff\xd8\xff", "JPEG"), (b"GIF8", "GIF"), (b"BM", "BMP"),
                (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"))


def image_kind(head: bytes) -> str | None:
    """The still-image format whose signature starts ``head`` (PNG, JPEG …), or None.

    A still image named like a video would decode as a one-frame "video"; uploads refuse it.
    """
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "WebP"
    return next((kind for magic, kind in _IMAGE_MAGIC if head.startswith(magic)), None)


def sampled(index: int, native_fps: float, fps: float | None) -> bool:
    """Whether frame ``index`` of a ``native_fps`` stream is kept when sampling at ``fps``.

    Keeps the first frame of every 1/fps interval, so 30 fps sampled at 2 fps keeps 0, 15, 30, …
    """
    if fps is None or fps >= native_fps:
        return True
    return index == 0 or math.floor(index * fps / native_fps) > math.floor((index - 1) * fps / native_fps)


class VideoFileSource:
    """A video file decoded with OpenCV."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if not path.is_file():
            raise IngestError(f"{path}: no such file")
        if path.stat().st_size == 0:
            raise IngestError(f"{path}: the file is empty")
        cap = cv2.VideoCapture(str(path))
        try:
            ok, first = cap.read() if cap.isOpened() else (False, None)
            if not ok or first is None:
                raise IngestError(f"{path}: not a video OpenCV can decode (unknown format, or the file is broken)")
            fps = cap.get(cv2.CAP_PROP_FPS)
            count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        finally:
            cap.release()
        if not fps or not math.isfinite(fps) or fps <= 0:
            raise IngestError(f"{path}: the video reports no frame rate; re-encode it (e.g. ffmpeg -i IN -c:v libx264 OUT.mp4)")
        height, width = first.shape[:2]
        self.info = SourceInfo("video", float(fps), max(count, 0), width, height, sha256_file(path))

    def frames(self, fps: float | None) -> Iterator[DecodedFrame]:
        cap = cv2.VideoCapture(str(self.path))
        decoded = 0
        try:
            while cap.grab():
                index = decoded
                decoded += 1
                if not sampled(index, self.info.fps, fps):
                    continue
                ok, bgr = cap.retrieve()
                if not ok:
                    raise IngestError(f"{self.path}: frame {index} cannot be decoded; the file is corrupt")
                yield DecodedFrame(index, index / self.info.fps, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        finally:
            cap.release()
        expected = self.info.frame_count
        if expected and decoded < MIN_DECODED_SHARE * expected:
            raise IngestError(f"{self.path}: truncated or corrupt: decoded {decoded} of the {expected} frames it announces")


class SyntheticSceneSource:
    """A directory written by ``dataset.synthetic.write_video``: lossless frames plus ground truth."""

    SIDE_FILES = ("right.png", "disparity.npy", "mono_disparity.npy", "stereo_disparity.npy")

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.scene = json.loads((path / SCENE_FILE).read_text())
            frames = self.scene["frames"]
            digest = hashlib.sha256((path / SCENE_FILE).read_bytes())
            digest.update(sha256_file(path / "video.mp4").encode())
        except (OSError, ValueError, KeyError) as exc:
            raise IngestError(f"{path}: not a readable synthetic scene ({exc})") from None
        if not frames:
            raise IngestError(f"{path}: the scene has no frames")
        self.info = SourceInfo(
            "synthetic", float(self.scene["fps"]), len(frames), int(self.scene["width"]), int(self.scene["height"]),
            digest.hexdigest(),
            meta={"synthetic": True, "seed": self.scene.get("seed"), "pairs": self.scene.get("pairs", []),
                  "intrinsics": self.scene.get("intrinsics"), "baseline_m": self.scene.get("baseline_m")},
        )

    def frames(self, fps: float | None) -> Iterator[DecodedFrame]:
        for frame in self.scene["frames"]:
            index = int(frame["index"])
            if not sampled(index, self.info.fps, fps):
                continue
            frame_dir = self.path / "frames" / f"{index:06d}"
            png = (frame_dir / "left.png").read_bytes()
            bgr = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
            if bgr is None:
                raise IngestError(f"{frame_dir / 'left.png'}: not a readable PNG")
            side = {name.split(".")[0]: frame_dir / name for name in self.SIDE_FILES}
            side.update({p.stem: p for p in sorted(frame_dir.glob("*_[0-9][0-9].png"))})
            yield DecodedFrame(index, float(frame["time_s"]), cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), png, side)


def open_source(path: Path) -> FrameSource:
    """The right source for ``path`` (a synthetic scene directory or a video file)."""
    path = Path(path)
    if path.is_dir():
        if (path / SCENE_FILE).is_file():
            return SyntheticSceneSource(path)
        raise IngestError(f"{path}: a directory that is not a synthetic scene (no {SCENE_FILE})")
    return VideoFileSource(path)


def find_sources(paths: list[Path]) -> list[Path]:
    """Expand folders into the video files and synthetic scenes inside them (sorted, no repeats)."""
    found: list[Path] = []
    for path in map(Path, paths):
        if not path.exists():
            raise IngestError(f"{path}: no such file or directory")
        if path.is_file() or (path / SCENE_FILE).is_file():
            found.append(path)
            continue
        scenes = sorted(p.parent for p in path.rglob(SCENE_FILE))
        videos = sorted(p for p in path.rglob("*") if p.suffix.lower() in VIDEO_EXTENSIONS
                        and not any(p.is_relative_to(s) for s in scenes))
        found += scenes + videos
    return list(dict.fromkeys(p.resolve() for p in found))
