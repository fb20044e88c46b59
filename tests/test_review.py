"""Curator review: decisions, reasons, stale pages (409), bulk, undo, audit, filters — on both databases."""

from __future__ import annotations

import pytest
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import review as review_service
from dataset.services import users as user_service
from dataset.services.errors import Conflict, InvalidInput
from dataset.services.frames import funnel_counts
from dataset.tables import AuditEntry, Frame, FrameState, PrefilterResult, Review, SourceKind, Video


def seed_frames(s, n: int = 4) -> list[int]:  # type: ignore[no-untyped-def]
    video = Video(name="v", source_kind=SourceKind.web, content_sha256="f" * 64)
    s.add(video)
    s.flush()
    ids = []
    for i in range(n):
        frame = Frame(video_id=video.id, index=i, time_s=i / 2, width=64, height=48, content_sha256=f"{i:064d}",
                      media_key="k", state=FrameState.prefiltered, assets={"thumb": "t"})
        s.add(frame)
        s.flush()
        answers = [None] * 12
        answers[8] = i % 2 == 0  # Q9 "blurry": yes on even frames
        s.add(PrefilterResult(frame_id=frame.id, backend="heuristic", model_id="heuristic-v1", prompt_version="paper-v1",
                              answers=answers, parsed=False, keep=False if i % 2 == 0 else None,
                              metrics={"laplacian_var": 10.0 * i}))
        ids.append(frame.id)
    return ids



