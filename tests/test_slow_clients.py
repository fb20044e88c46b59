"""Slow clients under the server `serve` runs: no client, anonymous or of any role, holds a worker thread
while its body drips in, each such connection is closed at its deadline, and a large body that does
arrive in pieces is read whole (in memory or on disk) before a worker takes it."""

from __future__ import annotations

import http.client
import io
import json
import selectors
import socket
import statistics
import threading
import time
from collections.abc import Iterator

import httpx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.served import chunk, head, served_app
from webapp import server as server_module
from webapp.server import BODY_GRACE_S, BODY_MIN_RATE, SPOOL_BYTES, ChunkCounter

pytestmark = pytest.mark.serial  # measures latency: alone, after the parallel part
THREADS = 8  # `serve`'s default
SLOW = 64  # slow connections: half anonymous chunked logins, half annotator Content-Length drips
EXPIRY_SLACK_S = 1.5  # the selector looks for expired connections every 0.5 s


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, dict[str, str]]]:
    """The app under `serve`'s server with its default eight worker threads; (its port, a token per role)."""
    with served_app(tmp_path_factory.mktemp("slow") / "ws", THREADS) as answer:
        yield answer


class Drip:
    """One slow client: it sends its head and a first piece at once, then one byte at a time."""

    def __init__(self, port: int, start: bytes, body_sent: int, drip: bytes) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.sendall(start)
        self.began = time.time()
        self.expected_close = self.began + BODY_GRACE_S + body_sent / BODY_MIN_RATE
        self.drip = drip
        self.closed_at: float | None = None

    def step(self) -> None:
        if self.closed_at is None:
            try:
                self.sock.sendall(self.drip)
            except OSError:
                self.closed_at = time.time()


def test_64_slow_connections_hold_no_worker_and_close_at_their_deadline(served) -> None:  # type: ignore[no-untyped-def]
    """The probe's attack: chunked anonymous logins that send ~30 KB at once, then a byte now and then,
    and annotators' segment calls that declare 1 MB, send 40 KB, then drip. Meanwhile /healthz and a
    token user's calls answer within 2 s at p95, and every slow connection closes by its deadline."""
    port, tokens = served
    login = head("POST", "/login", {"Content-Type": "application/x-www-form-urlencoded", "Transfer-Encoding": "chunked"})
    segment = head("POST", "/api/v1/frames/1/segment", {"Content-Type": "application/json", "Content-Length": "1000000",
                                                        "Authorization": f"Bearer {tokens['annotator']}"})
    drips = [Drip(port, login + chunk(b"a" * 30_000), 30_000 + 10, chunk(b"a")) if n % 2 else
             Drip(port, segment + b" " * 40_000, 40_000, b" ") for n in range(SLOW)]
    watch = selectors.DefaultSelector()
    for drip in drips:
        watch.register(drip.sock, selectors.EVENT_READ, drip)
    latencies: list[float] = []
    user = httpx.Client(base_url=f"http://127.0.0.1:{port}", headers={"Authorization": f"Bearer {tokens['annotator']}"},
                        timeout=20)
    stop = max(d.expected_close for d in drips) + EXPIRY_SLACK_S + 0.5
    try:
        while time.time() < stop:
            for path in ("/healthz", "/api/v1/me"):
                t0 = time.monotonic()
                assert user.get(path).status_code == 200
                latencies.append(time.monotonic() - t0)
            for key, _ in watch.select(timeout=0.2):  # the server closed it (or answered it: it must not)
                drip = key.data
                assert drip.sock.recv(1 << 16) == b"", "a slow connection was answered: a worker took it"
                drip.closed_at = time.time()
                watch.unregister(drip.sock)
            for drip in drips:
                drip.step()
    finally:
        user.close()
        for drip in drips:
            drip.sock.close()
    p95 = statistics.quantiles(latencies, n=20)[-1]
    assert p95 < 2.0, f"p95 {p95:.2f} s over {len(latencies)} calls"
    late = [(d.closed_at or time.time()) - d.expected_close for d in drips]
    assert all(d.closed_at is not None for d in drips), f"{sum(d.closed_at is None for d in drips)} slow connections still open"
    assert max(late) < EXPIRY_SLACK_S, f"closed up to {max(late):.1f} s after the deadline"
    assert min(late) > -1.0, f"closed {-min(late):.1f} s before the deadline"


def test_a_large_body_in_pieces_is_read_whole_before_a_worker_takes_it(served) -> None:  # type: ignore[no-untyped-def]
    """A 3 MB draft, past what waits in memory, arrives in pieces over a second from each of 2 x THREADS
    clients at once; each is judged on its content (no frame 1: 404), none cut short."""
    port, tokens = served
    body = json.dumps({"version": 0, "submit": False, "regions": [], "pad": "x" * (3 * SPOOL_BYTES)}).encode()
    answers: list[int] = []

    def post(chunked: bool) -> None:
        framing = {"Transfer-Encoding": "chunked"} if chunked else {"Content-Length": str(len(body))}
        with socket.create_connection(("127.0.0.1", port), timeout=20) as sock:
            sock.sendall(head("POST", "/api/v1/frames/1/annotation", {
                "Content-Type": "application/json", "Authorization": f"Bearer {tokens['annotator']}", **framing}))
            step = len(body) // 5 + 1
            for at in range(0, len(body), step):
                piece = body[at:at + step]
                sock.sendall(chunk(piece) if chunked else piece)
                time.sleep(0.2)
            if chunked:
                sock.sendall(b"0\r\n\r\n")
            response = http.client.HTTPResponse(sock)
            response.begin()
            answers.append(response.status)
            assert "frame" in json.loads(response.read())["error"]

    clients = [threading.Thread(target=post, args=(n % 2 == 0,)) for n in range(2 * THREADS)]
    t0 = time.monotonic()
    for t in clients:
        t.start()
    time.sleep(0.3)
    health = httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=10)  # the workers are free meanwhile
    assert health.status_code == 200 and time.monotonic() - t0 < 1.0
    for t in clients:
        t.join(30)
    assert answers == [404] * len(clients)


