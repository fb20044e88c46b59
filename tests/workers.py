"""Real worker processes over a real queue: SQLite always, Redis when TEST_REDIS_URL is set.

Modules that import these fixtures may define an ``extra_settings`` fixture (a dict) that goes
into the workspace's settings file, which the worker processes read too.
"""

from __future__ import annotations

import subprocess
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from benchmarks import served
from dataset.settings import Settings, write_settings_file
from dataset.tables import Job
from tests.conftest import TEST_REDIS_URL, make_settings, migrate_copying
from webapp.runtime import Runtime


@pytest.fixture
def extra_settings() -> dict[str, Any]:
    return {}


@pytest.fixture(params=["sqlite", "redis"])
def queue_settings(request: pytest.FixtureRequest, tmp_path: Path, extra_settings: dict[str, Any],
                   migrated_sqlite: Path) -> Settings:
    home = tmp_path / "ws"
    home.mkdir()
    values = dict(extra_settings)
    if request.param == "redis":
        if not TEST_REDIS_URL:
            pytest.skip("Redis queue tests need TEST_REDIS_URL (e.g. redis://127.0.0.1:6379/0)")
        # A queue name of its own, so parallel or leftover runs never share a backlog.
        values.update(queue_url=TEST_REDIS_URL, queue_name=f"test-{uuid.uuid4().hex[:8]}")
    write_settings_file(home, **values)
    settings = make_settings(home)
    migrate_copying(settings.database_url, migrated_sqlite)
    return settings


@pytest.fixture
def rt(queue_settings: Settings) -> Iterator[Runtime]:
    runtime = Runtime(queue_settings)
    yield runtime
    if queue_settings.queue_url:
        for huey in runtime.queue.hueys.values():
            huey.flush()
    runtime.close()


@pytest.fixture
def start_worker(queue_settings: Settings) -> Iterator[Callable[..., subprocess.Popen[str]]]:
    """Start a real `illusion-studio worker [ARGS…]` process and return once it listens for jobs;
    all are stopped after the test."""
    procs: list[subprocess.Popen[str]] = []

    def start(*args: str) -> subprocess.Popen[str]:
        procs.append(served.start_worker(queue_settings.home, *args))
        return procs[-1]

    yield start
    for proc in procs:
        served.stop(proc)


def wait_for(rt: Runtime, job_id: int, predicate: Callable[[Job], bool], timeout: float = 90) -> Job:
    """Poll a job's row until ``predicate`` holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with rt.sessions() as s:
            job = s.get(Job, job_id)
            if predicate(job):
                return job
        time.sleep(0.01)
    raise AssertionError(f"job {job_id} never reached the expected state; last: {job.state} {job.progress} {job.error}")
