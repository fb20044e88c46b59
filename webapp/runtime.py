"""The live objects one process needs, built once from the settings: DB, media store, job queue."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from dataset.db import make_engine, make_session_factory
from dataset.media import MediaStore
from dataset.settings import Settings
from dataset.tables import Job, User


@dataclass
class Runtime:
    settings: Settings
    engine: Engine = field(init=False)
    sessions: sessionmaker[Session] = field(init=False)
    media: MediaStore = field(init=False)

    def __post_init__(self) -> None:
        self.engine = make_engine(self.settings.database_url)
        self.sessions = make_session_factory(self.engine)
        self.media = MediaStore(self.settings.media_root)

    @cached_property
    def queue(self):  # type: ignore[no-untyped-def]
        from webapp.jobs.queue import JobQueue  # the queue pulls in every job handler: only on use

        return JobQueue(self)

    def submit(self, session: Session, kind: str, params: dict[str, Any], user: User | None) -> Job:
        """Queue a job (its row commits with ``session``); see :meth:`JobQueue.submit`."""
        return self.queue.submit(session, kind, params, user)

    def close(self) -> None:
        self.engine.dispose()


def runtime() -> Runtime:
    """The runtime of the app serving the current request."""
    from flask import current_app

    return current_app.extensions["runtime"]
