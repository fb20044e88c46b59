"""Huey as the job queue: SQLite storage by default, Redis when ``queue_url`` is redis://…"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any

from huey import Huey, RedisHuey, SqliteHuey
from sqlalchemy import event
from sqlalchemy.orm import Session

from dataset.db import transaction
from dataset.models import Job, User
from dataset.services import jobs as job_rows
from webapp.jobs.handlers import HANDLERS

if TYPE_CHECKING:
    from webapp.runtime import Runtime

log = logging.getLogger(__name__)
QUEUES = ("default", "train")
# Kinds that take hours go to a queue of their own, so other jobs never wait behind them.
TRAIN_KINDS = frozenset({"train"})


def make_huey(queue_url: str, sqlite_path: str, name: str) -> Huey:
    # Results live in the job rows, so Huey keeps none (results=False).
    if queue_url.startswith(("redis://", "rediss://", "unix://")):
        return RedisHuey(name, url=queue_url, results=False)
    if queue_url:
        raise ValueError(f"unsupported queue_url {queue_url!r}: use redis://… or leave empty for SQLite")
    return SqliteHuey(name, filename=sqlite_path, results=False)


def queue_for(kind: str) -> str:
    return "train" if kind in TRAIN_KINDS else "default"


class JobQueue:
    """Creates job rows and hands their ids to Huey; runs them in workers.

    Two Huey queues: ``default`` (named ``queue_name``) and ``train`` (``<queue_name>-train``),
    each with its own workers (``illusion-studio worker --queue train``).
    """

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        s = runtime.settings
        self.hueys = {"default": make_huey(s.queue_url, str(s.queue_path), s.queue_name),
                      "train": make_huey(s.queue_url, str(s.queue_path), f"{s.queue_name}-train")}
        self.huey = self.hueys["default"]
        self._tasks = {name: huey.task(name="run_job")(self._execute) for name, huey in self.hueys.items()}

    def enqueue(self, job_id: int, kind: str) -> None:
        """Hand a job's id to its queue (the row must be committed and queued)."""
        self._tasks[queue_for(kind)](job_id)

    def submit(self, session: Session, kind: str, params: dict[str, Any], user: User | None) -> Job:
        """Create the row in the caller's transaction; enqueue once it commits.

        Enqueueing after commit means a worker never sees an id whose row is not there yet.
        """
        if kind not in HANDLERS:
            raise ValueError(f"unknown job kind {kind!r}")
        job = job_rows.create_job(session, kind, params, user)
        job_id = job.id
        event.listen(session, "after_commit", lambda _s: self.enqueue(job_id, kind), once=True)
        return job

    def retry(self, job_id: int) -> Job:
        with transaction(self.runtime.sessions) as s:
            job = job_rows.mark_for_retry(s, job_id)
        self.enqueue(job_id, job.kind)
        return job

    def _execute(self, job_id: int) -> str:
        return job_rows.execute_job(job_id, HANDLERS, self.runtime).value

    def run_worker(self, concurrency: int = 1, queue: str = "default") -> None:
        """Run a consumer of ``queue`` until SIGINT/SIGTERM, with a heartbeat thread that also reaps lost jobs."""
        huey = self.hueys[queue]
        me = job_rows.worker_id()
        self._reap()
        stop = threading.Event()

        def beat() -> None:
            while not stop.wait(job_rows.HEARTBEAT_S):
                try:
                    with transaction(self.runtime.sessions) as s:
                        job_rows.heartbeat(s, me)
                    self._reap()
                except Exception:  # a DB hiccup must not kill the heartbeat
                    log.exception("heartbeat failed")

        threading.Thread(target=beat, name="heartbeat", daemon=True).start()
        # Said once a consumer thread is listening, so scripts (and tests) know when jobs will be taken.
        huey.on_startup()(lambda: log.info("worker %s ready", me))
        consumer = huey.create_consumer(workers=concurrency, worker_type="thread", periodic=False,
                                             max_delay=1.0)
        try:
            consumer.run()
        finally:
            stop.set()

    def _reap(self) -> None:
        with transaction(self.runtime.sessions) as s:
            lost = job_rows.reap_lost_jobs(s)
        for job_id in lost:
            log.warning("job %s lost its worker; marked interrupted (retry it)", job_id)
