"""Annotation documents: a frame's details for the page, drafts and submits, deletion.

Saves carry the version the annotator started from, and a stale version is refused (409)
without overwriting anything; a frame held by someone else (:mod:`dataset.services.leases`)
cannot be saved or deleted.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError
from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from core.formats import FormatError
from core.formats.rle import canonical_rle
from core.wording import quoted
from dataset.services import audit, proposals
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.frames import get_frame, update_frame
from dataset.services.leases import ensure_annotation_row, held_by_other, release_lease, renew_lease
from dataset.services.sample_review import returned_note, returned_waiting
from dataset.services.validate import DB_INT_MAX, db_int
from dataset.tables import Annotation, Frame, FrameState, IllusionType, Region, RegionKind, User, utcnow

ANNOTATABLE = (FrameState.approved,)
DELETE_REASONS = ("redundant", "imperceptible")
MAX_REGIONS = 64
MAX_CLICKS = 1000  # entries per region; the page sends its clicks, one box and a link or two
# JSON values and keys a draft holds besides its masks' runs, as webapp.api.blueprint.too_many_values
# counts them: a click entry takes at most 7 ({"x", "y", "label"}: a brace, three colons, two commas
# and the comma after it), and a region's own fields, its mask's and the draft's far fewer than 64.
DRAFT_VALUES = MAX_REGIONS * (7 * MAX_CLICKS + 64) + 64


class _Entry(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)

    def inside(self, width: int, height: int) -> bool:
        """Whether the entry's pixels lie on a width x height frame (an entry without any does)."""
        return True


_Coordinate = Annotated[float, Field(ge=0)]
_Id = Annotated[int, Field(ge=0, le=DB_INT_MAX)]


class _Point(_Entry):
    """A click: the pixel it hit and whether it is inside (1) or outside (0) the region."""

    x: _Coordinate
    y: _Coordinate
    label: int = Field(ge=0, le=1)

    def inside(self, width: int, height: int) -> bool:
        return self.x < width and self.y < height


class _Box(_Entry):
    """A dragged box, [x0, y0, x1, y1] in pixels (its edges may lie on the frame's far edges)."""

    box: list[_Coordinate] = Field(min_length=4, max_length=4)

    def inside(self, width: int, height: int) -> bool:
        return max(self.box[::2]) <= width and max(self.box[1::2]) <= height


class _Proposal(_Entry):
    """The proposal the region was accepted from (:mod:`dataset.services.proposals`)."""

    proposal_id: _Id


class _Propagated(_Entry):
    """The frame the region was propagated from (the ``propagate`` job writes it)."""

    propagated_from: _Id


class _Source(_Entry):
    """Where a mask came from when no one clicked it (the demo's ground truth)."""

    source: str = Field(alias="from", max_length=64)


# What a region's ``clicks`` may hold: the entries the Annotate page and the jobs write, nothing else
# (they are stored and served to the next annotator as they came).
_CLICKS = TypeAdapter(list[_Point | _Box | _Proposal | _Propagated | _Source])
_CLICK_FORMS = "{x, y, label: 0|1}, {box: [x0, y0, x1, y1]}, {proposal_id}, {propagated_from} or {from: text}"


def frame_detail(session: Session, frame_id: int, user: User | Any) -> dict[str, Any]:
    """Everything the annotation page needs about a frame, in one response."""
    frame = get_frame(session, frame_id)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id))
    neighbours = session.execute(select(Frame.id, Frame.index).where(Frame.video_id == frame.video_id,
                                                                     Frame.state != FrameState.deleted)
                                 .order_by(Frame.index)).all()
    ids = [i for i, _ in neighbours]
    pos = ids.index(frame.id) if frame.id in ids else -1
    held = ann is not None and held_by_other(ann, user.id)
    return {
        "id": frame.id, "video_id": frame.video_id, "video": frame.video.name,
        "index": frame.index, "time_s": frame.time_s,
        "width": frame.width, "height": frame.height, "state": frame.state.value, "revision": frame.revision,
        "image": frame.media_key, "content_sha256": frame.content_sha256,
        "annotation_version": ann.version if ann else 0,
        "submitted": bool(ann and ann.submitted),
        "illusion_type": ann.illusion_type.value if ann and ann.illusion_type else None,
        "regions": [{"pair": r.pair, "kind": r.kind.value, "mask": r.mask_rle, "clicks": r.clicks,
                     "illusion_type": r.illusion_type.value if r.illusion_type else None}
                    for r in (ann.regions if ann else [])],
        "lease": {"mine": bool(ann and ann.lease_user_id == user.id and not held),
                  "held_by_other": held,
                  "expires": ann.lease_expires_at.isoformat() + "Z" if ann and ann.lease_expires_at else None},
        "returned": returned_note(session, frame),
        # Frames sent back to this annotator meanwhile: the page names them while another frame is on it.
        "returned_waiting": returned_waiting(session, user, other_than=frame.id),
        "prev_id": ids[pos - 1] if pos > 0 else None,
        "next_id": ids[pos + 1] if 0 <= pos < len(ids) - 1 else None,
    }


