"""Job rows: the database mirror of every long step (state, progress, log, result).

The queue (Huey) only carries a job id; everything a person wants to see lives in the row, so a
job survives a restarted queue, and a job whose worker died is found and made retryable.
"""

from __future__ import annotations

import os
import socket
import time
import traceback
from collections.abc import Callable, Collection
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import timedelta
from typing import Any, Protocol

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from dataset.db import transaction
from dataset.media import MediaStore
from dataset.redact import redacted, redactor_for
from dataset.services.errors import Conflict, NotFound, ServiceError
from dataset.settings import Settings
from dataset.tables import Job, JobState, RunState, User, utcnow

LOG_LIMIT = 200_000  # characters kept of a job's log; the head is dropped first
HEARTBEAT_S = 10.0
STALE_AFTER_S = 60.0  # a running job without a heartbeat for this long has lost its worker


def worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def create_job(session: Session, kind: str, params: dict[str, Any], user: User | None) -> Job:
    job = Job(kind=kind, params=params, created_by_id=user.id if user else None)
    session.add(job)
    session.flush()
    return job


def get_job(session: Session, job_id: int) -> Job:
    job = session.get(Job, job_id)
    if job is None:
        raise NotFound(f"no job {job_id}")
    return job


_ERROR_CHARS = 300


def user_error(exc: BaseException, redact: Callable[[str], str]) -> str:
    """What a failed job tells its user: the exception's first line, server paths rewritten by
    ``redact`` (the workspace's :class:`dataset.redact.Redactor`), at most _ERROR_CHARS characters.
    Bad-input errors (ValueError, OSError, ServiceError) are worded for people and shown bare;
    any other exception is a bug and keeps its class name. The full traceback stays in the log."""
    text = (str(exc).strip().splitlines() or [""])[0]
    if not isinstance(exc, (ValueError, OSError, ServiceError)) or not text:
        text = f"{type(exc).__name__}: {text}".rstrip(": ")
    text = redact(text)
    return text if len(text) <= _ERROR_CHARS else text[:_ERROR_CHARS - 1] + "…"


def job_json(job: Job, *, with_log: bool = False) -> dict[str, Any]:
    """What answers say of a job. Its parameters and result (a command line's paths), its error and
    its log (tracebacks, a trainer's output) come from outside the app's own answers: shown through
    :func:`dataset.redact.redacted`, which keeps server paths out of a request's answer.

    ``state`` is the row's, except ``cancelled`` for the ended train job of a cancelled run (the row
    says failed: the handler raised); ``took_s``: the seconds every attempt ran, once it has ended."""
    data: dict[str, Any] = {
        "id": job.id, "kind": job.kind, "state": _state(job), "progress": job.progress,
        "params": redacted(job.params), "result": redacted(job.result), "error": redacted(job.error), "attempts": job.attempts,
        "worker": job.worker, "created_by": job.created_by.name if job.created_by else None,
        "created_at": _iso(job.created_at), "started_at": _iso(job.started_at),
        "finished_at": _iso(job.finished_at), "took_s": _took_s(job),
    }
    if with_log:
        data["log"] = redacted(job.log)
    return data


def _iso(value: Any) -> str | None:
    return value.isoformat() + "Z" if value is not None else None


def _state(job: Job) -> str:
    """The job's state as people read it: a cancel is a person's decision, not a failure."""
    run = job.training_run if job.kind == "train" and job.state == JobState.failed else None
    return "cancelled" if run is not None and run.state == RunState.cancelled else job.state.value


def _took_s(job: Job) -> float | None:
    """Seconds the job ran over all its attempts once it has ended; None before, or when it never ran."""
    if not job.state.finished:
        return None
    last = (job.finished_at - job.started_at).total_seconds() if job.started_at and job.finished_at else 0.0
    return round((job.ran_s or 0.0) + last, 1) if job.ran_s or job.started_at else None


