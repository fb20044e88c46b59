"""Huey as the job queue: SQLite storage by default, Redis when ``queue_url`` is redis://…"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING, Any

from huey import Huey, RedisHuey, SqliteHuey
from sqlalchemy import event, select
from sqlalchemy.orm import Session, sessionmaker

from dataset.contained import resolve_storage
from dataset.db import transaction
from dataset.services import jobs as job_rows
from dataset.services.errors import Unavailable
from dataset.tables import Job, JobState, User
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


def check_reachable(huey: Huey) -> None:
    """Raise :class:`Unavailable` when the queue's storage cannot be read (Redis down, broken file)."""
    try:
        huey.storage.queue_size()
    except Exception as exc:  # redis.ConnectionError, sqlite3.DatabaseError, OSError …: all mean "down"
        raise Unavailable(f"the job queue is unreachable ({type(exc).__name__}); try again in a minute") from None


def pending_job_ids(huey: Huey) -> set[int]:
    """Job ids of the messages waiting in ``huey``'s queue."""
    return {int(task.args[0]) for task in huey.pending() if task.args}


class UnsentSweep:
    """Re-sends ``queued`` rows whose message is missing from one queue (lost in a queue outage).

    A row counts as unsent once two sweeps at least ``grace_s`` apart both found it queued with no
    message; the grace covers a message a worker has just taken but not yet claimed. Re-sending is
    safe because :func:`dataset.services.jobs.execute_job` claims with a compare-and-swap: a job
    sent twice still runs once. One sweep per queue name, over the kinds that queue carries.
    """

    def __init__(self, huey: Huey, send: Callable[[int], Any], kinds: Collection[str], grace_s: float) -> None:
        self.huey, self.send, self.kinds, self.grace_s = huey, send, tuple(kinds), grace_s
        self._missing_since: dict[int, float] = {}

    def __call__(self, sessions: sessionmaker[Session]) -> list[int]:
        """One sweep; returns the ids sent again."""
        now = time.monotonic()
        # Rows first, then messages: a row committed in between was enqueued before we look.
        with sessions() as s:
            queued = set(s.scalars(select(Job.id).where(Job.state == JobState.queued, Job.kind.in_(self.kinds))))
        missing = queued - pending_job_ids(self.huey)
        self._missing_since = {j: self._missing_since.get(j, now) for j in missing}
        due = sorted(j for j, since in self._missing_since.items() if now - since >= self.grace_s)
        for job_id in due:
            self.send(job_id)
            del self._missing_since[job_id]
        return due


class JobQueue:
    """Creates job rows and hands their ids to Huey; runs them in workers.

    Two Huey queues: ``default`` (named ``queue_name``) and ``train`` (``<queue_name>-train``),
    each with its own workers (``illusion-studio worker --queue train``) and its own sweep.
    """

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        s = runtime.settings
        self.hueys = {"default": make_huey(s.queue_url, str(s.queue_path), s.queue_name),
                      "train": make_huey(s.queue_url, str(s.queue_path), f"{s.queue_name}-train")}
        self.huey = self.hueys["default"]
        self._tasks = {name: huey.task(name="run_job")(self._execute) for name, huey in self.hueys.items()}
        self.sweeps = {name: UnsentSweep(huey, self._tasks[name], [k for k in HANDLERS if queue_for(k) == name],
                                         s.queue_resend_after_s)
                       for name, huey in self.hueys.items()}

    def enqueue(self, job_id: int, kind: str) -> None:
        """Hand a job's id to its queue (the row must be committed and queued)."""
        self._tasks[queue_for(kind)](job_id)

    def submit(self, session: Session, kind: str, params: dict[str, Any], user: User | None) -> Job:
        """Create the row in the caller's transaction; enqueue once it commits.

        Raises :class:`Unavailable` (503) while the queue is down, before any row is written.
        Enqueueing after commit means a worker never sees an id whose row is not there yet; a
        message lost between the commit and the queue is re-sent by the workers' sweep.
        """
        if kind not in HANDLERS:
            raise ValueError(f"unknown job kind {kind!r}")
        check_reachable(self.hueys[queue_for(kind)])
        job = job_rows.create_job(session, kind, params, user)
        self._send_after_commit(session, job.id, kind)
        return job

    def retry(self, session: Session, job_id: int) -> Job:
        """Put a failed or interrupted job back in the queue, in the caller's transaction."""
        job = job_rows.mark_for_retry(session, job_id)
        check_reachable(self.hueys[queue_for(job.kind)])
        self._send_after_commit(session, job_id, job.kind)
        return job

    def _send_after_commit(self, session: Session, job_id: int, kind: str) -> None:
        def send(_session: Session) -> None:
            try:
                self.enqueue(job_id, kind)
            except Exception:  # the row is committed; the sweep re-sends it once the queue is back
                log.warning("job %s is saved but could not be queued; a worker will re-send it", job_id,
                            exc_info=True)

        event.listen(session, "after_commit", send, once=True)

    def _execute(self, job_id: int) -> str:
        return job_rows.execute_job(job_id, HANDLERS, self.runtime).value

    def run_worker(self, concurrency: int = 1, queue: str = "default") -> None:
        """Run a consumer of ``queue`` until SIGINT/SIGTERM, with a heartbeat thread that also reaps
        lost jobs and re-sends the queue's queued jobs whose message was lost."""
        huey, sweep = self.hueys[queue], self.sweeps[queue]
        me = job_rows.worker_id()
        resolve_storage(self.runtime.settings)  # runs/ and evaluations/ as they are now (dataset.contained)
        self._reap()
        stop = threading.Event()
        interval = min(job_rows.HEARTBEAT_S, max(sweep.grace_s / 2, 0.5))

        def beat() -> None:
            while not stop.wait(interval):
                try:
                    with transaction(self.runtime.sessions) as s:
                        job_rows.heartbeat(s, me)
                    self._reap()
                    for job_id in sweep(self.runtime.sessions):
                        log.warning("job %s was queued without a message; sent it again", job_id)
                except Exception:  # a DB or queue hiccup must not kill the heartbeat
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
