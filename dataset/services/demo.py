"""The demo workspace's head start: some frames reviewed and annotated from their true masks.

Synthetic frames carry exact masks of every illusion and its support, so the demo can show every
page with content (approved frames, annotations, generated samples) while leaving work for a
newcomer to do by hand in each role.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from core.formats import mask_to_rle
from dataset.media import MediaStore
from dataset.samples import load_output
from dataset.services.annotate import save_annotation
from dataset.services.review import review_frame
from dataset.services.sample_review import review_sample
from dataset.tables import Frame, FrameState, Sample, SampleState, User, Video

APPROVE_PER_VIDEO = 6
ANNOTATE_PER_VIDEO = 3


def seed_reviews_and_annotations(session: Session, media: MediaStore, curator: User, annotator: User, *,
                                 approve: int = APPROVE_PER_VIDEO, annotate: int = ANNOTATE_PER_VIDEO) -> list[int]:
    """Approve the first ``approve`` frames of each synthetic video and annotate the first ``annotate``
    of those from their true masks (submitted, so generation follows). Returns the annotated frame
    ids; idempotent."""
    annotated = []
    for video in session.scalars(select(Video).order_by(Video.id)):
        if not video.meta.get("synthetic"):
            continue
        frames = session.scalars(select(Frame).where(Frame.video_id == video.id).order_by(Frame.index)
                                 .limit(approve)).all()
        for n, frame in enumerate(frames):
            if frame.state == FrameState.prefiltered:
                review_frame(session, frame.id, curator, "approve")
            if n < annotate and frame.state == FrameState.approved:
                save_annotation(session, frame.id, annotator, version=0, regions=true_regions(media, frame, video),
                                illusion_type=None, submit=True)
                annotated.append(frame.id)
    return annotated


def accept_generated_samples(session: Session, curator: User) -> int:
    """Accept every generated sample (they come from true masks), so the demo has a dataset to train on."""
    ids = session.scalars(select(Sample.id).where(Sample.state == SampleState.generated).order_by(Sample.id)).all()
    for sample_id in ids:
        review_sample(session, sample_id, curator, "accept")
    return len(ids)


def true_regions(media: MediaStore, frame: Frame, video: Video) -> list[dict[str, object]]:
    """A synthetic frame's regions from its true masks, each illusion typed as its scene says (a
    scene holds a picture and a mirror: ``video.meta["pairs"]``, from its ``scene.json``)."""
    types = {int(p["pair"]): p["illusion_type"] for p in video.meta.get("pairs", []) if p.get("illusion_type")}
    regions = []
    for name, key in sorted(frame.assets.items()):
        kind, _, pair = name.partition("_")
        if kind in ("illusion", "support") and pair.isdigit():
            mask = load_output(media, key, "mask")
            typed = {"illusion_type": types[int(pair)]} if kind == "illusion" and int(pair) in types else {}
            regions.append({"pair": int(pair), "kind": kind, "mask": mask_to_rle(mask),
                            "clicks": [{"from": "ground truth"}], **typed})
    return regions
