"""The data layer on SQLite and PostgreSQL: migrations, constraints, and the queries services use."""

from __future__ import annotations

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import func, select, text
from sqlalchemy.exc import IntegrityError

from dataset.db import alembic_config, make_engine, migrate, schema_is_current, transaction
from dataset.services import audit
from dataset.services import users as user_service
from dataset.services.errors import Conflict, InvalidInput
from dataset.services.frames import funnel_counts, list_frames
from dataset.tables import AuditEntry, Base, Frame, FrameState, PrefilterResult, Role, SourceKind, User, Video


def _video(s, name: str = "v") -> Video:  # type: ignore[no-untyped-def]
    video = Video(name=name, source_kind=SourceKind.web, content_sha256=name.ljust(64, "0"), illusion_types=["picture"])
    s.add(video)
    s.flush()
    return video


def _frame(s, video: Video, index: int, state: FrameState = FrameState.ingested) -> Frame:  # type: ignore[no-untyped-def]
    frame = Frame(video_id=video.id, index=index, time_s=index / 2, width=64, height=48,
                  content_sha256=f"{index:064d}", media_key="k", state=state)
    s.add(frame)
    s.flush()
    return frame


def test_migrations_match_the_models(db_url: str) -> None:
    migrate(db_url)
    migrate(db_url)  # idempotent
    engine = make_engine(db_url)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == [], f"models and migrations disagree: {diff}"
    assert schema_is_current(engine)
    command.downgrade(alembic_config(db_url), "base")
    assert not schema_is_current(engine)
    migrate(db_url)
    assert schema_is_current(engine)
    engine.dispose()


@pytest.mark.password_hashing
def test_passwords_are_stored_as_scrypt_hashes(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        user_service.create_user(s, "ana", "curator", "long-enough")
    with transaction(sessions) as s:
        assert s.scalar(select(User.password_hash).where(User.name == "ana")).startswith("scrypt:")
        assert user_service.authenticate(s, "ana", "long-enough") is not None
        assert user_service.authenticate(s, "ana", "long-enougH") is None


def test_users_roles_and_tokens(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        user = user_service.create_user(s, "ana", "curator", "long-enough")
        token = user_service.issue_token(s, user, "script")
    with transaction(sessions) as s:
        assert user_service.authenticate(s, "ana", "long-enough").role == Role.curator
        assert user_service.authenticate(s, "ana", "wrong-password") is None
        assert user_service.user_for_token(s, token).name == "ana"
        assert user_service.user_for_token(s, token + "x") is None
        stored = s.scalar(select(User).where(User.name == "ana"))
        assert "long-enough" not in stored.password_hash
    with transaction(sessions) as s, pytest.raises(Conflict, match="already exists"):
        user_service.create_user(s, "ana", "admin", "long-enough")
    with transaction(sessions) as s, pytest.raises(InvalidInput, match="unknown role"):
        user_service.create_user(s, "bo", "superuser", "long-enough")


def test_database_enforces_constraints(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        video_id = _video(s).id
        _frame(s, s.get(Video, video_id), 0)
    with pytest.raises(IntegrityError), transaction(sessions) as s:
        _frame(s, s.get(Video, video_id), 0)  # one row per (video, index)
    with pytest.raises(IntegrityError), transaction(sessions) as s:
        s.execute(text("UPDATE frames SET state = 'bogus'"))  # CHECK constraint, not just Python
    with pytest.raises(IntegrityError), transaction(sessions) as s:
        s.execute(text("INSERT INTO frames (video_id, \"index\", time_s, width, height, content_sha256, media_key,"
                       " state, revision, assets, updated_at) VALUES (999, 1, 0, 1, 1, 'x', 'k', 'ingested', 1,"
                       " '{}', CURRENT_TIMESTAMP)"))  # foreign key


def test_deleting_a_video_deletes_its_frames(sessions) -> None:  # type: ignore[no-untyped-def]
    with transaction(sessions) as s:
        video = _video(s)
        for i in range(3):
            _frame(s, video, i)
    with transaction(sessions) as s:
        s.execute(Video.__table__.delete())
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(Frame)) == 0


def test_funnel_and_frame_listing(sessions) -> None:  # type: ignore[no-untyped-def]
    states = [FrameState.ingested, FrameState.prefiltered, FrameState.rejected, FrameState.approved,
              FrameState.annotated, FrameState.generated, FrameState.accepted, FrameState.deleted]
    with transaction(sessions) as s:
        video = _video(s)
        frames = [_frame(s, video, i, st) for i, st in enumerate(states)]
        for keep in (False, True):  # the newest verdict wins
            s.add(PrefilterResult(frame_id=frames[1].id, backend="heuristic", model_id="m", prompt_version="v1",
                                  answers=[None] * 12, keep=keep))
        audit.record(s, None, "review.approve", "frame", frames[3].id, reason="")
    with sessions() as s:
        assert funnel_counts(s) == {"videos": 1, "frames": 7, "prefiltered": 6, "approved": 4, "annotated": 3,
                                    "generated": 2, "accepted": 1}
        items, total = list_frames(s, limit=3)
        assert total == 8 and [f["index"] for f in items] == [0, 1, 2]
        assert items[0]["prefilter_keep"] is None and items[1]["prefilter_keep"] is True
        assert items[1]["time_s"] == 0.5 and items[1]["width"] == 64
        only, total = list_frames(s, state=FrameState.approved)
        assert total == 1 and only[0]["state"] == "approved"
        assert s.scalar(select(AuditEntry.action)) == "review.approve"
        with pytest.raises(InvalidInput):
            list_frames(s, limit=0)


def test_sqlite_runs_in_wal_mode(tmp_path) -> None:  # type: ignore[no-untyped-def]
    engine = make_engine(f"sqlite:///{tmp_path / 'w.db'}")
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    engine.dispose()