def mark_for_retry(session: Session, job_id: int) -> Job:
    """Put a failed or interrupted job back in the queued state (the caller enqueues it)."""
    job = get_job(session, job_id)
    if job.state not in (JobState.failed, JobState.interrupted):
        raise Conflict(f"job {job_id} is {job.state.value}; only failed or interrupted jobs can be retried")
    if job.started_at is not None and job.finished_at is not None:  # the attempt that ended counts in "took"
        job.ran_s += max(0.0, (job.finished_at - job.started_at).total_seconds())
    job.state, job.error, job.progress, job.worker, job.finished_at = JobState.queued, None, 0.0, None, None
    job.started_at = None  # the next attempt's, when a worker claims it
    return job


def reap_lost_jobs(session: Session, *, now_host: str | None = None) -> list[int]:
    """Mark running jobs whose worker is gone as ``interrupted``; returns their ids.

    A worker is gone when it runs on this host and its process no longer exists, or when it has
    sent no heartbeat for :data:`STALE_AFTER_S` (a worker on another machine).
    """
    host = now_host or socket.gethostname()
    cutoff = utcnow() - timedelta(seconds=STALE_AFTER_S)
    lost = []
    for job in session.scalars(select(Job).where(Job.state == JobState.running)):
        owner_host, _, pid = (job.worker or "").rpartition(":")
        dead_here = owner_host == host and pid.isdigit() and not _pid_alive(int(pid))
        silent = job.heartbeat_at is None or job.heartbeat_at < cutoff
        if dead_here or silent:
            job.state = JobState.interrupted
            job.error = f"worker {job.worker} stopped while running this job; retry it"
            job.finished_at = utcnow()
            lost.append(job.id)
    return lost


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def heartbeat(session: Session, worker: str) -> None:
    session.execute(update(Job).where(Job.worker == worker, Job.state == JobState.running)
                    .values(heartbeat_at=utcnow()))


class JobEnv(Protocol):
    """What jobs run against: the data layer, settings, and a way to queue follow-up jobs."""

    sessions: sessionmaker[Session]
    media: MediaStore
    settings: Settings

    def submit(self, session: Session, kind: str, params: dict[str, Any], user: User | None) -> Job: ...


@dataclass
class JobContext:
    """What a job handler gets: its parameters, its environment, and a way to report progress."""

    job_id: int
    params: dict[str, Any]
    env: JobEnv
    _last_flush: float = field(default=0.0, repr=False)
    _pending_log: list[str] = field(default_factory=list, repr=False)
    _progress: float = field(default=0.0, repr=False)

    @property
    def sessions(self) -> sessionmaker[Session]:
        return self.env.sessions

    @property
    def media(self) -> MediaStore:
        return self.env.media

    @property
    def settings(self) -> Any:
        return self.env.settings

    def log(self, message: str) -> None:
        self._pending_log.append(f"{time.strftime('%H:%M:%S')} {message}")
        self._flush(force=False)

    def progress(self, fraction: float, message: str | None = None) -> None:
        """Report progress in 0..1; written to the row at most a few times a second."""
        self._progress = min(max(float(fraction), 0.0), 1.0)
        if message:
            self._pending_log.append(f"{time.strftime('%H:%M:%S')} {message}")
        self._flush(force=False)

    def finish(self, message: str | None, progress: float | None = None) -> None:
        """Write what is pending now (the job is about to end)."""
        if message:
            self._pending_log.append(message)
        if progress is not None:
            self._progress = progress
        self._flush(force=True)

    def _flush(self, *, force: bool) -> None:
        now = time.monotonic()
        if not force and now - self._last_flush < 0.1:
            return
        self._last_flush = now
        with transaction(self.sessions) as s:
            job = s.get(Job, self.job_id)
            if job is None:
                return
            job.progress, job.heartbeat_at = self._progress, utcnow()
            if self._pending_log:
                job.log = (job.log + "\n".join(self._pending_log) + "\n")[-LOG_LIMIT:]
                self._pending_log.clear()


