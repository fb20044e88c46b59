"""Request bodies under the server `serve` runs: a body is read only after its route's limit and the
client's role allow it, an answer given over an unread body closes the connection instead of
reading the rest, and connections whose request has not arrived hold no worker thread."""

from __future__ import annotations

import contextlib
import http.client
import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from dataset.db import migrate
from tests.conftest import make_settings
from tests.served import head, served_app
from webapp.bodies import DEFAULT_BODY_BYTES, DRAFT_BODY_BYTES, PUBLIC_BODY_BYTES
from webapp.cli.workspace import make_server
from webapp.runtime import Runtime

KB64 = 64 * 1024
MB = 10**6
THREADS = 2


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, dict[str, str]]]:
    """The app under `serve`'s server with two worker threads; (its port, a token per role)."""
    with served_app(tmp_path_factory.mktemp("bodies") / "ws", THREADS) as answer:
        yield answer


def zeros(total: int) -> Iterator[bytes]:
    """``total`` bytes in 64 KB pieces, made as they are sent."""
    piece = b"\0" * KB64
    for start in range(0, total, KB64):
        yield piece[:min(KB64, total - start)]


def chunked(pieces: Iterator[bytes]) -> Iterator[bytes]:
    for piece in pieces:
        yield f"{len(piece):x}\r\n".encode() + piece + b"\r\n"


def send_big(port: int, path: str, size: int, headers: dict[str, str], *, chunks: bool = False) -> tuple[int, dict, int]:
    """Send ``size`` bytes of body to ``path``: the first 64 KB, then wait for the answer (the server
    must give it from those alone), then the rest until the server closes or stops reading.
    Returns (status, the answer's headers and JSON, how many body bytes went out in all)."""
    framing = {"Transfer-Encoding": "chunked"} if chunks else {"Content-Length": str(size)}
    body = chunked(zeros(size)) if chunks else zeros(size)
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(head("POST", path, {**headers, **framing}))
        sent = 0
        for piece in body:
            sock.sendall(piece)
            sent += len(piece)
            if sent >= KB64:
                break
        response = http.client.HTTPResponse(sock)
        response.begin()  # times out if the server waits for more of the body
        answer = {"connection": response.getheader("Connection"), **json.loads(response.read())}
        sock.settimeout(2)
        try:
            for piece in body:
                sock.sendall(piece)
                sent += len(piece)
        except OSError:  # reset, broken pipe, or the server stopped reading: what matters is how much went
            pass
    return response.status, answer, sent


def multipart(token: str | None) -> dict[str, str]:
    return {"Content-Type": "multipart/form-data; boundary=x", **({"Authorization": f"Bearer {token}"} if token else {})}


@pytest.mark.parametrize(("path", "role", "chunks", "status"), [
    ("/api/v1/videos", None, False, 401),
    ("/api/v1/videos", None, True, 401),
    ("/api/v1/videos", "annotator", False, 403),
    ("/api/v1/frames/1/segment", "annotator", False, 413),
], ids=["anonymous-upload", "anonymous-chunked-upload", "annotator-upload", "annotator-200MB-json"])
def test_a_300_mb_body_is_answered_from_its_first_64_kb_and_never_read(served, path, role, chunks, status) -> None:  # type: ignore[no-untyped-def]
    port, tokens = served
    headers = multipart(tokens.get(role or ""))
    send_big(port, path, 300 * MB, headers, chunks=chunks)  # the first answer imports and caches what answering takes
    process = psutil.Process()
    before = process.memory_info().rss
    got, answer, sent = send_big(port, path, 300 * MB, headers, chunks=chunks)
    grown = process.memory_info().rss - before
    assert got == status and answer["status"] == status, answer
    assert answer["connection"] == "close"
    # What went out beyond the first 64 KB sat in the sockets' buffers when the server hung up on it.
    assert sent < 16 * MB, f"the server read {sent / MB:.0f} MB of a body it had answered"
    assert grown < 20 * MB, f"the server grew by {grown / MB:.0f} MB"


def test_a_chunked_body_is_cut_at_the_routes_limit(served) -> None:  # type: ignore[no-untyped-def]
    port, tokens = served
    headers = {"Content-Type": "application/json", "Authorization": f"Bearer {tokens['curator']}",
               "Transfer-Encoding": "chunked"}

    def send(sock: socket.socket) -> None:
        with contextlib.suppress(OSError):  # the server hangs up once it has read the limit
            for piece in chunked(zeros(2 * DEFAULT_BODY_BYTES)):
                sock.sendall(piece)

    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(head("POST", "/api/v1/prefilter", headers))  # a route that reads its body first
        threading.Thread(target=send, args=(sock,), daemon=True).start()
        response = http.client.HTTPResponse(sock)
        response.begin()
        text = response.read()
        assert response.status == 413 and "at most" in json.loads(text)["error"], text


