"""The ingest job: a video file or synthetic scene becomes a Video row and sampled, de-duplicated frames.

Idempotent and resumable: a video is keyed by its content hash and frames by (video, index), so
a re-ingest of a finished video is a no-op and a retry after a crash picks up where it stopped,
making the same sampling and de-duplication decisions. A source that turns out to be broken
removes the partial video again, so a failed ingest leaves nothing behind in the database. A video
whose frames copy an earlier one's (re-encoded, resized, renamed) joins its scene group
(:mod:`dataset.services.scene_groups`), and the job's result and log say so.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sqlalchemy import delete, func, select

from core.formats import FormatError, read_map
from core.wording import plural, quoted
from dataset.capture.files import trailing_number
from dataset.db import transaction
from dataset.ingest import DecodedFrame, IngestError, dhash, hamming, open_source
from dataset.samples import store_outputs
from dataset.services.errors import InvalidInput
from dataset.services.jobs import JobContext
from dataset.services.prefilter import launch_prefilter
from dataset.services.scene_groups import join_scene_group
from dataset.tables import Frame, IllusionType, SourceKind, Video
from dataset.thumbnails import put_thumbnail

DEFAULT_FPS = 2.0  # the paper's sampling rate
DEFAULT_DEDUP_HAMMING = 4
MONO_SUFFIXES = (".pfm", ".npy")
MISSING_SHOWN = 100  # frames without a disparity that a job's result names (its log says how many)
# The frame asset the precomputed depth backend reads (dataset.services.generate.mono_disparity).
MONO_ASSET = "precomputed_disparity"


def ingest_params(path: str, *, fps: float | None = DEFAULT_FPS, source: str | None = None,
                  illusion_types: list[str] | None = None, dedup_hamming: int | None = DEFAULT_DEDUP_HAMMING,
                  user_id: int | None = None, original_name: str | None = None,
                  prefilter: bool = False, mono_dir: str | None = None,
                  mono_files: list[tuple[int, str, str]] | None = None) -> dict[str, Any]:
    """Validated parameters of an ingest job (raises InvalidInput with a one-line reason).

    ``mono_dir``: a folder of the video's per-frame monocular disparities (``.pfm`` or ``.npy``, float
    HxW, larger = nearer; a file's stem ends with its frame's index in the decoded video, as in
    ``frame_000012.npy``), stored with the frames as the ``precomputed`` depth backend reads them.
    ``mono_files``: the same maps uploaded, as (frame index, stored path, name as uploaded)."""
    if fps is not None and not 0 < fps <= 240:
        raise InvalidInput("fps must be in (0, 240]")
    if source is not None and source not in SourceKind.__members__:
        raise InvalidInput(f"unknown source {quoted(source)}; choose one of {', '.join(SourceKind)}")
    bad = [t for t in illusion_types or [] if t not in IllusionType.__members__]
    if bad:
        raise InvalidInput(f"unknown illusion type {quoted(bad[0])}; choose from {', '.join(IllusionType)}")
    if dedup_hamming is not None and not 0 <= dedup_hamming <= 64:
        raise InvalidInput("dedup_hamming must be 0..64 bits (or None: keep near-duplicates)")
    if mono_dir is not None:
        mono_maps(Path(mono_dir))  # refused now, not in the worker
    return {"path": path, "fps": fps, "source": source, "illusion_types": illusion_types or [],
            "dedup_hamming": dedup_hamming, "user_id": user_id, "original_name": original_name,
            "prefilter": prefilter, **({"mono_dir": str(mono_dir)} if mono_dir is not None else {}),
            **({"mono_files": [list(f) for f in mono_files]} if mono_files else {})}


def mono_maps(folder: Path) -> dict[int, Path]:
    """``{frame index: map file}`` of a ``mono_dir`` (see :func:`ingest_params`); InvalidInput when the
    folder is missing, holds no maps, or names a frame twice."""
    if not folder.is_dir():
        raise InvalidInput(f"{folder}: no such folder of monocular disparities")
    files = [p for p in sorted(folder.iterdir()) if not p.name.startswith(".") and p.is_file()
             and p.suffix.lower() in MONO_SUFFIXES]
    if not files:
        raise InvalidInput(f"{folder}: no {' or '.join(MONO_SUFFIXES)} disparities in it")
    by_name = {p.name: p for p in files}
    return {index: by_name[name] for index, name in mono_index([p.name for p in files]).items()}


def mono_index(names: list[str]) -> dict[int, str]:
    """``{frame index: name}`` of monocular disparity files by their names (``frame_000012.npy`` is
    frame 12's); InvalidInput for a name of another kind or without an index, or a frame named twice."""
    index: dict[int, str] = {}
    for name in names:
        path = Path(name)
        if path.suffix.lower() not in MONO_SUFFIXES:
            raise InvalidInput(f"{quoted(name)}: a monocular disparity is a {' or '.join(MONO_SUFFIXES)} file")
        number = trailing_number(path.stem)
        if number is None:
            raise InvalidInput(f"{quoted(name)}: a disparity's name must end with its frame's index (frame_000012.npy)")
        if number in index:
            raise InvalidInput(f"{quoted(index[number])} and {quoted(name)} are both frame {number}'s disparity")
        index[number] = name
    return index


def ingest_video(ctx: JobContext) -> dict[str, Any]:
    """Job handler for kind ``ingest`` (params from :func:`ingest_params`).

    Errors about an upload name the file as uploaded, never its path in the media store.
    """
    try:
        return _ingest(ctx, ctx.params)
    except IngestError as exc:
        name = ctx.params.get("original_name")
        if not name:
            raise
        raise IngestError(str(exc).replace(str(ctx.params["path"]), name)) from None


def _ingest(ctx: JobContext, p: dict[str, Any]) -> dict[str, Any]:
    src = open_source(p["path"])
    info = src.info
    try:
        mono = ({i: (path, path.name) for i, path in mono_maps(Path(p["mono_dir"])).items()} if p.get("mono_dir")
                else {int(i): (Path(path), name) for i, path, name in p.get("mono_files", [])})
    except InvalidInput as exc:
        raise IngestError(str(exc)) from None
    with transaction(ctx.sessions) as s:
        video = s.scalar(select(Video).where(Video.content_sha256 == info.fingerprint))
        if video is not None and video.meta.get("ingest") == "complete":
            n = s.scalar(select(func.count()).select_from(Frame).where(Frame.video_id == video.id))
            ctx.log(f"already ingested as video {video.id}; nothing to do"
                    + ("; its monocular disparities were not imported (its frames are stored already)" if mono else ""))
            return {"video_id": video.id, "video_name": video.name, "frames": n, "new_frames": 0,
                    "dropped_duplicates": 0, "skipped": True, **({"mono_ignored": True} if mono else {})}
        if video is None:
            video = Video(
                name=p.get("original_name") or Path(p["path"]).name,
                source_kind=SourceKind(p["source"] or ("generated" if info.kind == "synthetic" else "web")),
                illusion_types=p["illusion_types"] or sorted({q["illusion_type"] for q in info.meta.get("pairs", [])}),
                content_sha256=info.fingerprint, original_path=str(p["path"]), fps=info.fps,
                width=info.width, height=info.height, created_by_id=p.get("user_id"),
                meta={**info.meta, "ingest": "running", "sampling_fps": p["fps"]},
            )
            s.add(video)
            s.flush()
        video_id, video_name = video.id, video.name
        done = set(s.scalars(select(Frame.index).where(Frame.video_id == video_id)))
    ctx.log(f"video {video_id}: {info.width}x{info.height} at {info.fps:g} fps, {plural(info.frame_count, 'frame')}; "
            f"sampling at {p['fps'] or 'all'} fps; {plural(len(done), 'frame')} from an earlier attempt")

    kept = new = dropped = 0
    last: int | None = None
    hashes: list[int] = []  # of the kept frames: whether the video copies another is judged on them
    mono_missing: list[int] = []  # kept frames the mono_dir has no disparity for
    try:
        for frame in src.frames(p["fps"]):
            h = dhash(frame.rgb)
            if last is not None and p["dedup_hamming"] is not None and hamming(h, last) <= p["dedup_hamming"]:
                dropped += 1
                continue
            last = h
            kept += 1
            hashes.append(h)
            if mono and frame.index not in mono:
                mono_missing.append(frame.index)
            if frame.index not in done:
                _store_frame(ctx, video_id, frame, h, _mono_asset(ctx, mono.get(frame.index), frame))
                new += 1
            ctx.progress((frame.index + 1) / max(info.frame_count, 1), f"frame {frame.index} ({frame.time_s:.2f} s)")
    except IngestError:
        with transaction(ctx.sessions) as s:
            s.execute(delete(Video).where(Video.id == video_id))  # frames go with it (ON DELETE CASCADE)
        raise
    if kept == 0:
        raise IngestError(f"{p['path']}: no frames could be decoded")
    with transaction(ctx.sessions) as s:
        # One transaction: a crash can't leave a complete video whose prefilter was never queued.
        video = s.get(Video, video_id)
        video.meta = {**video.meta, "ingest": "complete", "frames": kept, "dropped_duplicates": dropped}
        if mono:
            # Whether every kept frame has its own disparity: the video's frames can then become samples
            # without a depth model (a frame without one is judged on its own assets).
            video.meta = {**video.meta, "mono": "precomputed" if not mono_missing else "partial"}
        copy_of = join_scene_group(s, video_id, hashes)
        jobs = launch_prefilter(s, ctx.env.submit, None, video_id=video_id) if p.get("prefilter") else []
    ctx.log(f"kept {plural(kept, 'frame')} ({new} new), dropped {plural(dropped, 'near-duplicate')}; "
            f"queued {plural(len(jobs), 'prefilter job')}")
    if mono:
        origin = p.get("mono_dir") or "the upload"
        ctx.log(f"monocular disparities from {origin}: {kept - len(mono_missing)} of {plural(kept, 'frame')}"
                + (f"; none for frame {', '.join(map(str, mono_missing[:10]))}"
                   f"{' …' if len(mono_missing) > 10 else ''}" if mono_missing else ""))
    if copy_of:
        ctx.log(f"looks like a copy of video {copy_of['video_id']} (“{copy_of['video_name']}”; {copy_of['matched']} "
                f"of {kept} frames alike): kept in the same scene group, so no split separates them")
    return {"video_id": video_id, "video_name": video_name, "frames": kept, "new_frames": new,
            "dropped_duplicates": dropped, **({"copy_of": copy_of} if copy_of else {}),
            **({"mono_frames": kept - len(mono_missing), "mono_missing": mono_missing[:MISSING_SHOWN]} if mono else {})}


def _mono_asset(ctx: JobContext, source: tuple[Path, str] | None, frame: DecodedFrame) -> dict[str, str]:
    """The frame's monocular disparity from ``source`` (its file and the name a message gives it) stored
    as the precomputed backend reads it (``{MONO_ASSET: key}``), or nothing without one; a map that is
    unreadable or of another size fails the ingest, naming the file."""
    if source is None:
        return {}
    path, name = source
    try:
        disparity = read_map(path)
    except FormatError as exc:
        raise IngestError(f"{name}: {str(exc).replace(str(path), name)}") from None
    if disparity.shape != frame.rgb.shape[:2]:
        raise IngestError(f"{name} is {disparity.shape[1]}x{disparity.shape[0]}, but frame {frame.index} is "
                          f"{frame.rgb.shape[1]}x{frame.rgb.shape[0]}: a disparity must match its frame")
    return {MONO_ASSET: store_outputs(ctx.media, {"disparity_mono": disparity.astype(np.float32)})["disparity_mono"]}


def _store_frame(ctx: JobContext, video_id: int, frame: DecodedFrame, phash: int,
                 extra: dict[str, str] | None = None) -> None:
    bgr = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
    # Compression level 1: ~3x faster than the default for ~10% larger files; frames are written once.
    png = frame.png or _encode(bgr, ".png", [cv2.IMWRITE_PNG_COMPRESSION, 1])
    height, width = frame.rgb.shape[:2]
    # Media first, row last: a crash in between leaves an orphan file, never a row without its file.
    assets: dict[str, Any] = {"thumb": put_thumbnail(ctx.media, frame.rgb), "dhash": f"{phash:016x}"}
    for name, path in frame.side_files.items():
        assets[name] = ctx.media.put_file(path)
    assets.update(extra or {})
    key = ctx.media.put_bytes(png, "png")
    with transaction(ctx.sessions) as s:
        s.add(Frame(video_id=video_id, index=frame.index, time_s=frame.time_s, width=width, height=height,
                    content_sha256=hashlib.sha256(png).hexdigest(), media_key=key, assets=assets))


def _encode(bgr: np.ndarray, ext: str, params: list[int]) -> bytes:
    ok, buf = cv2.imencode(ext, bgr, params)
    if not ok:
        raise IngestError(f"could not encode a frame as {ext}")
    return buf.tobytes()