def test_a_pipelined_request_after_a_chunked_body_is_answered(served) -> None:  # type: ignore[no-untyped-def]
    port, tokens = served
    auth = {"Authorization": f"Bearer {tokens['annotator']}"}
    post = head("POST", "/api/v1/frames/1/lease/release", {**auth, "Content-Type": "application/json",
                                                            "Transfer-Encoding": "chunked"}) + chunk(b"{}") + b"0\r\n\r\n"
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(post + head("GET", "/healthz", {}))
        answers = SharedAnswers(sock)
        first = http.client.HTTPResponse(answers)  # type: ignore[arg-type]
        first.begin()
        first.read()
        second = http.client.HTTPResponse(answers)  # type: ignore[arg-type]
        second.begin()
        assert second.status == 200


def test_pipelined_requests_are_each_answered_whatever_the_reads_left_behind(served) -> None:  # type: ignore[no-untyped-def]
    """Requests sent in one go, each after a body read to its last byte: none waits for bytes that came."""
    port, tokens = served
    auth = {"Authorization": f"Bearer {tokens['annotator']}", "Content-Type": "application/json"}
    sized = head("POST", "/api/v1/frames/1/lease/release", {**auth, "Content-Length": "2"}) + b"{}"
    chunked = (head("POST", "/api/v1/frames/1/lease/release", {**auth, "Transfer-Encoding": "chunked"})
               + chunk(b"{}") + b"0\r\n\r\n")
    # Bodies that end on and around the reader's 8 KiB buffer, where a body read to its last byte leaves
    # the next request in the read-ahead rather than in the buffer.
    padded = []
    for end in (8192, 16384, 24576):
        for delta in range(-3, 4):
            start = head("POST", "/api/v1/frames/1/lease/release", {**auth, "Content-Length": "0000000"})
            body = end + delta - len(start)
            padded.append(head("POST", "/api/v1/frames/1/lease/release", {**auth, "Content-Length": f"{body:07d}"})
                          + b" " * body)
    requests = [sized, chunked, head("GET", "/healthz", {})] * 5 + [r for p in padded for r in (p, head("GET", "/healthz", {}))]
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(b"".join(requests))
        answers = SharedAnswers(sock)
        for _ in requests:
            response = http.client.HTTPResponse(answers)  # type: ignore[arg-type]
            response.begin()
            response.read()
            assert response.status in (200, 404, 409)


class SharedAnswers:
    """A socket whose answers are parsed one after another from one buffer (http.client makes a new
    buffered file per response, which may swallow the start of the next)."""

    class _File(io.BufferedReader):
        def close(self) -> None:  # http.client closes each response's file
            pass

    def __init__(self, sock: socket.socket) -> None:
        self.file = self._File(socket.SocketIO(sock, "rb"))

    def makefile(self, *_: object, **__: object) -> io.BufferedReader:
        return self.file


@settings(max_examples=200, deadline=None)
@given(sizes=st.lists(st.integers(1, 300), max_size=8), cuts=st.lists(st.integers(1, 50), min_size=1, max_size=30),
       tail=st.binary(max_size=20))
def test_the_chunk_counter_finds_a_bodys_data_and_end_however_it_arrives(sizes, cuts, tail) -> None:  # type: ignore[no-untyped-def]
    raw = b"".join(f"{n:x};ext=1\r\n".encode() + bytes(n) + b"\r\n" for n in sizes) + b"0\r\nTrailer: x\r\n\r\n"
    stream, counter, used, at = raw + tail, ChunkCounter(), 0, 0
    for cut in cuts * (len(stream) // max(1, sum(cuts)) + 1):
        if at >= len(stream):
            break
        used += counter.feed(stream[at:at + cut])
        at += cut
    assert counter.ended and not counter.bad
    assert counter.data == sum(sizes)
    assert used == len(raw)


def test_the_chunk_counter_refuses_what_is_not_chunked() -> None:
    counter = ChunkCounter()
    counter.feed(b"zz\r\n")
    assert counter.bad
    counter = ChunkCounter()
    counter.feed(b"1" * 5000)
    assert counter.bad


def test_the_deadline_grows_with_the_bytes_that_came() -> None:
    arrival = server_module.Arrival(began=100.0)
    assert arrival.deadline() == 100.0 + server_module.TIMEOUT_S
    arrival.head, arrival.headers_at = 10, 101.0
    assert arrival.deadline() == 101.0 + BODY_GRACE_S
    arrival.body = 10 * BODY_MIN_RATE
    assert arrival.deadline() == pytest.approx(101.0 + BODY_GRACE_S + 10)