Handler = Callable[[JobContext], dict[str, Any]]


def execute_job(job_id: int, handlers: dict[str, Handler], env: JobEnv) -> JobState:
    """Run job ``job_id`` once, mirroring everything into its row.

    Idempotent on delivery: a job that already succeeded, or that another live worker runs, is
    left alone. Handlers must themselves be idempotent so that a retry after a crash does not
    duplicate their effects.
    """
    me = worker_id()
    sessions = env.sessions
    with transaction(sessions) as s:
        # Claim with one conditional UPDATE: of two workers handed the same id, exactly one runs it.
        claimed = s.execute(update(Job).where(Job.id == job_id, Job.state == JobState.queued)
                            .values(state=JobState.running, worker=me, attempts=Job.attempts + 1,
                                    started_at=utcnow(), heartbeat_at=utcnow())
                            .execution_options(synchronize_session=False)).rowcount
        job = s.get(Job, job_id)
        if not claimed:
            return job.state if job else JobState.failed
        job.log += f"--- attempt {job.attempts} on {me}\n"
        kind, params = job.kind, dict(job.params)
    ctx = JobContext(job_id, params, env)
    try:
        handler = handlers.get(kind)
        if handler is None:
            raise LookupError(f"no handler for job kind {kind!r}")
        result = handler(ctx)
    except Exception as exc:  # a job's failure is data for the user, not a worker crash
        # An ending worded for people (a cancelled or diverged run, bad input) is its own message;
        # a bug keeps its traceback.
        ctx.finish(f"{type(exc).__name__}: {exc}" if isinstance(exc, ServiceError) else traceback.format_exc())
        return _finish(sessions, job_id, me, state=JobState.failed, error=user_error(exc, redactor_for(env.settings)))
    ctx.finish(None, progress=1.0)
    return _finish(sessions, job_id, me, state=JobState.succeeded, result=result)


def _finish(sessions: sessionmaker[Session], job_id: int, me: str, **values: Any) -> JobState:
    """Record the outcome, unless the job was taken from this worker meanwhile (reaped and retried)."""
    with transaction(sessions) as s:
        s.execute(update(Job).where(Job.id == job_id, Job.worker == me, Job.state == JobState.running)
                  .values(finished_at=utcnow(), **values).execution_options(synchronize_session=False))
        return s.get(Job, job_id).state


def run_queued_jobs(handlers: dict[str, Handler], env: JobEnv, *, workers: int = 1,
                    only: Collection[int] | None = None) -> list[tuple[int, JobState]]:
    """Run every queued job in this process, oldest first, including jobs they queue — or, with
    ``only``, just those of these ids still queued (what one caller launched, when another process
    drains the same database) —; then return each job it took with its final state, in the order taken.

    ``workers`` threads take jobs at once (a training job's work runs in processes of its own, so
    two threads train two runs side by side). The database is the source of truth, so this works
    without the queue: a worker that later receives the same ids finds them finished and does nothing.
    """
    taken: list[int] = []

    def drain() -> None:
        while True:
            query = select(Job.id).where(Job.state == JobState.queued)
            if only is not None:
                query = query.where(Job.id.in_(list(only)))
            with env.sessions() as s:
                job_id = s.scalar(query.order_by(Job.id).limit(1))
            if job_id is None:
                return
            execute_job(job_id, handlers, env)
            taken.append(job_id)

    if workers == 1:
        drain()
    else:
        with ThreadPoolExecutor(workers, thread_name_prefix="jobs") as pool:
            for future in [pool.submit(drain) for _ in range(workers)]:
                future.result()
    # Final states from the rows: of two threads that raced for one job, the loser saw it running.
    ids = list(dict.fromkeys(taken))
    with env.sessions() as s:
        states = {job_id: state for job_id, state in s.execute(select(Job.id, Job.state).where(Job.id.in_(ids)))}
    return [(job_id, states[job_id]) for job_id in ids]
