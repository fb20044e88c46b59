"""The scale paths: keyset pages, the newest verdict kept on the frame, maintained counts
and migration 0002 — checked against the queries they replace, on both databases."""

from __future__ import annotations

import json
from typing import Any

import pytest
from alembic import command
from sqlalchemy import func, select, text, update

from benchmarks.scale import seed
from dataset.db import alembic_config, make_engine, make_session_factory, transaction
from dataset.services import review as review_service
from dataset.services import sample_review
from dataset.services import users as user_service
from dataset.services.errors import InvalidInput
from dataset.services.frames import frames_page, funnel_counts
from dataset.tables import (
    Frame,
    FrameCount,
    FrameState,
    Job,
    PrefilterResult,
    Sample,
    SampleCount,
    SampleState,
    SourceKind,
    Video,
)

_STATES = [FrameState.prefiltered, FrameState.approved, FrameState.rejected, FrameState.prefiltered,
           FrameState.ingested, FrameState.prefiltered, FrameState.deleted]


def _seed(s: Any, videos: int = 3, per_video: int = 7) -> list[int]:
    """Frames in several states; most with one verdict, some with two (the newest wins), some none."""
    ids = []
    for v in range(videos):
        video = Video(name=f"v{v}", source_kind=SourceKind.web, content_sha256=f"{v}".ljust(64, "0"))
        s.add(video)
        s.flush()
        # Indexes out of insertion order, so id order and (video, index) order differ.
        for i in reversed(range(per_video)):
            frame = Frame(video_id=video.id, index=i, time_s=i / 2, width=8, height=8, content_sha256=f"{v}-{i}",
                          media_key="k", state=_STATES[(i + v) % len(_STATES)])
            s.add(frame)
            s.flush()
            ids.append(frame.id)
            for attempt in range((i + v) % 3):  # 0, 1 or 2 verdicts
                answers = [None] * 12
                answers[8] = (i + attempt) % 2 == 0
                s.add(PrefilterResult(frame_id=frame.id, backend="b", model_id="m", prompt_version=f"v{attempt}",
                                      answers=answers, keep=[True, False, None][(i + attempt) % 3]))
            s.flush()
    return ids


def _reference(s: Any, *, states: tuple[FrameState, ...], keep: str | None = None,
               question: int | None = None, answer: str | None = None) -> list[int]:
    """The review grid's frames computed as before 0002: group every verdict, take each frame's newest."""
    newest = dict(s.execute(select(PrefilterResult.frame_id, func.max(PrefilterResult.id))
                            .group_by(PrefilterResult.frame_id)).all())
    results = {r.id: r for r in s.scalars(select(PrefilterResult))}
    out = []
    for frame in s.scalars(select(Frame).order_by(Frame.video_id, Frame.index)):
        result = results.get(newest.get(frame.id))
        verdict = result.keep if result else None
        if frame.state not in states:
            continue
        if keep is not None and verdict != {"true": True, "false": False, "null": None}[keep]:
            continue
        if question is not None:
            value = result.answers[question - 1] if result and len(result.answers) >= question else None
            if value != {"yes": True, "no": False, "unknown": None}[answer]:
                continue
        out.append(frame.id)
    return out


def _walk(s: Any, limit: int, **filters: Any) -> tuple[list[int], list[int]]:
    """Every page forwards by ``after`` and back by ``before``: the ids in order, both ways."""
    forward, listing = [], review_service.review_page(s, limit=limit, **filters)
    assert listing.prev is None  # the first page has nothing before it
    pages = [listing]
    while True:
        forward += [i["id"] for i in listing.items]
        if listing.next is None:
            break
        listing = review_service.review_page(s, limit=limit, after=listing.next, **filters)
        assert len(listing.items) > 0
        pages.append(listing)
    backward = [i["id"] for i in listing.items]
    while listing.prev is not None:
        listing = review_service.review_page(s, limit=limit, before=listing.prev, **filters)
        backward = [i["id"] for i in listing.items] + backward
    return forward, backward


FILTERS = [{}, {"state": "all"}, {"keep": "true"}, {"keep": "false"}, {"keep": "null", "state": "all"},
           {"state": "rejected"}, {"question": 9, "answer": "yes"}, {"question": 9, "answer": "unknown", "state": "all"}]


