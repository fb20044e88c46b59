"""A rendered synthetic video imported as captures: its exact right views and true disparity.

Generated samples never show stereo fooled by a mirror (their right views are warped from the
rectified disparity); rendered pairs do, since their right views are raytraced with the
reflection. Imported like a real rig's captures (``real_capture`` video, ground-truth samples),
they let training see both illusions as the paper's real test data shows them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from dataset.ingest.phash import dhash
from dataset.media import MediaStore
from dataset.samples import mask_name, store_outputs
from dataset.synthetic import SyntheticVideo
from dataset.tables import Frame, FrameState, Sample, SourceKind, Video
from dataset.thumbnails import put_thumbnail
from dataset.version import code_version


def import_rendered_video(session: Session, media: MediaStore, video: SyntheticVideo) -> list[int]:
    """Store every frame of ``video`` as a ground-truth sample (state ``generated``, for a curator to
    accept) of a new ``real_capture`` video; returns the sample ids. Idempotent: a video already
    imported (same name and seed) returns its samples' ids again."""
    fingerprint = f"rendered:{video.name}:{video.seed}:{video.baseline_m}:{video.frames[0].left.shape}"
    existing = session.scalar(select(Video).where(Video.content_sha256 == fingerprint))
    if existing is not None:
        return list(session.scalars(select(Sample.id).join(Frame).where(Frame.video_id == existing.id)
                                    .order_by(Frame.index)))
    height, width = video.frames[0].disparity.shape
    types = sorted({pair.illusion_type for frame in video.frames for pair in frame.regions})
    row = Video(name=f"{video.name}-rendered", source_kind=SourceKind.real_capture, illusion_types=types,
                content_sha256=fingerprint, original_path=f"rendered:{video.name}", fps=video.fps, width=width,
                height=height, meta={"synthetic": True, "rendered_pairs": True, "seed": video.seed,
                                     "intrinsics": {"fx": video.fx, "fy": video.fy, "cx": video.cx, "cy": video.cy},
                                     "baseline_m": video.baseline_m,
                                     "pairs": [{"pair": p.pair, "illusion_type": p.illusion_type}
                                               for p in video.frames[0].regions]})
    session.add(row)
    session.flush()
    ids = []
    for frame in video.frames:
        masks = {}
        for pair in frame.regions:
            masks[mask_name("illusion", pair.pair)] = pair.illusion
            masks[mask_name("support", pair.pair)] = pair.support
        # Media first, rows last: a crash in between leaves orphan files, never a row without its file.
        files = store_outputs(media, {"left": frame.left, "right": frame.right, "disparity": frame.disparity,
                                      "disparity_mono": frame.mono_disparity,
                                      "valid": np.isfinite(frame.disparity), "masks": masks})
        frame_row = Frame(video_id=row.id, index=frame.index, time_s=frame.time_s, width=width, height=height,
                          content_sha256=Path(files["left"]).stem, media_key=files["left"],
                          state=FrameState.generated,
                          assets={"thumb": put_thumbnail(media, frame.left), "dhash": f"{dhash(frame.left):016x}"})
        session.add(frame_row)
        session.flush()
        sample = Sample(frame_id=frame_row.id, files=files, params={"scale": 1.0},
                        provenance={"source": "capture", "rendered": video.name, "seed": video.seed,
                                    "pair_types": {mask_name("illusion", p.pair): p.illusion_type for p in frame.regions},
                                    "code_version": code_version()},
                        qa={"flags": []})
        session.add(sample)
        session.flush()
        ids.append(sample.id)
    return ids
