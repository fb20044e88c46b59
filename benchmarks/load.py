"""``bench load``: annotators and curators at once against a served app with a worker, for a bounded
time; what the server answered (requests, 5xx, 409s, p50/p95 per route) and whether every write it
acknowledged is in the database afterwards (:mod:`benchmarks.load_check`).

The workspace is one synthetic video ingested as the real job does, half its frames approved (the
annotators' queue) and half prefiltered (the curators' grid). Curators approve frames into the
annotators' queue, reject some and send rejected ones back; annotators click, save drafts, give most
frames back for someone else to finish and submit the rest, which the worker then generates. The
server (cheroot, webapp.server) and the worker run in processes of their own; the clients are threads here, each
with its own connection, all on 127.0.0.1. SQLite by default, PostgreSQL and Redis when given.
"""

from __future__ import annotations

import random
import tempfile
import time
import uuid
from collections import Counter, defaultdict
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import func, select, update

from benchmarks.load_check import lost_writes
from benchmarks.load_clients import Client, Tally, annotate, curate
from benchmarks.served import served_app, start_worker, stop
from benchmarks.workspace import ingested_workspace
from dataset.db import scratch_database, transaction
from dataset.services import users as user_service
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, FrameState, Job
from webapp.runtime import Runtime

BENCH_DATABASE = "bench_load"
PASSWORD = "bench-password"
SIZE = (320, 180)  # small frames: the figures are about the server and the database, not the segmenter


@contextmanager
def _database(server_url: str | None) -> Iterator[str | None]:
    """None (the workspace's own SQLite file), or ``bench_load`` created (and dropped) on the server."""
    if server_url is None:
        yield None
        return
    with scratch_database(server_url, BENCH_DATABASE) as url:
        yield url


def run_load_bench(annotators: int = 4, curators: int = 2, seconds: float = 30.0, frames: int = 40,
                   database_url: str | None = None, queue_url: str | None = None, seed: int = 0) -> dict[str, Any]:
    """Run the clients for ``seconds`` and report what they saw and what the database kept."""
    with tempfile.TemporaryDirectory() as tmp, _database(database_url) as url:
        root = Path(tmp)
        scenes = write_synthetic_dataset(root / "scene", videos=1, seed=seed, n_frames=frames, width=SIZE[0],
                                         height=SIZE[1])
        # A queue name of its own on a shared Redis, so no other deployment's workers take these jobs.
        rt = ingested_workspace(root / "ws", scenes, database_url=url, queue_url=queue_url,
                                queue_name=f"bench-load-{uuid.uuid4().hex[:8]}" if queue_url else None)
        try:
            _split_frames(rt)
            people = _people(rt, annotators, curators)
            worker = start_worker(rt.settings.home)
            try:
                with served_app(rt.settings.home, threads=max(8, annotators + curators)) as base_url:
                    tallies = _work(base_url, people, seconds, seed)
            finally:
                stop(worker)
            with rt.sessions() as s:
                lost = lost_writes(s, tallies)
                jobs = dict(s.execute(select(Job.state, func.count()).group_by(Job.state)).all())
            return {"database": rt.engine.dialect.name, "queue": "redis" if queue_url else "sqlite",
                    "annotators": annotators, "curators": curators, "seconds": seconds, "frames": frames,
                    **_figures(tallies, seconds), "lost_writes": sum(lost.values()), "lost_by_check": lost,
                    "jobs": {state.value: n for state, n in jobs.items()}}
        finally:
            if queue_url:
                for huey in rt.queue.hueys.values():
                    huey.flush()
            rt.close()


def _split_frames(rt: Runtime) -> None:
    """Every other frame waits for annotators (approved), the rest for curators (prefiltered)."""
    with transaction(rt.sessions) as s:
        ids = s.scalars(select(Frame.id).order_by(Frame.index)).all()
        s.execute(update(Frame).where(Frame.id.in_(ids[::2])).values(state=FrameState.approved))
        s.execute(update(Frame).where(Frame.id.in_(ids[1::2])).values(state=FrameState.prefiltered))


def _people(rt: Runtime, annotators: int, curators: int) -> list[tuple[str, int, str | None]]:
    """(role, user id, API token or None for the login form) per client: half of them log in, half
    send tokens."""
    roles = ["annotator"] * annotators + ["curator"] * curators
    with transaction(rt.sessions) as s:
        people = []
        for k, role in enumerate(roles):
            user = user_service.create_user(s, f"{role}{k}", role, PASSWORD)
            people.append((role, user.id, user_service.issue_token(s, user) if k % 2 else None))
    return people


def _work(base_url: str, people: Sequence[tuple[str, int, str | None]], seconds: float, seed: int) -> list[Tally]:
    deadline = time.monotonic() + seconds
    loops: dict[str, Callable[[Client, random.Random], None]] = {"annotator": annotate, "curator": curate}

    def person(k: int) -> Tally:
        role, user_id, token = people[k]
        tally = Tally(user_id)
        client = Client(base_url, tally, deadline)
        try:
            if token:
                client.use_token(token)
            else:
                client.log_in(f"{role}{k}", PASSWORD)
            loops[role](client, random.Random(seed * 1000 + k))
        finally:
            client.close()
        return tally

    with ThreadPoolExecutor(len(people)) as pool:
        return list(pool.map(person, range(len(people))))


def _figures(tallies: Sequence[Tally], seconds: float) -> dict[str, Any]:
    statuses: Counter[int] = sum((t.statuses for t in tallies), Counter())
    times: defaultdict[str, list[float]] = defaultdict(list)
    for t in tallies:
        for route, values in t.times.items():
            times[route].extend(values)
    requests = sum(t.requests for t in tallies)
    saves = [s for t in tallies for s in t.saves]
    return {
        "requests": requests, "requests_per_s": round(requests / seconds, 1),
        "5xx": sum(n for status, n in statuses.items() if status >= 500),
        "transport_errors": sum(t.transport_errors for t in tallies),
        "conflicts": statuses[409], "stale_saves_accepted": sum(t.stale_accepted for t in tallies),
        "statuses": {str(status): n for status, n in sorted(statuses.items())},
        "writes": {"reviews": sum(len(t.reviews) for t in tallies), "annotation_saves": len(saves),
                   "submits": sum(s.submitted for s in saves)},
        "routes": {route: {"count": len(values), "p50_ms": round(float(np.percentile(values, 50)), 1),
                           "p95_ms": round(float(np.percentile(values, 95)), 1)}
                   for route, values in sorted(times.items())},
    }
