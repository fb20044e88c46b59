"""A file swapped for a link while it is being served: the served app, real connections.

One thread keeps replacing a run's validation picture, a report's picture and rank 0's stdout.log
by a link to a file outside the workspace (a symbolic link, and every other round a hard link) and
back (``os.replace``, so the name always exists); another keeps
exchanging a folder below a run's ``val/``, and a second run's own folder, with a link to an outside
folder (``renameat2`` with ``RENAME_EXCHANGE``, where the C library has it). Meanwhile curators fetch
those files, and the run's log (its tail and the whole of it): every answer is the run's or the
report's own file, or a 404 (the log: with or without its stdout.log) — never the outside file.
"""

from __future__ import annotations

import ctypes
import os
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from dataset.db import migrate, transaction
from dataset.services import evaluations, training
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.tables import Evaluation, JobState, Role
from tests.conftest import make_settings
from tests.runs_data import add_accepted_samples
from tests.test_runs import _queued_run
from webapp.cli.workspace import make_server, server_url
from webapp.runtime import Runtime

REQUESTS = 1000  # to each file being swapped (the run's picture, the report's picture)
EXCHANGED_REQUESTS = 400  # to each folder being exchanged, when the C library can exchange
LOG_REQUESTS = 400  # to each of the log's routes (its tail, the whole of it)
SWAPS_MAX = 5_000_000  # the swapping threads stop at this many swaps …
SWAP_S = 60.0  # … or after this long, whichever comes first
HARD_LINKS = True  # every other swap a hard link to the outside file rather than a symbolic link
THREADS = 4  # the server's
CLIENTS = 8  # connections fetching at once
REAL = b"\x89PNG the workspace's own picture"
LOG_OUT = b"step 1/2 loss 0.5\n"  # rank 0's stdout.log, the file swapped
LOG_ERR = b"the run's own warning\n"  # its stderr.log, left alone
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


@dataclass(frozen=True)
class Target:
    """A URL whose file is being swapped, the answer its own file gives, and any other answer of the
    workspace's own (a log read while its swapped file was a link: without that file)."""

    url: str
    real: bytes
    also: tuple[bytes, ...] = ()


@dataclass
class Served:
    url: str
    token: str
    marker: bytes
    targets: list[Target]
    swaps: Counter[str]
    stop: threading.Event
    exchanging: bool  # folders too (where the C library can exchange two names)


def _exchanger() -> Callable[[Path, Path], None] | None:
    """Atomically exchange two names (``renameat2(…, RENAME_EXCHANGE)``), or None without it."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None

    def exchange(a: Path, b: Path) -> None:
        if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) != 0:
            raise OSError(ctypes.get_errno(), f"renameat2 {a} {b}")

    return exchange


def _swap_files(files: list[tuple[Path, bytes]], outside: Path, swaps: Counter[str], stop: threading.Event) -> None:
    """Replace each of ``files`` by a link to ``outside`` (a symbolic link, every other round a hard
    one), then by a fresh copy of its own bytes, over and over."""
    deadline = time.monotonic() + SWAP_S
    while not stop.is_set() and swaps["files"] < SWAPS_MAX and time.monotonic() < deadline:
        for file, real in files:
            link, copy = file.with_name(".swap-link"), file.with_name(".swap-copy")
            link.unlink(missing_ok=True)
            if HARD_LINKS and swaps["files"] % 2:
                os.link(outside, link)
            else:
                link.symlink_to(outside)
            os.replace(link, file)
            copy.write_bytes(real)
            os.replace(copy, file)
        swaps["files"] += 1


def _exchange_folders(pairs: list[tuple[Path, Path]], exchange: Callable[[Path, Path], None],
                      swaps: Counter[str], stop: threading.Event) -> None:
    """Exchange each (folder, link to an outside folder) pair, over and over."""
    deadline = time.monotonic() + SWAP_S
    while not stop.is_set() and swaps["folders"] < SWAPS_MAX and time.monotonic() < deadline:
        for folder, link in pairs:
            exchange(folder, link)
        swaps["folders"] += 1
        time.sleep(0.0001)  # the C call lets go of the GIL: unpaused, this loop would take a core from the server
    for folder, link in pairs:  # left as found: the real folders in place
        if folder.is_symlink():
            exchange(folder, link)


def _evaluation_folder(rt: Runtime) -> tuple[int, Path]:
    """A succeeded evaluation's row and its (empty) report folder: (evaluation id, folder)."""
    with transaction(rt.sessions) as s:
        job = job_service.create_job(s, "evaluate", {}, None)
        job.state = JobState.succeeded
        folder = evaluations.report_folder(rt.settings.home, job.id)
        evaluation = Evaluation(job_id=job.id, dataset="x", report_dir=str(folder))
        s.add(evaluation)
        s.flush()
        return evaluation.id, folder


