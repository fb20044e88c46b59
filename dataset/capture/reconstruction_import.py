"""The reconstruction import job: disparities and right views rendered from an external 3-D
reconstruction of a video (InstantSplat/DUSt3R, run elsewhere) become assets of its frames.

Folder layout::

    DIR/disparity/<stem>.pfm | .npy   float32 HxW disparity of the frame (left view) in pixels; NaN = none
    DIR/right/<stem>.png              the rendered right view, 8-bit colour (.png, .jpg, .jpeg), same HxW

Matching stems to the video's frames (``match``): ``index`` (default) — a stem ends with the
frame's index in the decoded video (``frame_000012`` → the frame with index 12; any stem may
be used, only its trailing number counts); ``order`` — the stems in natural order go to the
video's frames in index order, one each, and the counts must agree. Sizes must equal the frame's.

Each matched frame gets the assets ``reconstruction_disparity`` (PFM) and
``reconstruction_right`` (PNG), encoded as sample outputs are (:mod:`dataset.samples`). All
files are checked before any frame changes; a re-import of the same files changes nothing, a
new one replaces the assets and bumps the frame's revision.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from core.formats import FormatError, read_map, read_rgb
from core.wording import plural
from dataset.capture.errors import CaptureError
from dataset.capture.files import files_by_stem, matched_stems, names, trailing_number
from dataset.capture.layout import IMAGE_SUFFIXES
from dataset.db import transaction
from dataset.samples import store_outputs
from dataset.services.errors import NotFound
from dataset.services.jobs import JobContext
from dataset.tables import Frame, Video

RECONSTRUCTION_JOB = "import_reconstruction"
MATCH_MODES = ("index", "order")
Match = Literal["index", "order"]
DISPARITY_SUFFIXES = (".pfm", ".npy")
ASSET_DISPARITY = "reconstruction_disparity"
ASSET_RIGHT = "reconstruction_right"


@dataclass(frozen=True)
class ReconstructionFiles:
    """One frame's files and the frame they belong to (``frame_id``; ``size``: its (H, W))."""

    stem: str
    disparity: Path
    right: Path
    frame_id: int
    size: tuple[int, int]


def reconstruction_params(session: Session, video_id: int, path: str | Path, *, match: Match = "index",
                          user_id: int | None = None) -> dict[str, Any]:
    """Validated parameters of an ``import_reconstruction`` job: the video exists (else
    NotFound) and every file pair matches one of its frames (else :class:`CaptureError`)."""
    root = Path(path).resolve()
    match_files(session, video_id, root, match)
    return {"video_id": video_id, "path": str(root), "match": match, "user_id": user_id}


def match_files(session: Session, video_id: int, root: Path, match: Match) -> list[ReconstructionFiles]:
    """The folder's file pairs, each with the frame of video ``video_id`` it belongs to."""
    if match not in MATCH_MODES:
        raise CaptureError(f"unknown match mode {match!r}; choose one of {', '.join(MATCH_MODES)}")
    if session.get(Video, video_id) is None:
        raise NotFound(f"no video {video_id}")
    if not root.is_dir():
        raise CaptureError(f"{root}: reconstruction folder not found")
    groups = {"disparity": files_by_stem(root / "disparity", DISPARITY_SUFFIXES),
              "right": files_by_stem(root / "right", IMAGE_SUFFIXES)}
    stems = matched_stems(groups)
    frames = session.execute(select(Frame.index, Frame.id, Frame.height, Frame.width)
                             .where(Frame.video_id == video_id).order_by(Frame.index)).all()
    targets = _by_order(stems, frames, video_id) if match == "order" else _by_index(stems, frames, video_id)
    return [ReconstructionFiles(stem, groups["disparity"][stem], groups["right"][stem], frame.id,
                                (frame.height, frame.width)) for stem, frame in zip(stems, targets, strict=True)]


def import_reconstruction_job(ctx: JobContext) -> dict[str, Any]:
    """Job handler for kind ``import_reconstruction`` (params from :func:`reconstruction_params`)."""
    p = ctx.params
    with ctx.sessions() as s:
        items = match_files(s, p["video_id"], Path(p["path"]), p["match"])
    ctx.log(f"video {p['video_id']}: {len(items)} reconstructed frames in {p['path']} (matched by {p['match']})")
    assets: dict[int, dict[str, str]] = {}
    for done, item in enumerate(items, start=1):
        keys = store_outputs(ctx.media, {"disparity": _read_disparity(item), "right": _read_right(item)})
        assets[item.frame_id] = {ASSET_DISPARITY: keys["disparity"], ASSET_RIGHT: keys["right"]}
        ctx.progress(done / len(items), f"{item.stem} → frame {item.frame_id}")
    # Every file was read and checked above: the frames change together, or not at all.
    updated = 0
    with transaction(ctx.sessions) as s:
        for frame_id, new in assets.items():
            frame = s.get(Frame, frame_id)
            if any(frame.assets.get(k) != v for k, v in new.items()):
                frame.assets = {**frame.assets, **new}
                frame.revision += 1
                updated += 1
    ctx.log(f"{plural(updated, 'frame')} updated, {len(items) - updated} already had these files")
    return {"video_id": p["video_id"], "frames": len(items), "updated": updated, "unchanged": len(items) - updated}


def _by_index(stems: list[str], frames: list[Any], video_id: int) -> list[Any]:
    by_index = {f.index: f for f in frames}
    numbers = {stem: trailing_number(stem) for stem in stems}
    unnumbered = [stem for stem, n in numbers.items() if n is None]
    if unnumbered:
        raise CaptureError(f"file names must end with a frame index (e.g. frame_000012), or use --match order: "
                           f"{names(unnumbered)}")
    unknown = [stem for stem, n in numbers.items() if n not in by_index]
    if unknown:
        raise CaptureError(f"video {video_id} has no frame with the index of {names(unknown)}")
    seen: dict[int, str] = {}
    for stem, n in numbers.items():
        if n in seen:
            raise CaptureError(f"{seen[n]} and {stem} both name frame index {n}")
        seen[n] = stem
    return [by_index[numbers[stem]] for stem in stems]


def _by_order(stems: list[str], frames: list[Any], video_id: int) -> list[Any]:
    if len(stems) != len(frames):
        raise CaptureError(f"matching by order needs one file pair per frame: {plural(len(stems), 'pair')}, "
                           f"video {video_id} has {plural(len(frames), 'frame')}")
    return list(frames)


def _read_disparity(item: ReconstructionFiles) -> np.ndarray:
    """float32 HxW pixels, the frame's size, with at least one finite value."""
    try:
        disparity = read_map(item.disparity).astype(np.float32, copy=False)
    except FormatError as exc:
        raise CaptureError(str(exc)) from None
    _check_size(item.disparity, disparity.shape, item)
    if not np.isfinite(disparity).any():
        raise CaptureError(f"{item.disparity}: no finite disparity value")
    return disparity


def _read_right(item: ReconstructionFiles) -> np.ndarray:
    try:
        right = read_rgb(item.right)
    except FormatError as exc:
        raise CaptureError(str(exc)) from None
    _check_size(item.right, right.shape[:2], item)
    return right


def _check_size(path: Path, got: tuple[int, ...], item: ReconstructionFiles) -> None:
    if tuple(got) != item.size:
        raise CaptureError(f"{path}: {got[1]}x{got[0]} px (WxH), frame {item.frame_id} is {item.size[1]}x{item.size[0]}")
