"""The job queue with real worker processes: SQLite queue always, Redis when TEST_REDIS_URL is set."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

from click.testing import CliRunner
from sqlalchemy import func, select

from dataset.db import transaction
from dataset.redact import redactor_for
from dataset.services import jobs as job_service
from dataset.services.ingest import ingest_params
from dataset.settings import Settings
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, Job, JobState
from tests.workers import wait_for
from webapp.cli import main
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


def submit_import(rt: Runtime, path: Path) -> int:
    with transaction(rt.sessions) as s:
        return rt.queue.submit(s, "ingest", ingest_params(str(path), fps=None, dedup_hamming=None), None).id


def frame_count(rt: Runtime) -> int:
    with rt.sessions() as s:
        return s.scalar(select(func.count()).select_from(Frame))


def test_worker_runs_an_import_job(rt: Runtime, start_worker, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    [video] = write_synthetic_dataset(tmp_path / "synth", videos=1, seed=3, n_frames=6, width=128, height=72)
    job_id = submit_import(rt, video)
    start_worker()
    job = wait_for(rt, job_id, lambda j: j.state.finished)
    assert job.state == JobState.succeeded, job.error
    assert job.progress == 1.0 and job.attempts == 1
    assert job.result == {"video_id": job.result["video_id"], "video_name": video.name, "frames": 6, "new_frames": 6,
                          "dropped_duplicates": 0}
    assert "frame 5" in job.log
    assert frame_count(rt) == 6


def test_sigkilled_worker_leaves_the_job_retryable(rt: Runtime, start_worker, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    n = 40
    warmup, video = write_synthetic_dataset(tmp_path / "synth", videos=2, seed=5, n_frames=n, width=160, height=90)
    worker = start_worker()
    wait_for(rt, submit_import(rt, warmup), lambda j: j.state == JobState.succeeded)  # the worker is up and idle
    before = frame_count(rt)

    # Single-step the worker (SIGCONT for a few ms, then SIGSTOP) so the kill lands mid-job on any machine.
    worker.send_signal(signal.SIGSTOP)
    job_id = submit_import(rt, video)
    for _ in range(5000):
        worker.send_signal(signal.SIGCONT)
        time.sleep(0.002)
        worker.send_signal(signal.SIGSTOP)
        if frame_count(rt) > before:
            break
    worker.send_signal(signal.SIGKILL)
    worker.wait(timeout=10)
    partial = frame_count(rt) - before
    assert 0 < partial < n, "the kill must land mid-way for this test to mean anything"
    with rt.sessions() as s:
        assert s.get(Job, job_id).state == JobState.running  # what a crash leaves behind

    start_worker()  # a new worker notices the dead one and marks its job interrupted
    job = wait_for(rt, job_id, lambda j: j.state == JobState.interrupted, timeout=30)
    assert "retry" in job.error

    with transaction(rt.sessions) as s:
        rt.queue.retry(s, job_id)
    job = wait_for(rt, job_id, lambda j: j.state.finished)
    assert job.state == JobState.succeeded, job.error
    assert job.attempts == 2
    assert job.result["new_frames"] == n - partial
    assert frame_count(rt) == before + n  # nothing duplicated, nothing missing
    with rt.sessions() as s:
        keys = s.scalars(select(Frame.media_key)).all()
    assert all(rt.media.exists(k) for k in keys)


def test_two_workers_share_one_backlog(rt: Runtime, start_worker, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    videos = write_synthetic_dataset(tmp_path / "synth", videos=4, seed=10, n_frames=3, width=96, height=64)
    job_ids = [submit_import(rt, v) for v in videos]
    start_worker()
    start_worker()
    jobs = [wait_for(rt, j, lambda job: job.state.finished) for j in job_ids]
    assert [j.state for j in jobs] == [JobState.succeeded] * 4
    assert all(j.attempts == 1 for j in jobs), "a job ran twice"
    assert frame_count(rt) == 12


def test_a_failing_job_records_a_readable_reason(runtime: Runtime, tmp_path: Path) -> None:
    with transaction(runtime.sessions) as s:
        job_id = job_service.create_job(s, "ingest", ingest_params(str(tmp_path / "nowhere")), None).id
    state = job_service.execute_job(job_id, HANDLERS, runtime)
    assert state == JobState.failed
    with runtime.sessions() as s:
        job = s.get(Job, job_id)
        # for people: what went wrong and which file, not the server's folders nor the class name
        assert job.error in ("…/nowhere: no such file", "…/nowhere: no such file or directory"), job.error
        assert not job.error.startswith("IngestError") and "IngestError" in job.log and "Traceback" in job.log


def test_user_error_keeps_messages_short_and_names_bugs(settings: Settings) -> None:
    redact = redactor_for(settings)
    assert job_service.user_error(ValueError(f"{settings.media_root}/81/d7/ab12.mp4: cannot decode\nmore"),
                                  redact) == "media/81/d7/ab12.mp4: cannot decode"
    assert job_service.user_error(KeyError("frame_ids"), redact) == "KeyError: 'frame_ids'"
    assert job_service.user_error(RuntimeError(), redact) == "RuntimeError"
    assert len(job_service.user_error(ValueError("x" * 1000), redact)) == 300


def test_redelivered_job_runs_once(runtime: Runtime, tmp_path: Path) -> None:
    [video] = write_synthetic_dataset(tmp_path / "synth", videos=1, seed=1, n_frames=2, width=96, height=64)
    with transaction(runtime.sessions) as s:
        job_id = job_service.create_job(s, "ingest", ingest_params(str(video)), None).id
    args = (HANDLERS, runtime)
    assert job_service.execute_job(job_id, *args) == JobState.succeeded
    assert job_service.execute_job(job_id, *args) == JobState.succeeded  # a duplicate delivery is a no-op
    with runtime.sessions() as s:
        assert s.get(Job, job_id).attempts == 1


def test_reaper_marks_jobs_of_dead_workers(runtime: Runtime) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "ingest", {}, None)
        job.state, job.worker = JobState.running, f"{job_service.worker_id().rpartition(':')[0]}:{dead.pid}"
        job.heartbeat_at = job.created_at
        alive = job_service.create_job(s, "ingest", {}, None)
        alive.state, alive.worker = JobState.running, job_service.worker_id()
        alive.heartbeat_at = alive.created_at
    with transaction(runtime.sessions) as s:
        assert job_service.reap_lost_jobs(s) == [job.id]
    with transaction(runtime.sessions) as s:
        assert job_service.mark_for_retry(s, job.id).state == JobState.queued


def test_run_queued_jobs_with_two_workers_runs_jobs_side_by_side(rt: Runtime) -> None:
    """Two threads each take a job; a job queued by one of them runs too; every job is listed once
    (known kinds, run by the test's own handlers)."""
    spans: dict[int, tuple[float, float]] = {}

    def slow(ctx: job_service.JobContext) -> dict[str, int]:
        started = time.monotonic()
        time.sleep(0.4)
        if ctx.params.get("chain"):
            with transaction(ctx.sessions) as s:
                rt.submit(s, "ingest", {}, None)
        spans[ctx.job_id] = (started, time.monotonic())
        return {}

    def broken(_ctx: job_service.JobContext) -> dict[str, int]:
        raise ValueError("bad input")

    with transaction(rt.sessions) as s:
        first, second = (rt.submit(s, "ingest", {"chain": chain}, None).id for chain in (True, False))
        failing = rt.submit(s, "generate", {}, None).id
    results = job_service.run_queued_jobs({"ingest": slow, "generate": broken}, rt, workers=2)
    assert sorted(results) == [(first, JobState.succeeded), (second, JobState.succeeded),
                               (failing, JobState.failed), (failing + 1, JobState.succeeded)]
    assert len(results) == 4
    (a_start, a_end), (b_start, b_end) = spans[first], spans[second]
    assert a_start < b_end and b_start < a_end, "the two first jobs did not overlap"


def test_a_burst_worker_takes_concurrency_jobs_at_once(rt: Runtime, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    calls: list[int] = []
    monkeypatch.setattr(job_service, "run_queued_jobs", lambda _handlers, _env, *, workers: calls.append(workers) or [])
    result = CliRunner().invoke(main, ["--data-dir", str(rt.settings.home), "worker", "--burst", "--concurrency", "3"])
    assert result.exit_code == 0, result.output
    assert calls == [3]