def test_idle_and_dripping_connections_hold_no_worker(served) -> None:  # type: ignore[no-untyped-def]
    """Stock cheroot gives every connection a worker at once, which waits for its bytes: as many
    silent connections as threads stopped everyone else for the timeout (30 s)."""
    port, _ = served
    form = {"Content-Type": "application/x-www-form-urlencoded", "Content-Length": "100"}
    starts = [b"", b"POST /login HTTP/1.1\r\nHost: x\r\n", head("POST", "/login", form) + b"name=",
              head("POST", "/login", {**form, "Expect": "100-continue"})]
    stalled = [socket.create_connection(("127.0.0.1", port)) for _ in range(2 * THREADS) for _ in starts]
    try:
        for n, sock in enumerate(stalled):
            sock.sendall(starts[n % len(starts)])
        time.sleep(0.3)
        t0 = time.monotonic()
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        connection.request("GET", "/healthz")
        assert connection.getresponse().status == 200
        assert time.monotonic() - t0 < 2
    finally:
        for sock in stalled:
            sock.close()


def test_expect_100_continue_on_a_small_body_is_answered_once(served) -> None:  # type: ignore[no-untyped-def]
    port, _ = served
    body = b"name=a&password=b"
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(head("POST", "/login", {"Content-Type": "application/x-www-form-urlencoded",
                                             "Content-Length": str(len(body)), "Expect": "100-continue"}))
        assert sock.recv(100) == b"HTTP/1.1 100 Continue\r\n\r\n"
        sock.sendall(body)
        response = http.client.HTTPResponse(sock)
        response.begin()
        assert response.status == 400  # no CSRF token: the login form was read and judged
        assert b"CSRF" in response.read()


def test_a_small_unread_body_keeps_the_connection(served) -> None:  # type: ignore[no-untyped-def]
    port, tokens = served
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    auth = {"Authorization": f"Bearer {tokens['annotator']}", "Content-Type": "application/json"}
    connection.request("POST", "/api/v1/frames/1/lease/release", body=b"{}" + b" " * 1000, headers=auth)
    response = connection.getresponse()
    response.read()
    first = connection.sock
    assert response.getheader("Connection") != "close"
    connection.request("GET", "/healthz")
    assert connection.getresponse().status == 200 and connection.sock is first


@pytest.mark.parametrize(("path", "role", "limit"), [
    ("/login", None, PUBLIC_BODY_BYTES),
    ("/api/v1/frames/1/segment", "annotator", DEFAULT_BODY_BYTES),
    ("/api/v1/frames/1/annotation", "annotator", DRAFT_BODY_BYTES),
])
def test_each_route_takes_its_own_limit(client, tokens, path, role, limit) -> None:  # type: ignore[no-untyped-def]
    headers = {"Authorization": f"Bearer {tokens[role]}"} if role else {}
    at_limit = client.post(path, data=b"{" + b" " * (limit - 1), headers=headers, content_type="application/json")
    assert at_limit.status_code != 413
    over = client.post(path, data=b"{" + b" " * limit, headers=headers, content_type="application/json")
    assert over.status_code == 413, over.get_data(as_text=True)[:300]


def test_a_draft_of_64_sam2_sized_masks_fits(client, tokens) -> None:  # type: ignore[no-untyped-def]
    """The draft limit holds 64 regions, each a 255 KB mask and 1000 clicks."""
    clicks = [{"x": 1919.2534912109375, "y": 1079.4967041015625, "label": 1}] * 1000
    regions = [{"pair": n // 2, "kind": ("illusion", "support")[n % 2], "mask": {"size": [1080, 1920], "counts": "a" * 255_000},
                "clicks": clicks} for n in range(64)]
    body = json.dumps({"version": 0, "submit": False, "regions": regions}).encode()
    assert len(body) <= DRAFT_BODY_BYTES
    response = client.post("/api/v1/frames/1/annotation", data=body, content_type="application/json",
                           headers={"Authorization": f"Bearer {tokens['annotator']}"})
    assert response.status_code != 413, response.json  # read and judged (there is no frame 1)


def test_the_server_listens_before_it_runs(tmp_path: Path) -> None:
    """`make_server` binds (port 0: any free port), and a connection waits in the backlog until `run`."""
    settings = make_settings(tmp_path / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    server = make_server(settings, rt, "127.0.0.1", 0, threads=1)
    try:
        sock = socket.create_connection(("127.0.0.1", server.effective_port), timeout=5)
        sock.sendall(head("GET", "/healthz", {}))
        threading.Thread(target=server.run, daemon=True).start()
        response = http.client.HTTPResponse(sock)
        response.begin()
        assert response.status == 200
        sock.close()
    finally:
        server.close()
        rt.close()