def save_annotation(session: Session, frame_id: int, user: User | Any, *, version: int, regions: Sequence[Any],
                    illusion_type: str | None, submit: bool) -> Annotation:
    """Save the regions as a draft, or submit them (the frame becomes ``annotated``).

    ``version`` is the annotation version the page loaded; anything else is a 409 and nothing is written.
    The illusion type belongs to each pair (a frame can hold a picture and a mirror): a region carries
    its pair's ``illusion_type``, and a pair without one gets ``illusion_type`` (a default for the
    request's pairs). The annotation's own type is that default, else its first typed pair's.
    """
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if frame.state not in ANNOTATABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only approved frames can be annotated")
    ensure_annotation_row(session, frame_id)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id).with_for_update())
    stale = Conflict(f"the annotation of frame {frame_id} changed since you loaded it (version {version}, "
                     f"now {ann.version}); reload to see it")
    if version != ann.version:
        raise stale
    if held_by_other(ann, user.id):
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    kind = _parse_type(illusion_type) if illusion_type else None
    parsed = _parse_regions(regions, frame.height, frame.width, require_illusion=submit)
    for region in parsed:
        region.illusion_type = region.illusion_type or kind
    untyped = sorted({r.pair for r in parsed if r.illusion_type is None})
    if submit and untyped:
        raise InvalidInput(f"choose the illusion type ({', '.join(IllusionType)}) of every pair before submitting "
                           f"(pair {untyped[0]} has none)")
    kind = kind or next((r.illusion_type for r in sorted(parsed, key=lambda r: r.pair) if r.illusion_type), None)
    # Compare-and-swap on the version: of two saves from the same version, exactly one wins.
    won = session.execute(update(Annotation).where(Annotation.id == ann.id, Annotation.version == version)
                          .values(version=Annotation.version + 1, user_id=user.id, illusion_type=kind,
                                  submitted=submit, updated_at=utcnow())
                          .execution_options(synchronize_session=False)).rowcount
    if won != 1:
        raise stale
    # The old rows go unread (a full draft's masks and clicks are MBs once parsed), and before the new
    # ones arrive (unique (annotation, pair, kind)).
    session.execute(delete(Region).where(Region.annotation_id == ann.id))
    session.refresh(ann)
    ann.regions.extend(parsed)
    if submit:
        ann.lease_user_id = ann.lease_expires_at = None
        update_frame(session, frame, state=FrameState.annotated)
        proposals.record_fates(session, frame_id, parsed, user)
        audit.record(session, user.id, "annotation.submit", "frame", frame.id, version=ann.version,
                     pairs=sorted({r.pair for r in parsed}), illusion_type=kind.value)
    session.flush()
    return ann


def _parse_type(value: str) -> IllusionType:
    try:
        return IllusionType(value)
    except ValueError:
        raise InvalidInput(f"unknown illusion type {quoted(value)}; choose one of {', '.join(IllusionType)}") from None


