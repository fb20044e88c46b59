"""Machine-proposed illusions for frames to annotate: the ``propose`` job, what the Annotate page is
shown, rejections, each proposal's fate on submit, and the figures per proposer.

A scan is one proposer having looked at one frame (its note says why it found nothing when it could
not look); its proposals wait (``pending``) until the annotator accepts one — it becomes a pair of
the annotation whose regions carry ``{"proposal_id": N}`` among their clicks — or rejects it. On
submit every proposal of the frame gets its fate: ``accepted`` (both masks as proposed), ``edited``
(with the IoU between the proposed and the submitted illusion), ``rejected`` (turned down, or left
untouched while shown) or ``hidden`` (left untouched while hidden); and each scan counts the submitted
illusions none of its shown or taken proposals found (IoU < MATCH_IOU).

The propose job keeps every proposal scoring at least plane-break's SCORE_FLOOR; the scan stores the
threshold in force (setting ``proposal_threshold``), and the page hides those scoring under it unless
the annotator asks to see all. A hidden proposal the annotator never saw is no verdict on it: its fate
``hidden`` counts neither against the acceptance rate nor as a find, and the figures per proposer are
grouped by threshold, since a threshold changes what annotators are shown.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from annotation.proposals import Proposer, make_proposers
from annotation.proposals.base import ProposalError, mask_iou
from annotation.proposals.plane_break import SCORE_FLOOR
from core.formats import mask_to_rle, rle_to_mask
from dataset.db import transaction
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.generate import GenerationError, mono_disparity
from dataset.services.jobs import JobContext
from dataset.services.leases import held_by_other
from dataset.services.prefilter import backend_for
from dataset.services.segmentation import frames_coming, load_rgb, settings_segmenter
from dataset.settings import Settings
from dataset.tables import (
    Annotation,
    Frame,
    FrameState,
    IllusionType,
    Proposal,
    ProposalFate,
    ProposalScan,
    Region,
    RegionKind,
    User,
    Video,
    utcnow,
)

MATCH_IOU = 0.5  # a submitted illusion counts as found by a proposer when one of its proposals overlaps it this much
LINK = "proposal_id"  # the click entry that ties a submitted pair to the proposal it was accepted from
TAKEN = (ProposalFate.accepted, ProposalFate.edited)
CHUNK = 16  # frames per propose job


def configured_proposers(settings: Settings) -> list[Proposer]:
    """The proposers named by ``settings.proposers``, with the configured VLM backend and segmenter
    (both cached per process, so a model loads once per worker). They keep every proposal scoring at
    least SCORE_FLOOR: the page hides those under the threshold (module doc)."""
    if "vlm" not in settings.proposers:
        return make_proposers(settings.proposers, min_score=SCORE_FLOOR)
    return make_proposers(settings.proposers, vlm=backend_for(settings, {}), segmenter=settings_segmenter(settings),
                          min_score=SCORE_FLOOR)


def frames_to_scan(session: Session, settings: Settings, frame_ids: Sequence[int]) -> list[int]:
    """Those of ``frame_ids`` that are approved (in the annotation queue), that some configured proposer
    has not looked at yet and that no queued or running ``propose`` job is about to: what a worker
    should propose on ahead."""
    wanted = set(settings.proposers)
    if not wanted or not frame_ids:
        return []
    approved = set(session.scalars(select(Frame.id).where(Frame.id.in_(frame_ids), Frame.state == FrameState.approved)))
    scanned: dict[int, set[str]] = {}
    for frame_id, source in session.execute(select(ProposalScan.frame_id, ProposalScan.source)
                                            .where(ProposalScan.frame_id.in_(approved))):
        scanned.setdefault(frame_id, set()).add(source)
    coming = frames_coming(session, "propose")
    return [fid for fid in dict.fromkeys(frame_ids)
            if fid in approved and fid not in coming and not wanted <= scanned.get(fid, set())]


def propose_chunks(frame_ids: Sequence[int]) -> list[list[int]]:
    """``frame_ids`` in jobs of at most CHUNK frames, so that a bulk approval does not hold the queue's
    embedding and generation jobs up behind one long job."""
    return [list(frame_ids[i:i + CHUNK]) for i in range(0, len(frame_ids), CHUNK)]


def propose_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``propose``: run the configured proposers on ``frame_ids`` that they have not looked at yet.
    Idempotent: a frame a proposer has scanned (here or in a parallel job) is skipped."""
    proposers = configured_proposers(ctx.settings)
    frame_ids = list(ctx.params["frame_ids"])
    scanned = found = 0
    for n, frame_id in enumerate(frame_ids, start=1):
        made = _propose_frame(ctx, proposers, frame_id)
        scanned += bool(made)
        found += sum(made.values())
        ctx.progress(n / len(frame_ids), f"frame {frame_id}: " + (", ".join(f"{k} {v}" for k, v in made.items())
                                                                  or "already proposed"))
    return {"frames": len(frame_ids), "scanned": scanned, "proposals": found,
            "proposers": [p.name for p in proposers]}