def test_decisions_reasons_conflicts_and_audit(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        ids = seed_frames(s)
        curator = user_service.create_user(s, "cu", "curator", "long-enough")
    with transaction(sessions) as s:
        frame = review_service.review_frame(s, ids[0], curator, "approve", revision=1)
        assert (frame.state, frame.revision) == (FrameState.approved, 2)
    with transaction(sessions) as s, pytest.raises(Conflict, match="changed since you loaded it"):
        review_service.review_frame(s, ids[0], curator, "reject", "blurry", revision=1)
    with transaction(sessions) as s, pytest.raises(InvalidInput, match="needs a reason"):
        review_service.review_frame(s, ids[1], curator, "reject")
    with transaction(sessions) as s, pytest.raises(InvalidInput, match="decision must be"):
        review_service.review_frame(s, ids[1], curator, "maybe")
    with transaction(sessions) as s:
        review_service.review_frame(s, ids[1], curator, "reject", "no illusion", revision=1)
        review_service.review_frame(s, ids[1], curator, "reset")  # undo
    with sessions() as s:
        assert s.get(Frame, ids[1]).state == FrameState.prefiltered
        actions = s.scalars(select(AuditEntry.action).order_by(AuditEntry.id)).all()
        assert actions == ["review.approve", "review.reject", "review.reset"]
        entry = s.scalar(select(AuditEntry).where(AuditEntry.action == "review.reject"))
        assert entry.user_id == curator.id and entry.detail == {"reason": "no illusion", "before": "prefiltered",
                                                                 "after": "rejected"}
        assert [r.decision.value for r in s.scalars(select(Review).order_by(Review.id))] == ["approve", "reject"]
        assert funnel_counts(s)["approved"] == 1
    with transaction(sessions) as s:
        s.get(Frame, ids[2]).state = FrameState.annotated
    with transaction(sessions) as s, pytest.raises(Conflict, match="is annotated"):
        review_service.review_frame(s, ids[2], curator, "reject", "blurry")


def test_bulk_review_succeeds_or_fails_per_item(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        ids = seed_frames(s)
        curator = user_service.create_user(s, "cu", "curator", "long-enough")
    with transaction(sessions) as s:
        results = review_service.review_many(s, [{"id": ids[0], "revision": 1}, {"id": ids[1], "revision": 7},
                                                 {"id": 9999}, {"nope": 1}], curator, "approve")
    assert [r["status"] for r in results] == [200, 409, 404, 400]
    assert results[1]["frame"]["revision"] == 1 and "changed since you loaded it" in results[1]["error"]
    with sessions() as s:
        assert [s.get(Frame, i).state for i in ids[:2]] == [FrameState.approved, FrameState.prefiltered]


def test_filters_by_state_verdict_and_answer(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        ids = seed_frames(s)
    with sessions() as s:
        items, total = review_service.list_review_items(s)
        assert total == 4 and items[0]["prefilter"]["metrics"] == {"laplacian_var": 0.0}
        assert [i["id"] for i in review_service.list_review_items(s, question=9, answer="yes")[0]] == [ids[0], ids[2]]
        assert [i["id"] for i in review_service.list_review_items(s, question=9, answer="no")[0]] == [ids[1], ids[3]]
        assert review_service.list_review_items(s, question=1, answer="unknown")[1] == 4
        assert [i["id"] for i in review_service.list_review_items(s, keep="null")[0]] == [ids[1], ids[3]]
        assert review_service.list_review_items(s, keep="false", limit=1, offset=1)[0][0]["id"] == ids[2]
        assert review_service.list_review_items(s, state="approved")[1] == 0
        for bad in ({"state": "annotated"}, {"question": 13, "answer": "yes"}, {"question": 2}, {"keep": "maybe"}):
            with pytest.raises(InvalidInput):
                review_service.list_review_items(s, **bad)


def test_review_api(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        ids = seed_frames(s)
    curator = {"Authorization": f"Bearer {tokens['curator']}"}
    page = client.get("/api/v1/review/frames?limit=2", headers=curator).json
    assert page["total"] == 4 and len(page["items"]) == 2 and len(page["questions"]) == 12
    assert "watermark" in page["reasons"]
    item = page["items"][0]
    ok = client.post(f"/api/v1/frames/{item['id']}/review", headers=curator,
                     json={"decision": "reject", "reason": "blurry", "revision": item["revision"]})
    assert ok.status_code == 200 and ok.json["state"] == "rejected"
    assert ok.json["last_review"]["reason"] == "blurry" and ok.json["last_review"]["user"] == "curator"
    stale = client.post(f"/api/v1/frames/{item['id']}/review", headers=curator,
                        json={"decision": "approve", "revision": item["revision"]})
    assert stale.status_code == 409 and stale.json["frame"]["state"] == "rejected"
    bulk = client.post("/api/v1/review/bulk", headers=curator,
                       json={"decision": "approve", "items": [{"id": i} for i in ids[1:]]})
    assert [r["status"] for r in bulk.json["results"]] == [200, 200, 200]
    assert client.get("/api/v1/stats/funnel", headers=curator).json["approved"] == 3
    annotator = {"Authorization": f"Bearer {tokens['annotator']}"}
    assert client.post(f"/api/v1/frames/{ids[0]}/review", headers=annotator, json={"decision": "approve"}).status_code == 403


def test_a_decision_on_a_stale_read_is_refused_and_overwrites_nothing(sessions) -> None:  # type: ignore[no-untyped-def]
    """Two curators load the same frame; the second to decide gets a conflict, not a silent overwrite."""
    from dataset.services.frames import update_frame

    with transaction(sessions) as s:
        ids = seed_frames(s, n=1)
        curator = user_service.create_user(s, "cu", "curator", "long-enough")
    slow = sessions()
    stale = slow.get(Frame, ids[0])  # curator A has the page open at revision 1
    with transaction(sessions) as s:
        review_service.review_frame(s, ids[0], curator, "reject", "blurry", revision=1)  # curator B is quicker
    with pytest.raises(Conflict):
        review_service.review_frame(slow, ids[0], curator, "approve", revision=1)
    with pytest.raises(Conflict):  # the write itself is a compare-and-swap on the revision
        update_frame(slow, stale, state=FrameState.approved)
    slow.rollback()
    slow.close()
    with sessions() as s:
        frame = s.get(Frame, ids[0])
        assert (frame.state, frame.revision) == (FrameState.rejected, 2)
