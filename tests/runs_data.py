"""Accepted samples for training-run tests: small real stereo pairs (a textured plane shifted by a
known disparity) in the media store, one video per split."""

from __future__ import annotations

import numpy as np
from sqlalchemy.orm import Session

from dataset.media import MediaStore
from dataset.samples import store_outputs
from dataset.tables import Frame, FrameState, Sample, SampleState, SourceKind, Video

H, W, DISPARITY = 64, 96, 4.0


def add_accepted_samples(session: Session, media: MediaStore, videos: int = 3, frames: int = 2,
                         seed: int = 0) -> list[int]:
    """``videos`` videos of ``frames`` accepted samples each; returns the sample ids."""
    rng = np.random.default_rng(seed)
    ids = []
    for v in range(videos):
        video = Video(name=f"plane {v}", source_kind=SourceKind.generated, illusion_types=["picture"],
                      content_sha256=f"{seed:02d}{v:062d}", fps=2.0, width=W, height=H, meta={})
        session.add(video)
        session.flush()
        for f in range(frames):
            wide = rng.integers(0, 255, (H, W + 8, 3), dtype=np.uint8)
            # x_right = x_left - DISPARITY for every pixel.
            left, right = wide[:, :W], wide[:, int(DISPARITY):W + int(DISPARITY)]
            illusion = np.zeros((H, W), bool)
            illusion[16:48, 24:72] = True
            files = store_outputs(media, {"left": left, "right": right,
                                          "disparity": np.full((H, W), DISPARITY, np.float32),
                                          # the lite preset's precomputed mono backend reads this
                                          "disparity_mono": np.linspace(0.5, 1.5, H * W, dtype=np.float32).reshape(H, W),
                                          "masks": {"illusion_00": illusion}})
            frame = Frame(video_id=video.id, index=f, time_s=f / 2, width=W, height=H,
                          content_sha256=files["left"].rsplit("/", 1)[1][:64], media_key=files["left"],
                          state=FrameState.accepted)
            session.add(frame)
            session.flush()
            sample = Sample(frame_id=frame.id, state=SampleState.accepted, files=files, params={"scale": 1.0},
                            provenance={"illusion_type": "picture"}, qa={"flags": []})
            session.add(sample)
            session.flush()
            ids.append(sample.id)
    return ids