def _propose_frame(ctx: JobContext, proposers: Sequence[Proposer], frame_id: int) -> dict[str, int]:
    """Run the proposers that have not looked at the approved frame; {proposer: proposals found}. A frame
    that cannot be read is logged and skipped: the other frames of the job go on."""
    with ctx.sessions() as s:
        frame = s.get(Frame, frame_id)
        if frame is None or frame.state != FrameState.approved:
            return {}
        done = set(s.scalars(select(ProposalScan.source).where(ProposalScan.frame_id == frame_id)))
        todo = [p for p in proposers if p.name not in done]
        video = s.get(Video, frame.video_id)
    if not todo:
        return {}
    mono, why = None, ""
    try:
        image = load_rgb(ctx.media, frame.media_key)
        if any(p.needs_mono for p in todo):
            mono = mono_disparity(ctx.settings, ctx.media, frame, video, image).disparity
    except GenerationError as exc:
        why = str(exc)
    except (InvalidInput, OSError) as exc:
        ctx.log(f"frame {frame_id}: skipped, {exc}")
        return {}
    made = {}
    for proposer in todo:
        started = time.perf_counter()
        try:
            result = proposer.propose(image, mono)
            items, note = result.items, result.note
        except ProposalError as exc:  # a frame it cannot read is a note on the page, not a failed job
            items, note = [], str(exc)
        if why and proposer.needs_mono:
            note = f"{note} ({why})"
        scan = ProposalScan(frame_id=frame_id, source=proposer.name, content_sha256=frame.content_sha256, note=note,
                            seconds=round(time.perf_counter() - started, 3), threshold=ctx.settings.proposal_threshold)
        scan.proposals = [Proposal(frame_id=frame_id, source=proposer.name, rank=rank, type_guess=p.illusion_type,
                                   score=round(float(p.score), 4), illusion_rle=mask_to_rle(p.illusion),
                                   support_rle=mask_to_rle(p.support)) for rank, p in enumerate(items)]
        try:
            with transaction(ctx.sessions) as s:
                # Submitted (or deleted) meanwhile: its proposals would wait for a decision that never comes.
                if s.get(Frame, frame_id, with_for_update=True).state != FrameState.approved:
                    return made
                s.add(scan)
        except IntegrityError:  # a parallel job scanned it first: its proposals stand
            continue
        made[proposer.name] = len(items)
    return made


def frame_proposals(session: Session, settings: Settings, frame_id: int) -> dict[str, Any]:
    """What the Annotate page shows of a frame's proposals: ``proposals`` (best first, every fate),
    ``proposals_ready`` (every configured proposer has looked) and ``proposals_note`` (why there are
    none, when there are none)."""
    scans = session.scalars(select(ProposalScan).where(ProposalScan.frame_id == frame_id)).all()
    wanted = list(settings.proposers)
    missing = [name for name in wanted if name not in {s.source for s in scans}]
    items = sorted((p for scan in scans for p in scan.proposals), key=lambda p: (-p.score, p.id))
    if not wanted:
        note = "no proposers are configured (setting proposers)"
    elif missing:
        note = f"proposals are being computed ({', '.join(missing)})"
    elif not items:
        note = "; ".join(f"{s.source}: {s.note}" for s in scans if s.note) or "the proposers found no illusion here"
    else:
        note = ""
    return {"proposals": [proposal_json(p) for p in items], "proposals_ready": not missing, "proposals_note": note}