def _parse_regions(regions: Sequence[Any], height: int, width: int, *, require_illusion: bool) -> list[Region]:
    if not isinstance(regions, list) or len(regions) > MAX_REGIONS:
        raise InvalidInput(f"regions must be a list of at most {MAX_REGIONS} masks")
    out, seen = [], set()
    for n, r in enumerate(regions):
        if not isinstance(r, dict):
            raise InvalidInput(f"region {n} is not an object")
        pair = db_int(r.get("pair"), f"region {n}: pair", minimum=0)
        try:
            kind = RegionKind(r.get("kind"))
        except ValueError:
            raise InvalidInput(f"region {n} needs a kind (illusion or support)") from None
        if (pair, kind) in seen:
            raise InvalidInput(f"pair {pair} has two {kind.value} regions")
        seen.add((pair, kind))
        try:
            mask_rle = canonical_rle(r.get("mask"), (height, width))
        except FormatError as exc:
            raise InvalidInput(f"region {n}: {exc}") from None
        clicks = _clicks(r.get("clicks") or [], height, width, f"region {n}")
        out.append(Region(pair=pair, kind=kind, mask_rle=mask_rle, clicks=clicks))
    types: dict[int, IllusionType] = {}
    for n, (r, region) in enumerate(zip(regions, out, strict=True)):
        if r.get("illusion_type"):
            chosen = _parse_type(str(r["illusion_type"]))
            if types.setdefault(region.pair, chosen) != chosen:
                raise InvalidInput(f"region {n}: pair {region.pair} has two illusion types "
                                   f"({types[region.pair].value}, {chosen.value})")
    for region in out:  # both masks of a pair carry its type
        region.illusion_type = types.get(region.pair)
    if require_illusion:
        pairs = {p for p, _ in seen}
        missing = sorted(p for p in pairs if (p, RegionKind.illusion) not in seen)
        if not pairs or missing:
            raise InvalidInput("every pair needs an illusion region before submitting"
                               + (f" (pair {missing[0]} has none)" if missing else ""))
    return out


def _clicks(clicks: Any, height: int, width: int, where: str) -> list[Any]:
    """A region's click entries, checked to be those the page sends (:data:`_CLICKS`) on the frame;
    stored as they came (a click at pixel 3 stays 3, not 3.0)."""
    if not isinstance(clicks, list) or len(clicks) > MAX_CLICKS:
        raise InvalidInput(f"{where}: clicks must be a list of at most {MAX_CLICKS} entries")
    try:
        entries = _CLICKS.validate_python(clicks)
    except ValidationError as exc:
        raise InvalidInput(f"{where}: clicks entry {exc.errors()[0]['loc'][0]} must be one of {_CLICK_FORMS}") from None
    for i, entry in enumerate(entries):
        if not entry.inside(width, height):
            raise InvalidInput(f"{where}: clicks entry {i} is outside the {width}x{height} frame")
    return clicks


def take_lease(session: Session, frame_id: int, user: User | Any, lease_s: int) -> datetime:
    """Take or renew ``user``'s lease on a frame to annotate; when it ends. 404 for no such frame, 409 for
    a frame that is not to annotate (not approved) or that someone else holds."""
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if frame.state not in ANNOTATABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only approved frames can be annotated")
    return renew_lease(session, frame_id, user, lease_s)


def give_back(session: Session, frame_id: int, user: User | Any) -> bool:
    """Release ``user``'s lease on the frame; False when they held none (nothing happened). 404 for no
    such frame, 409 when someone else holds it (only its holder or its running out frees it)."""
    get_frame(session, frame_id)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id).with_for_update())
    if ann is None:
        return False
    if held_by_other(ann, user.id):
        raise Conflict(f"frame {frame_id} is held by another annotator; only they can release it")
    if ann.lease_user_id != user.id:
        return False
    release_lease(session, frame_id, user)
    return True


def delete_frame(session: Session, frame_id: int, user: User | Any, reason: str) -> Frame:
    """Mark a frame redundant or imperceptible: it leaves the pipeline (audited)."""
    if reason not in DELETE_REASONS:
        raise InvalidInput(f"reason must be one of {', '.join(DELETE_REASONS)}")
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if frame.state not in ANNOTATABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only approved frames can be deleted here")
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id))
    if ann is not None and held_by_other(ann, user.id):
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    before = frame.state
    update_frame(session, frame, state=FrameState.deleted)
    release_lease(session, frame_id, user)
    audit.record(session, user.id, "annotation.delete", "frame", frame.id, reason=reason, before=before.value)
    return frame