@pytest.mark.parametrize("filters", FILTERS, ids=lambda f: "&".join(f"{k}={v}" for k, v in f.items()) or "default")
def test_review_pages_match_the_grouped_query(sessions, filters: dict[str, Any]) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        _seed(s)
    with sessions() as s:
        state = filters.get("state", "prefiltered")
        states = review_service.REVIEWABLE if state == "all" else (FrameState(state),)
        expected = _reference(s, states=states, keep=filters.get("keep"), question=filters.get("question"),
                              answer=filters.get("answer"))
        assert expected, "the seed should give every filter something to show"
        for limit in (1, 2, len(expected), len(expected) + 5):
            forward, backward = _walk(s, limit, **filters)
            assert forward == expected and backward == expected
        whole = review_service.review_page(s, limit=500, **filters)
        assert whole.total == len(expected) and whole.total_exact
        assert (whole.prev, whole.next) == (None, None)
        for offset in range(len(expected) + 2):  # offsets (old deep links) give the same slices
            assert [i["id"] for i in review_service.review_page(s, limit=2, offset=offset, **filters).items] == \
                expected[offset:offset + 2]
        past = review_service.review_page(s, limit=2, offset=len(expected) + 3, **filters)
        assert past.items == [] and past.next is None
        back = review_service.review_page(s, limit=2, before=past.prev, **filters)
        assert [i["id"] for i in back.items] == expected[-2:]


