"""Bring a synthetic video (``dataset.synthetic.write_video``'s layout) into the database.

This is the demo's stand-in for video ingest: the frames are already rendered, and their side data
(exact right view, true / mono-fooled / stereo-fooled disparity, masks) becomes the frame's assets,
ground truth for later steps. The job is idempotent: the video is keyed by its content hash and
frames by (video, index), so a retry after a crash finishes the work without duplicating it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from PIL import Image
from sqlalchemy import select

from dataset.db import transaction
from dataset.models import Frame, IllusionType, SourceKind, Video
from dataset.services.errors import InvalidInput
from dataset.services.jobs import JobContext

_SIDE_FILES = ("right.png", "disparity.npy", "mono_disparity.npy", "stereo_disparity.npy")


def import_synthetic_video(ctx: JobContext) -> dict[str, Any]:
    """Job handler; params: ``path`` (a video dir), optional ``user_id``."""
    video_dir = Path(ctx.params["path"])
    scene_file = video_dir / "scene.json"
    if not scene_file.is_file():
        raise InvalidInput(f"{video_dir} is not a synthetic video (no scene.json)")
    scene = json.loads(scene_file.read_text())
    frames = scene.get("frames") or []
    if not frames:
        raise InvalidInput(f"{video_dir} has no frames")
    digest = hashlib.sha256(scene_file.read_bytes() + (video_dir / "video.mp4").read_bytes()).hexdigest()

    with transaction(ctx.sessions) as s:
        video = s.scalar(select(Video).where(Video.content_sha256 == digest))
        if video is None:
            video = Video(
                name=scene["name"], source_kind=SourceKind.generated, content_sha256=digest,
                illusion_types=sorted({IllusionType(p["illusion_type"]).value for p in scene["pairs"]}),
                original_path=str(video_dir), fps=scene["fps"], width=scene["width"],
                height=scene["height"], created_by_id=ctx.params.get("user_id"),
                meta={"synthetic": True, "seed": scene["seed"], "pairs": scene["pairs"],
                      "intrinsics": scene["intrinsics"],
                      "baseline_m": scene["baseline_m"]},
            )
            s.add(video)
            s.flush()
        video_id = video.id
        done = set(s.scalars(select(Frame.index).where(Frame.video_id == video_id)))
    ctx.log(f"video {video_id} ({scene['name']}): {len(frames)} frames, {len(done)} already imported")

    for n, frame in enumerate(frames, start=1):
        index = frame["index"]
        if index not in done:
            _import_frame(ctx, video_id, index, frame["time_s"], video_dir / "frames" / f"{index:06d}")
        ctx.progress(n / len(frames), f"frame {index}")
    return {"video_id": video_id, "frames": len(frames), "new_frames": len(frames) - len(done)}


def _import_frame(ctx: JobContext, video_id: int, index: int, time_s: float, frame_dir: Path) -> None:
    left = frame_dir / "left.png"
    with Image.open(left) as im:
        width, height = im.size
    data = left.read_bytes()
    key = ctx.media.put_bytes(data, "png")
    # Media first, row last: a crash in between leaves an orphan file, never a row without its file.
    assets = {name.split(".")[0]: ctx.media.put_file(frame_dir / name) for name in _SIDE_FILES}
    assets["masks"] = {p.stem: ctx.media.put_file(p) for p in sorted(frame_dir.glob("*_[0-9][0-9].png"))}
    with transaction(ctx.sessions) as s:
        s.add(Frame(video_id=video_id, index=index, time_s=time_s, width=width, height=height,
                    content_sha256=hashlib.sha256(data).hexdigest(), media_key=key, assets=assets))