def proposal_json(proposal: Proposal) -> dict[str, Any]:
    """A proposal for the page: ``illusion_type`` is its guess where that is an annotation type (a
    "transparent" guess leaves the choice to the annotator), ``guess`` the proposer's own word,
    ``hidden`` whether it scored under ``threshold``, its scan's (shown only when the annotator asks)."""
    typed = proposal.type_guess if proposal.type_guess in IllusionType.__members__ else None
    return {"id": proposal.id, "source": proposal.source, "score": proposal.score, "illusion_type": typed,
            "guess": proposal.type_guess, "illusion": proposal.illusion_rle, "support": proposal.support_rle,
            "fate": proposal.fate.value, "iou": proposal.iou, "hidden": is_hidden(proposal),
            "threshold": proposal.scan.threshold}


def is_hidden(proposal: Proposal) -> bool:
    """The proposal scored under the threshold in force when its frame was scanned."""
    return proposal.score < proposal.scan.threshold


def reject_proposal(session: Session, frame_id: int, proposal_id: int, user: User | Any) -> Proposal:
    """Turn a pending proposal of the frame down (idempotent); 404 for another frame's, 409 unless the
    frame is to annotate and ``user`` holds its lease (the annotator at work on it decides)."""
    proposal = session.get(Proposal, proposal_id, with_for_update=True)
    if proposal is None or proposal.frame_id != frame_id:
        raise NotFound(f"frame {frame_id} has no proposal {proposal_id}")
    frame = session.get(Frame, frame_id)
    if frame.state != FrameState.approved:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; proposals are decided while it is annotated")
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id))
    if ann is not None and held_by_other(ann, user.id):
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    if ann is None or not _holds(ann, user.id):
        raise Conflict(f"take frame {frame_id} first (POST its lease): proposals are decided by the annotator "
                       "holding the frame")
    if proposal.fate == ProposalFate.pending:
        _decide(proposal, ProposalFate.rejected, None, user)
    return proposal


def _holds(ann: Annotation, user_id: int) -> bool:
    """``user_id`` holds an unexpired lease on ``ann`` (the counterpart of :func:`held_by_other`)."""
    return ann.lease_user_id == user_id and ann.lease_expires_at is not None and ann.lease_expires_at > utcnow()


def record_fates(session: Session, frame_id: int, regions: Sequence[Region], user: User | Any) -> None:
    """On submit: every proposal of the frame gets its fate from the submitted ``regions`` (module
    doc), and every scan its misses. A link to a proposal of another frame is ignored."""
    proposals = {p.id: p for p in session.scalars(select(Proposal).where(Proposal.frame_id == frame_id))}
    scans = session.scalars(select(ProposalScan).where(ProposalScan.frame_id == frame_id)).all()
    if not scans:
        return
    pairs: dict[int, dict[RegionKind, Region]] = {}
    for region in regions:
        pairs.setdefault(region.pair, {})[region.kind] = region
    frame = session.get(Frame, frame_id)
    shape = (frame.height, frame.width)
    finals = {pair: {kind: rle_to_mask(r.mask_rle, shape) for kind, r in masks.items()} for pair, masks in pairs.items()
              if RegionKind.illusion in masks}
    linked: dict[int, int] = {}
    for pair, masks in pairs.items():
        link = _link(masks.get(RegionKind.illusion))
        if link in proposals and link not in linked and pair in finals:
            linked[link] = pair
    for proposal in proposals.values():
        if proposal.id in linked:
            final = finals[linked[proposal.id]]
            proposed = rle_to_mask(proposal.illusion_rle, shape)
            iou = mask_iou(proposed, final[RegionKind.illusion])
            proposed_support = rle_to_mask(proposal.support_rle, shape)
            # The page saves no empty region: an absent support is an empty one.
            support = final.get(RegionKind.support, np.zeros_like(proposed_support))
            same = iou == 1.0 and np.array_equal(proposed_support, support)
            _decide(proposal, ProposalFate.accepted if same else ProposalFate.edited, round(iou, 4), user)
        elif proposal.fate != ProposalFate.rejected:
            _decide(proposal, ProposalFate.hidden if is_hidden(proposal) else ProposalFate.rejected, None, user)
    masks_by_source: dict[str, list[np.ndarray]] = {}
    for proposal in proposals.values():
        if proposal.fate == ProposalFate.hidden:  # never seen: it found nothing for the annotator
            continue
        masks_by_source.setdefault(proposal.source, []).append(rle_to_mask(proposal.illusion_rle, shape))
    for scan in scans:
        if scan.note:  # it could not look (no monocular disparity, no VLM answer): it missed nothing
            scan.misses = 0
            continue
        found = masks_by_source.get(scan.source, [])
        scan.misses = sum(max((mask_iou(m, final[RegionKind.illusion]) for m in found), default=0.0) < MATCH_IOU
                          for final in finals.values())