@pytest.fixture
def served(tmp_path: Path) -> Iterator[Served]:
    """The app under `serve`'s server, with the swapping threads running."""
    settings = make_settings(tmp_path / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        token = user_service.issue_token(s, user_service.create_user(s, "curator", Role.curator, "x" * 12))
    marker = f"OUTSIDE-SECRET-{uuid.uuid4().hex}".encode()
    outside = tmp_path / "outside"
    (outside / "room").mkdir(parents=True)
    (outside / "secret.png").write_bytes(marker)
    (outside / "room" / "x.png").write_bytes(marker)
    (outside / "run" / "val").mkdir(parents=True)
    (outside / "run" / "val" / "x.png").write_bytes(marker)

    run_id, moved_id = _queued_run(rt), _queued_run(rt)
    run = training.run_dir(settings.runs_dir, run_id)
    (run / "val" / "race").mkdir(parents=True)
    (run / "val" / "race" / "race.png").write_bytes(REAL)
    evaluation_id, report = _evaluation_folder(rt)
    (report / "pictures").mkdir(parents=True)
    (report / "pictures" / "race.png").write_bytes(REAL)
    targets = [Target(f"/models/runs/{run_id}/files/val/race/race.png", REAL),
               Target(f"/api/v1/evaluations/{evaluation_id}/files/pictures/race.png", REAL)] * REQUESTS

    rank0 = run / "logs" / "r1_race" / "attempt_0" / "0"
    rank0.mkdir(parents=True)
    (rank0 / "stdout.log").write_bytes(LOG_OUT)
    (rank0 / "stderr.log").write_bytes(LOG_ERR)

    swaps: Counter[str] = Counter()
    stop = threading.Event()
    workers = [threading.Thread(target=_swap_files, daemon=True,
                                args=([(run / "val" / "race" / "race.png", REAL),
                                       (report / "pictures" / "race.png", REAL), (rank0 / "stdout.log", LOG_OUT)],
                                      outside / "secret.png", swaps, stop))]
    exchange = _exchanger()
    if exchange is not None:
        room = run / "val" / "room"
        room.mkdir()
        (room / "x.png").write_bytes(REAL + b" room")
        (run / "val" / ".room-link").symlink_to(outside / "room")
        moved = training.run_dir(settings.runs_dir, moved_id)
        (moved / "val").mkdir()
        (moved / "val" / "x.png").write_bytes(REAL + b" moved")
        (settings.runs_dir / ".moved-link").symlink_to(outside / "run")
        pairs = [(room, run / "val" / ".room-link"), (moved, settings.runs_dir / ".moved-link")]
        workers.append(threading.Thread(target=_exchange_folders, args=(pairs, exchange, swaps, stop), daemon=True))
        targets += [Target(f"/models/runs/{run_id}/files/val/room/x.png", REAL + b" room"),
                    Target(f"/models/runs/{moved_id}/files/val/x.png", REAL + b" moved")] * EXCHANGED_REQUESTS

    server = make_server(settings, rt, "127.0.0.1", 0, threads=THREADS)
    threading.Thread(target=server.run, daemon=True).start()
    targets += _log_targets(server_url(server).rstrip("/"), token, run_id, rank0 / "stdout.log") * LOG_REQUESTS
    for worker in workers:
        worker.start()
    try:
        yield Served(server_url(server).rstrip("/"), token, marker, targets, swaps, stop, exchange is not None)
    finally:
        stop.set()
        for worker in workers:
            worker.join(timeout=SWAP_S)
        server.close()
        rt.close()


def _log_targets(url: str, token: str, run_id: int, stdout: Path) -> list[Target]:
    """The log's routes, with the answers the run's own files give (asked before the swapping
    starts): with its stdout.log, and without it (the swapped file read as a link, so left out)."""
    urls = [f"/models/runs/{run_id}/log?lines=50", f"/models/runs/{run_id}/log.txt"]
    with httpx.Client(base_url=url, timeout=30, headers={"Authorization": f"Bearer {token}"}) as client:
        whole = [client.get(u).content for u in urls]
        stdout.rename(stdout.with_name(".away"))
        without = [client.get(u).content for u in urls]
        stdout.with_name(".away").rename(stdout)
    assert b"step 1/2" in whole[1] and b"step 1/2" not in without[1] and b"own warning" in without[1], without
    return [Target(u, real, (other,)) for u, real, other in zip(urls, whole, without, strict=True)]


@pytest.mark.slow
def test_a_file_swapped_for_a_link_is_never_served(served: Served) -> None:
    local = threading.local()
    clients: list[httpx.Client] = []

    def fetch(target: Target) -> tuple[str, int, bool, bool, bool]:
        """(url, status, whether the answer carries the outside file, whether it is the file's own or
        a 404, whether it is the answer of the file's own with nothing left out)."""
        if not hasattr(local, "client"):
            local.client = httpx.Client(base_url=served.url, timeout=30,
                                        headers={"Authorization": f"Bearer {served.token}"})
            clients.append(local.client)
        try:
            answer = local.client.get(target.url)
        except httpx.TransportError:  # the server broke off an answer: not one of the two outcomes allowed
            del local.client
            return target.url, -1, False, False, False
        full = answer.status_code == 200 and answer.content == target.real
        own = full or answer.status_code == 404 or (answer.status_code == 200 and answer.content in target.also)
        return target.url, answer.status_code, served.marker in answer.content, own, full

    started = time.monotonic()
    try:
        with ThreadPoolExecutor(CLIENTS) as pool:
            answers = list(pool.map(fetch, served.targets))
    finally:
        for client in clients:
            client.close()
    took = time.monotonic() - started
    served.stop.set()
    leaks = Counter(url for url, _, leaked, _, _ in answers if leaked)
    statuses = Counter((url.split("/files/")[-1], status) for url, status, *_ in answers)
    assert not leaks, (leaks, statuses, dict(served.swaps), took)
    assert all(own for *_, own, _ in answers), (statuses, took)
    assert served.swaps["files"] > 100, (dict(served.swaps), took)  # the files were swapped all along
    assert not served.exchanging or served.swaps["folders"] > 100, (dict(served.swaps), took)
    for name in ("val/race/race.png", "pictures/race.png"):  # and were served between the swaps
        assert statuses[(name, 200)] > 0, statuses
    whole = Counter(url for url, *_, full in answers if full)  # the log was read whole between the swaps
    assert all(whole[target.url] > 0 for target in served.targets if target.also), (whole, statuses)
