"""A scratch workspace holding one approved frame of a synthetic scene, for benchmarks."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sqlalchemy import select, update

from dataset.db import migrate, transaction
from dataset.models import Frame, FrameState
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.ingest import ingest_params
from dataset.settings import load_settings
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


def approved_frame_workspace(home: Path, scene: Path, **settings: Any) -> tuple[Runtime, int, int]:
    """A workspace in ``home`` with ``scene`` ingested (as the real job does) and its first frame
    approved, plus an annotator named ``bench``; returns (runtime, frame id, user id)."""
    home.mkdir(parents=True)
    rt = Runtime(load_settings(home, **settings))
    migrate(rt.settings.database_url)
    with transaction(rt.sessions) as s:
        rt.submit(s, "ingest", ingest_params(str(scene), fps=None, dedup_hamming=None), None)
    job_service.run_queued_jobs(HANDLERS, rt)
    with transaction(rt.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))
        frame_id = s.scalar(select(Frame.id).order_by(Frame.index))
        user_id = user_service.create_user(s, "bench", "annotator", "bench-password").id
    return rt, frame_id, user_id