def _link(region: Region | None) -> int | None:
    """The proposal id a region was accepted from (its clicks' ``{"proposal_id": N}``), if any."""
    for entry in (region.clicks if region is not None else []):
        if isinstance(entry, dict) and type(entry.get(LINK)) is int:
            return entry[LINK]
    return None


def _decide(proposal: Proposal, fate: ProposalFate, iou: float | None, user: User | Any) -> None:
    proposal.fate, proposal.iou, proposal.decided_by, proposal.decided_at = fate, iou, user.id, utcnow()


def proposer_stats(session: Session) -> dict[str, Any]:
    """Per proposer, over all its scans and in ``by_threshold`` (highest first) over those made at each
    threshold in force: frames scanned, proposals by fate, acceptance rate (accepted and edited over
    those shown and decided: a hidden one left untouched is no verdict), median IoU of the accepted
    ones (as proposed = 1), misses, and the median seconds per frame."""
    groups: dict[str, list[float]] = {}
    for source, threshold in session.execute(select(ProposalScan.source, ProposalScan.threshold).distinct()
                                             .order_by(ProposalScan.source, ProposalScan.threshold.desc())):
        groups.setdefault(source, []).append(threshold)
    return {"proposers": {source: {**_figures(session, ProposalScan.source == source),
                                   "by_threshold": [{"threshold": t, **_figures(session, ProposalScan.source == source,
                                                                                ProposalScan.threshold == t)}
                                                    for t in thresholds]}
                          for source, thresholds in groups.items()}}


def _figures(session: Session, *scans: Any) -> dict[str, Any]:
    """:func:`proposer_stats`' figures over the scans that ``scans`` (conditions on ProposalScan) select."""
    frames, misses = session.execute(select(func.count(), func.coalesce(func.sum(ProposalScan.misses), 0))
                                     .where(*scans)).one()
    row: dict[str, Any] = {"frames": frames, "misses": int(misses), **{f.value: 0 for f in ProposalFate}}
    of_scans = select(Proposal.fate, func.count()).join(ProposalScan, Proposal.scan_id == ProposalScan.id).where(*scans)
    for fate, count in session.execute(of_scans.group_by(Proposal.fate)):
        row[fate.value] = count
    row["proposals"] = sum(row[f.value] for f in ProposalFate)
    taken = row["accepted"] + row["edited"]
    decided = taken + row["rejected"]
    row["acceptance_rate"] = round(taken / decided, 4) if decided else None
    row["median_iou"] = _median(session, Proposal.iou, *scans, Proposal.fate.in_(TAKEN), Proposal.iou.is_not(None))
    seconds = session.scalars(select(ProposalScan.seconds).where(*scans).order_by(ProposalScan.id.desc()).limit(1000)).all()
    row["ms_per_frame"] = round(1000 * statistics.median(seconds), 1) if seconds else None
    return row


def _median(session: Session, column: Any, *where: Any) -> float | None:
    """The median of ``column`` over the proposals (joined with their scans) ``where`` selects, in the
    database: the dashboard polls this, and at the paper's scale there are a million proposals to not
    load into Python."""
    joined = select(func.count()).select_from(Proposal).join(ProposalScan, Proposal.scan_id == ProposalScan.id)
    count = session.scalar(joined.where(*where))
    if not count:
        return None
    middle = session.scalars(select(column).join(ProposalScan, Proposal.scan_id == ProposalScan.id).where(*where)
                             .order_by(column).offset((count - 1) // 2).limit(2 - count % 2)).all()
    return round(statistics.fmean(middle), 4)