def test_rows_that_leave_between_pages_are_neither_skipped_nor_repeated(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        _seed(s, videos=4)
        curator = user_service.create_user(s, "cu", "curator", "long-enough")
    with sessions() as s:
        expected = _reference(s, states=(FrameState.prefiltered,))
        first = review_service.review_page(s, limit=3)
    seen = [i["id"] for i in first.items]
    with transaction(sessions) as s:
        for item in first.items:  # the curator decides the whole page: it leaves the filter
            review_service.review_frame(s, item["id"], curator, "approve")
        following = expected[3:]
        s.execute(update(Frame).where(Frame.id == following[0]).values(state=FrameState.deleted))  # and one is deleted
    with sessions() as s:
        page = review_service.review_page(s, limit=3, after=first.next)
        assert [i["id"] for i in page.items] == following[1:4]
        assert page.prev is None  # nothing before it is still in the filter
        rest = seen + [following[0]]
        while page.items:
            rest += [i["id"] for i in page.items]
            if page.next is None:
                break
            page = review_service.review_page(s, limit=3, after=page.next)
        assert rest == expected
        assert review_service.review_page(s, limit=3).total == len(expected) - 4


def test_bad_cursors_are_clear_errors(sessions) -> None:  # type: ignore[no-untyped-def]
    with sessions() as s:
        for bad in ({"after": "x"}, {"after": "1"}, {"before": "1-2-3"}, {"after": "1-2", "before": "1-2"}):
            with pytest.raises(InvalidInput, match="after|before"):
                review_service.review_page(s, **bad)


def test_frames_and_samples_pages(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        ids = _seed(s)
        for n, frame_id in enumerate(ids[:9]):
            s.add(Sample(frame_id=frame_id, annotation_version=1, state=list(SampleState)[n % 3], flagged=n % 2 == 0))
    with sessions() as s:
        order = s.scalars(select(Frame.id).where(Frame.state == FrameState.prefiltered)
                          .order_by(Frame.video_id, Frame.index)).all()
        items, total, page = frames_page(s, state=FrameState.prefiltered, limit=2)
        walked = [f["id"] for f in items]
        while page.next:
            items, total, page = frames_page(s, state=FrameState.prefiltered, limit=2, after=page.next)
            walked += [f["id"] for f in items]
        assert walked == order and total == len(order)
        for state, flagged in ((None, None), ("generated", None), (None, True), ("accepted", False)):
            query = select(Sample.id).order_by(Sample.id)
            if state:
                query = query.where(Sample.state == SampleState(state))
            if flagged is not None:
                query = query.where(Sample.flagged.is_(flagged))
            expected = s.scalars(query).all()
            items, total, page = sample_review.samples_page(s, state=state, flagged=flagged, limit=2)
            walked = [i["id"] for i in items]
            while page.next:
                items, total, page = sample_review.samples_page(s, state=state, flagged=flagged, limit=2, after=page.next)
                walked += [i["id"] for i in items]
            assert walked == expected and total == len(expected)


def _recount(s: Any) -> tuple[dict[Any, int], dict[Any, int]]:
    frames = {(v, st, -1 if k is None else int(k)): n for v, st, k, n in s.execute(
        select(Frame.video_id, Frame.state, Frame.prefilter_keep, func.count())
        .group_by(Frame.video_id, Frame.state, Frame.prefilter_keep))}
    samples = {(st, f): n for st, f, n in s.execute(
        select(Sample.state, Sample.flagged, func.count()).group_by(Sample.state, Sample.flagged))}
    kept_frames = {(c.video_id, c.state, c.keep): c.n for c in s.scalars(select(FrameCount))}
    kept_samples = {(c.state, c.flagged): c.n for c in s.scalars(select(SampleCount))}
    assert kept_frames == frames and kept_samples == samples
    return kept_frames, kept_samples


def test_counts_follow_every_writer(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        ids = _seed(s)
        s.add(Sample(frame_id=ids[0], annotation_version=1))
    with transaction(sessions) as s:
        _recount(s)
        s.execute(update(Frame).where(Frame.id.in_(ids[:5])).values(state=FrameState.approved))  # a script's bulk write
        s.add(PrefilterResult(frame_id=ids[6], backend="b", model_id="m", prompt_version="v9", keep=True))
        s.execute(update(Sample).values(flagged=True))
    with transaction(sessions) as s:
        _recount(s)
        assert s.get(Frame, ids[6]).prefilter_keep is True
        s.execute(Video.__table__.delete().where(Video.name == "v0"))  # cascades to its frames and samples
    with sessions() as s:
        frames, samples = _recount(s)
        assert all(n > 0 for n in frames.values()) and samples == {}
        assert funnel_counts(s)["frames"] == s.scalar(select(func.count()).select_from(Frame)
                                                      .where(Frame.state != FrameState.deleted))


def test_migration_upgrades_a_populated_database(db_url: str) -> None:
    cfg = alembic_config(db_url)
    command.upgrade(cfg, "0001")
    engine = make_engine(db_url)
    with engine.begin() as conn:
        seeded = seed(conn, 2500)  # the benchmark's seed: every table, in the paper's proportions
    cfg.attributes["backfill_batch"] = 300  # many batches, and a last partial one
    command.upgrade(cfg, "head")
    sessions = make_session_factory(engine)
    with sessions() as s:
        newest = dict(s.execute(select(PrefilterResult.frame_id, func.max(PrefilterResult.id))
                                .group_by(PrefilterResult.frame_id)).all())
        keeps = dict(s.execute(select(PrefilterResult.id, PrefilterResult.keep)).all())
        frames = s.execute(select(Frame.id, Frame.prefilter_result_id, Frame.prefilter_keep)).all()
        assert len(frames) == seeded["counts"]["frame"] == 2500
        assert all(rid == newest.get(fid) and keep == keeps.get(rid) for fid, rid, keep in frames)
        assert sum(rid is not None for _, rid, _ in frames) == len(newest) > 2000
        _recount(s)
    with transaction(sessions) as s:  # the triggers take over after the backfill
        frame_id = frames[0][0]
        s.add(PrefilterResult(frame_id=frame_id, backend="b", model_id="m", prompt_version="v9", keep=False))
        s.add(Job(kind="prefilter", params={}))
    with sessions() as s:
        assert s.get(Frame, frame_id).prefilter_keep is False
        _recount(s)
    command.downgrade(cfg, "0001")
    with engine.connect() as conn:
        assert "prefilter_keep" not in list(conn.execute(text("SELECT * FROM frames LIMIT 0")).keys())
        assert conn.execute(text("SELECT count(*) FROM frames")).scalar() == 2500
    engine.dispose()


@pytest.mark.parametrize("sparse", [False, True])
def test_prefilter_claims_the_backlog_in_keyed_pages(sessions, monkeypatch: pytest.MonkeyPatch, sparse: bool) -> None:  # type: ignore[no-untyped-def]
    from dataset.services import jobs as job_service
    from dataset.services import prefilter

    monkeypatch.setattr(prefilter, "CLAIM_PAGE", 3)  # pages end inside chunks and inside videos
    with transaction(sessions) as s:
        _seed(s, videos=3, per_video=21)
    with transaction(sessions) as s:
        backlog = s.execute(select(Frame.id, Frame.video_id).where(Frame.state == FrameState.ingested)
                            .order_by(Frame.video_id, Frame.index)).all()
        jobs = prefilter.launch_prefilter(s, lambda s_, kind, params, user: job_service.create_job(s_, kind, params, user),
                                          None, chunk=2, sparse=sparse)
    with sessions() as s:
        claimed = [fid for job in jobs for fid in s.get(Job, job.id).params["frame_ids"]]
        assert claimed == [fid for fid, _ in backlog]
        if sparse:
            by_video = {}
            for fid, vid in backlog:
                by_video.setdefault(vid, []).append(fid)
            assert [s.get(Job, j.id).params["frame_ids"] for j in jobs] == list(by_video.values())
        else:
            assert [len(s.get(Job, j.id).params["frame_ids"]) for j in jobs][:-1] == [2] * (len(jobs) - 1)
        owners = dict(s.execute(select(Frame.id, Frame.prefilter_job_id).where(Frame.state == FrameState.ingested)).all())
        assert all(owners[fid] == job.id for job in jobs for fid in s.get(Job, job.id).params["frame_ids"])


@pytest.mark.slow
def test_bench_scale_reports_every_route_at_both_sizes(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from click.testing import CliRunner

    from webapp.cli import main

    result = CliRunner().invoke(main, ["bench", "scale", "--frames", "2000", "--repeats", "2", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    sqlite = report["backends"]["sqlite"]
    assert report["frames"] == 2000 and sqlite["tenth"]["frames"] == 1000
    assert sqlite["counts"]["frame"] == 2000 and sqlite["counts"]["sample"] > 0
    assert set(sqlite["routes"]) == set(sqlite["tenth"]["routes"]) and len(sqlite["routes"]) >= 20
    assert all(0 < t["p50_ms"] <= t["p95_ms"] for t in sqlite["routes"].values())
