"""Did every write the server acknowledged during ``bench load`` land? Read back from the database.

A lost write is a 2xx whose effect is missing afterwards: a review decision without its audit entry
(or, for approvals and rejections, its review row), or whose answered frame revision did not move on
from the one it was sent with or is above the frame's revision now; a save whose answered annotation
version is not the one it was sent with plus one (compare-and-swap), two saves acknowledged with the
same version (one overwrote the other), a version the annotation never reached, or a last save whose
masks are not the ones stored.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session

from benchmarks.load_clients import Save, Tally
from dataset.tables import Annotation, AuditEntry, Frame, Review


def lost_writes(session: Session, tallies: Sequence[Tally]) -> dict[str, int]:
    """Acknowledged writes missing from the database, per check (all must be 0)."""
    return {**_lost_reviews(session, tallies), **_lost_saves(session, [s for t in tallies for s in t.saves])}


def _lost_reviews(session: Session, tallies: Sequence[Tally]) -> dict[str, int]:
    acked = Counter((d.frame_id, t.user_id, d.decision) for t in tallies for d in t.reviews)
    audited = Counter((frame, user, action.removeprefix("review.")) for frame, user, action in session.execute(
        select(AuditEntry.target_id, AuditEntry.user_id, AuditEntry.action).where(AuditEntry.action.like("review.%"))))
    rows = Counter((frame, user, decision.value) for frame, user, decision in session.execute(
        select(Review.frame_id, Review.user_id, Review.decision)))
    revisions = dict(session.execute(select(Frame.id, Frame.revision)).all())
    return {
        "review_audit": sum(max(0, n - audited[key]) for key, n in acked.items()),
        "review_rows": sum(max(0, n - rows[key]) for key, n in acked.items() if key[2] != "reset"),
        # A decision moves the frame on from the revision it was sent with, and revisions never go back.
        "frame_revisions": sum(not d.base < d.revision <= revisions[d.frame_id] for t in tallies for d in t.reviews),
    }


def _lost_saves(session: Session, saves: Sequence[Save]) -> dict[str, int]:
    by_frame: defaultdict[int, list[Save]] = defaultdict(list)
    for save in saves:
        by_frame[save.frame_id].append(save)
    stored = {a.frame_id: a for a in session.scalars(select(Annotation).where(Annotation.frame_id.in_(by_frame)))}
    lost = {"annotation_versions_not_advanced": sum(s.version != s.base + 1 for s in saves),
            "annotation_versions_twice": 0, "annotation_versions_missing": 0, "annotation_content": 0}
    for frame_id, acked in by_frame.items():
        ann = stored.get(frame_id)
        versions = [s.version for s in acked]
        current = ann.version if ann else 0
        lost["annotation_versions_twice"] += len(versions) - len(set(versions))
        lost["annotation_versions_missing"] += sum(v > current for v in set(versions))
        last = max(acked, key=lambda s: s.version)
        if ann is not None and last.version == current:  # else a later write nobody saw answered came after it
            masks = tuple(r.mask_rle["counts"] for r in ann.regions)
            lost["annotation_content"] += masks != last.masks or ann.submitted != last.submitted
    return lost
